"""The belief-adaptive EKF with out-of-sequence GNSS fusion (Algorithm 1), in the local NED frame.

Inputs are NED accelerations (gravity-compensated) with the attitude they were rotated by (the
accelerometer bias is a body-frame state) and NED position fixes stamped with their validity
time; no quaternions or geodesy here (``navigator.py`` does those).

The filter is a time-ordered list of fusions. Each entry keeps the posterior (x⁺, P⁺) at the
fix's validity time, the adaptation state after it (so β too) and the fix itself. Between two
entries nothing but the prediction happens, and the prediction over any interval is one closed-
form step (``model.py``: F and Q of a block from the rotation integrals; ``history.py``: exact
mean and those integrals from prefix sums),
so neither the state nor the covariance is propagated per IMU sample:

* an on-time or late fix whose validity is after the last fusion: one prediction from the last
  entry to its validity time, one update — the same cost whatever the delay;
* a fix older than the last fusion (arrived out of order): roll back to the entry before its
  validity time, fuse it, then re-fuse the later fixes from their stored measurements — cost
  O(number of later fixes), never O(IMU samples). The result equals in-order processing;
* a fix valid slightly after the newest IMU sample waits until the IMU stream passes it;
* ``estimate()`` predicts from the last entry to the newest IMU time (cached).

Entries older than ``history_s`` are dropped; the newest of them is kept as the base (re-based
to the horizon when it is older, so a GNSS outage does not grow the IMU history). Fixes valid
before the base are rejected and counted. The list, the roll-back and the trimming are
``timeline.Timeline``'s (shared with the tight engine); this module fuses.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any, NamedTuple

import numpy as np

from companion.estimator import _core, methods, model
from companion.estimator.belief import InnovationTerms, Vec3
from companion.estimator.config import EstimatorConfig
from companion.estimator.consistency import Fit, Scatter, Scatter1, fit_add3
from companion.estimator.history import Integrals, finite3
from companion.estimator.timeline import Timeline

# the IMU counters (``ImuHistory.counts``, counted by the core), in that order
_IMU_COUNTS = ("imu_used", "imu_gaps", "imu_rejected_nonfinite", "imu_rejected_time_backwards",
               "imu_rejected_out_of_range")


class Fusion(NamedTuple):
    """One entry of the fusion history (all NED)."""

    t_us: int  # validity time of the fix (or of a re-based anchor)
    z_ned_m: Vec3 | None  # the fix; None for an anchor without a measurement
    # posterior [p, v, b (NED), a (FRD), d (NED)] (m, m/s, m, m/s², m/s²); prior if the fix failed the gate
    x: model.State
    P: model.Cov  # posterior covariance (15×15, never written again)
    state: Any  # adaptation state after this fix (immutable)
    nis: float  # NIS of this fix (of the last fix for an anchor)
    # per-fusion constants, computed once (each prediction from this entry needs them)
    ints: Integrals  # IMU prefix integrals at t_us (history.py)
    beta: float  # method.beta(state): the belief in force after this entry
    sigma_bias_m: float  # σ_b(β) of eq. 13 for that belief
    # innovation gate (a deterministic function of the time-ordered fixes: re-fused identically)
    r_nominal_m2: Vec3  # this fix's nominal R as given (variances, m²; config, reported, or LEARN)
    t_fused_us: int  # validity time of the last fix fused (or reset to) up to this entry
    test_ratio: float  # horizontal NIS / gate² of this fix (NaN for the first)
    glitch: bool  # this fix failed the gate (rejected, or fused only relative to an open GNSS offset)
    n_rejected: int  # fixes rejected by the gate up to this entry (cumulative)
    n_resets: int  # resets up to this entry (cumulative)
    # GNSS step hypothesis (docs/estimator.md): the offset (NED, m) subtracted from the fixes while
    # it is open (None: closed), when it opened, and how many opened up to this entry
    offset: Vec3 | None = None
    t_offset_us: int = 0
    n_offsets: int = 0
    # the last step accepted (the offset that became the GNSS's track, moving the position) and
    # when, for gnss_offset_return_s (None: none); steps back onto the earlier track so far
    accepted: Vec3 | None = None
    t_accepted_us: int = 0
    n_returns: int = 0
    # the receiver's velocity (NED, m/s; NaN = a component not reported; None: none) and its R
    # (variances, (m/s)²), its horizontal NIS / gate² (NaN: none), velocities tested and rejected
    # by their gate up to this entry
    zv_ned_m_s: Vec3 | None = None
    rv_m2: Vec3 = (math.nan, math.nan, math.nan)
    vel_ratio: float = math.nan
    n_vel_tested: int = 0
    n_vel_rejected: int = 0
    # IMU / GNSS disagreement: the mean NIS per dof (config imu_gnss_disagree_*), whether it is
    # flagged (the prediction from this entry then uses the inflated IMU noise), onsets so far
    disagree_level: float = 0.0
    disagree: bool = False
    n_disagree: int = 0
    # the receiver's innovation spread: log-domain running centres of |horizontal innovation| and
    # |vertical innovation| (m; config gnss_scale_tau_s), which floor the gate's R
    scale_h_m: float = 0.0
    scale_v_m: float = 0.0
    # the receiver's own noise, independent of the filter's state (so a wrong model cannot feed it):
    # u = (z − z_prev − D_imu) / T, the velocity at the previous fix the two fixes imply once the
    # IMU's displacement over the block is removed (None: no previous fix), dv_imu the IMU's velocity
    # change over the block, T_s its length, and the running centres of the normalised change of u
    # (m) that give the R of fixes without a reported accuracy
    u_ned_m_s: Vec3 | None = None
    dv_imu_m_s: Vec3 = (0.0, 0.0, 0.0)
    block_s: float = 0.0
    noise_h_m: float = 0.0
    noise_v_m: float = 0.0
    # fly-away guard: the velocity smoothed over the acceleration window (NED, m/s), this entry's
    # estimate left the vehicle's envelope; entries that did so far
    v_smooth: Vec3 = (0.0, 0.0, 0.0)
    invalid: bool = False
    n_invalid: int = 0
    # the receiver's scale of the bias range in force from this entry (config.bias_scale of this fix's
    # nominal R): sigma_bias_m above includes it
    bias_scale: float = 1.0
    # the fused fixes' consistency so far (N, E, D innovations over their S; the reported accuracy's
    # inflation, ``consistency``)
    fit: Fit = Fit()
    # the open step's fixes tested against dead reckoning from its opening (``_hold_fit``): the opening
    # (t_us, x⁻, P⁻, IMU integrals, σ_b, the velocity variance the test assumes there, the offset; None:
    # no step open, one re-opened, or the IMU found wrong), the horizontal residuals of the fixes since
    # (t − t₀ s, r_N, r_E, D_N, D_E: D the IMU's own displacement over that time), and whether they were
    # found a ramp of the fixes (a fading reflection; the step then held on the IMU from its opening)
    hold_ref: tuple[Any, ...] | None = None
    hold_obs: tuple[tuple[float, float, float, float, float], ...] = ()
    ramp: bool = False
    # the fused fixes' own horizontal scatter and correlation (the reported accuracy's floor, ``consistency``)
    scatter: Scatter = Scatter()
    scatter_v: Scatter1 = Scatter1()  # the same vertically (one axis)


class Snapshot(NamedTuple):
    """The filter carried to the newest IMU time (the full covariance: ``covariance_now``)."""

    t_us: int
    x: model.State
    out: np.ndarray  # (18,) p, v, b, their variances (N, E, D each; m, m/s, m, m², (m/s)², m²); never written
    beta: float
    nis: float
    test_ratio: float
    glitch: bool
    pos_valid: bool
    n_rejected: int
    n_resets: int
    vel_ratio: float = math.nan  # horizontal velocity NIS / gate² of the last fix (NaN: none)
    disagree: bool = False  # the IMU-propagated motion persistently disagrees with GNSS

    @property
    def var(self) -> tuple[float, ...]:
        """Variances of p, v, b (N, E, D each; m², (m/s)², m²)."""
        return tuple(self.out[9:18].tolist())


class FusionEngine(Timeline[Fusion, "_Fix", "Snapshot"]):
    """Belief-adaptive EKF on NED inputs; counts every rejection in ``counts``. IMU input:
    ``push_acc``, ``push_frd``, ``push_acc_batch`` (``Timeline``'s)."""

    def __init__(self, cfg: EstimatorConfig, method: str, counts: dict[str, int] | None = None,
                 context: methods.MethodContext | None = None) -> None:
        self.cfg = cfg
        self.method_name = method
        # the method's map and plugin parameters, and a reader of this filter's latest posterior
        self.method = methods.make(method, cfg, replace(context or methods.MethodContext(),
                                                        posterior=lambda: self.entries[-1].x))
        # A belief (GNSS trust) learns from a fix the gate rejects: it is evidence against trust.
        # R-learners (adaptive, vbakf) do not: they estimate the noise of the fixes fused, as the
        # autopilot EKFs keep gated fixes out of everything.
        self._learn_rejected = bool(getattr(self.method, "learns_from_rejected", False))
        self._counts = counts if counts is not None else {}
        for name in (
            "imu_used", "imu_gaps", "imu_rejected_nonfinite", "imu_rejected_time_backwards",
            "imu_rejected_out_of_range", "gnss_fused", "gnss_refused", "gnss_out_of_order",
            "gnss_rejected_before_imu", "gnss_rejected_too_old", "gnss_rejected_future",
            "gnss_rejected_duplicate", "gnss_rejected_nonfinite", "gnss_rejected_innovation", "gnss_resets",
            "gnss_offsets", "gnss_vel_fused", "gnss_vel_rejected_innovation", "imu_gnss_disagreements",
            "envelope_violations", "gnss_offset_returns",
        ):
            self._counts.setdefault(name, 0)
        super().__init__(cfg.imu_hold_max_s, cfg.history_s, cfg.future_tolerance_s, cfg.gravity_m_s2,
                         self._counts, cfg.imu_hold_periods)
        self._tested = 0  # fixes that reached the innovation test (fused = this − rejected)
        self._r_nominal: Vec3 = tuple(float(v) for v in cfg.r_nominal_m2().diagonal())  # type: ignore[assignment]
        self._q_acc = cfg.sigma_acc_m_s2**2
        self._q_rw = cfg.sigma_acc_bias_rw_m_s2_sqrt_s**2
        self._q_ned = cfg.sigma_acc_ned_rw_m_s2_sqrt_s**2
        # held IMU time (history.py, "Held time"): the white density's share and the acceleration's change;
        # a coast the acceleration it drops (1: on)
        q_hold = cfg.imu_hold_acc_rw_m_s2_sqrt_s**2
        self._prop = model.BlockPropagator(self._q_acc, self._q_rw, self._q_ned, self._q_acc, q_hold, 1.0)
        # while the IMU disagrees with GNSS: the white-acceleration density inflated
        q_distrust = self._q_acc * cfg.imu_gnss_disagree_acc_factor**2
        self._prop_disagree = model.BlockPropagator(q_distrust, self._q_rw, self._q_ned, q_distrust, q_hold,
                                                    1.0)
        self._gate2 = cfg.gnss_gate_sigma**2
        self._vel_gate2 = cfg.gnss_vel_gate_sigma**2
        self._scale_tau_s = cfg.gnss_scale_tau_s
        h, d = cfg.sigma_gnss_velocity_m_s**2, cfg.sigma_gnss_velocity_vertical_m_s**2
        self._rv_default: Vec3 = (h, h, d)
        self._noise_tau_s = cfg.gnss_noise_tau_s
        self._noise_bias_m = cfg.sigma_gnss_unreported_bias_m
        self._decay_cache: dict[int, tuple[float, float, float, float, float, float, float]] = {}
        self._reset_var = (cfg.sigma_bias0_m**2, cfg.gnss_reset_sigma_vel_m_s**2,
                           (cfg.sigma_acc_bias0_m_s2**2, cfg.sigma_acc_ned0_m_s2**2))
        self._v_max2 = cfg.envelope_speed_max_m_s**2
        self._vd_max = cfg.envelope_speed_vertical_max_m_s
        self._a_max = cfg.envelope_acc_max_m_s2
        self._acc_window_s = cfg.envelope_acc_window_s
        self._dv_max2 = (cfg.envelope_acc_max_m_s2 * cfg.envelope_acc_window_s) ** 2
        self._dis_tau_s = cfg.imu_gnss_disagree_tau_s
        self._dis_on, self._dis_off = cfg.imu_gnss_disagree_on, cfg.imu_gnss_disagree_off
        self._dis_clip = self._gate2  # one NIS per dof counts at most gate² (a single outlier)
        self._gate_r_min = cfg.gnss_gate_r_floor_m**2
        self._r_max = cfg.r_learned_max_factor
        self._r_max_blind = min(cfg.r_learned_max_factor, cfg.r_learned_max_factor_unreported)
        self._reset_us = int(round(cfg.gnss_reset_timeout_s * 1e6))
        self._offset_open_us = int(round(cfg.gnss_offset_open_s * 1e6))
        self._offset_max_us = int(round(cfg.gnss_offset_max_s * 1e6))
        self._return_us = int(round(cfg.gnss_offset_return_s * 1e6))
        self._valid_us = int(round(cfg.pos_valid_timeout_s * 1e6))
        self._tau_s = cfg.bias_tau_s
        self._window_s = cfg.accuracy_window_s
        self._bias_level = cfg.lambda_bias_level > 0.0  # the belief's bias-level term reads bias_m2

    @property
    def fusions(self) -> list[Fusion]:
        """The entries, in time order (``Timeline.entries``)."""
        return self.entries

    @property
    def counts(self) -> dict[str, int]:
        """Samples used and rejected by reason (the dict given to the constructor, updated)."""
        self._counts.update(zip(_IMU_COUNTS, self.imu.counts, strict=True))
        return self._counts

    # ---------------------------------------------------------------- GNSS
    def push_fix(self, t_us: int, z_ned_m: Any, r_nominal_m2: Vec3 | None = None,
                 v_ned_m_s: Any = None, rv_m2: Vec3 | None = None) -> None:
        """A GNSS position (NED, m; 3 numbers) valid at ``t_us``; fused now, later, or rejected.

        ``r_nominal_m2``: this fix's nominal R (NED variances, m²), e.g. from the receiver's
        reported accuracy; None = the config's ``r_nominal_m2``. ``v_ned_m_s``: the receiver's
        velocity valid at the same time (NED, m/s; a component it does not report NaN; None: no
        velocity) with its variances ``rv_m2`` ((m/s)²; None: the config's
        ``sigma_gnss_velocity*``): fused beside the position, with its own gate."""
        c = self._counts
        if type(z_ned_m) is not tuple:  # the navigator's are tuples of floats already
            z_ned_m = tuple(z_ned_m.tolist() if isinstance(z_ned_m, np.ndarray) else map(float, z_ned_m))
        z = z_ned_m
        if len(z) != 3 or not finite3(*z):
            c["gnss_rejected_nonfinite"] += 1
            return
        r = self._r_nominal if r_nominal_m2 is None else r_nominal_m2
        # each > 0 (NaN > 0 is False); +inf: learned (north and east alike)
        if not (len(r) == 3 and r[0] > 0.0 and r[1] > 0.0 and r[2] > 0.0
                and (r[0] == _INF) == (r[1] == _INF)):
            c["gnss_rejected_nonfinite"] += 1
            return
        zv = None if v_ned_m_s is None else self._velocity(v_ned_m_s, rv_m2)
        self._push(t_us, _Fix(t_us, z, r, zv[0] if zv else None, zv[1] if zv else _NAN3))

    def _velocity(self, v: Any, rv: Vec3 | None) -> tuple[Vec3, Vec3] | None:
        """(velocity, its variances) with the components not reported (not finite, or their
        variance not finite and > 0) as NaN; None when none is reported."""
        if rv is None:
            rv = self._rv_default
        vals = v.tolist() if isinstance(v, np.ndarray) else v
        if len(vals) != 3 or len(rv) != 3:
            return None
        nan, isfinite = math.nan, math.isfinite
        v0, v1, v2 = float(vals[0]), float(vals[1]), float(vals[2])
        ok0 = isfinite(v0) and rv[0] > 0.0 and rv[0] < _INF  # NaN comparisons are False
        ok1 = isfinite(v1) and rv[1] > 0.0 and rv[1] < _INF
        ok2 = isfinite(v2) and rv[2] > 0.0 and rv[2] < _INF
        if not (ok0 or ok1 or ok2):
            return None
        return ((v0 if ok0 else nan, v1 if ok1 else nan, v2 if ok2 else nan),
                (rv[0] if ok0 else nan, rv[1] if ok1 else nan, rv[2] if ok2 else nan))

    def _measurement(self, e: Fusion) -> _Fix | None:
        return None if e.z_ned_m is None else _Fix(e.t_us, e.z_ned_m, e.r_nominal_m2, e.zv_ned_m_s, e.rv_m2)

    def _inserted(self) -> None:
        self._tested += 1
        self._count()

    def _count(self) -> None:
        """Gate counters from the newest entry (cumulative there, so exact after a re-fusion)."""
        last, c = self.entries[-1], self._counts
        c["gnss_rejected_innovation"] = last.n_rejected
        c["gnss_resets"] = last.n_resets
        c["gnss_offsets"] = last.n_offsets
        c["gnss_offset_returns"] = last.n_returns
        c["gnss_fused"] = self._tested - last.n_rejected
        c["gnss_vel_fused"] = last.n_vel_tested - last.n_vel_rejected
        c["gnss_vel_rejected_innovation"] = last.n_vel_rejected
        c["imu_gnss_disagreements"] = last.n_disagree
        c["envelope_violations"] = last.n_invalid

    def _start(self, t_us: int, fix: _Fix) -> Fusion:
        z, zv = fix.z, fix.zv
        s0 = self.cfg.sigma_gnss_unreported_m**2
        r: Vec3 = (s0 if fix.r[0] == math.inf else fix.r[0], s0 if fix.r[1] == math.inf else fix.r[1],
                   s0 if fix.r[2] == math.inf else fix.r[2])
        x = (*z, *(0.0,) * (model.N_STATE - 3))
        f = self.cfg.bias_scale(r[0])  # the receiver's scale of the bias range (1 for a decimetre receiver)
        P = model.initial_cov(self.cfg, r, f)
        if zv is not None:  # the receiver's velocity where it gives one
            x, P = model.reset_to_fix(x, P, z, r, (self.cfg.sigma_bias0_m * f) ** 2, zv, fix.rv)
        state = self.method.initial_state()
        beta = self.method.beta(state)
        return Fusion(t_us, z, x, P, state, math.nan, self.imu.integrals(t_us),
                      beta, self.cfg.sigma_bias_m(beta) * f,
                      fix.r, t_us, math.nan, False, 0, 0, None, 0, 0, None, 0, 0, zv, fix.rv,
                      scale_h_m=_SCALE_H * math.sqrt(r[0]), scale_v_m=_SCALE_V * math.sqrt(r[2]),
                      noise_h_m=_SCALE_H * math.sqrt(r[0]), noise_v_m=_SCALE_V * math.sqrt(r[2]),
                      v_smooth=(x[3], x[4], x[5]), bias_scale=f,
                      scatter=Scatter().add(t_us, (z[0], z[1]), (x[3], x[4]), self._window_s)
                      if self._window_s > 0.0 else Scatter(),
                      scatter_v=Scatter1().add(t_us, z[2], x[5], self._window_s)
                      if self._window_s > 0.0 else Scatter1())

    def _fuse(self, prev: Fusion, t_us: int, fix: _Fix) -> Fusion:
        """Predict the last entry to the fix's time, test it there and fuse it (Algorithm 1, lines
        7-17). Position and velocity are tested against the prior, each with its own gate; the
        velocity is fused whenever it passes its gate. A position failing the gate

        * while an offset hypothesis is open and ``z`` − offset passes: fused as ``z`` − offset
          (the step's fixes still observe velocity);
        * while no fix passed for ``gnss_reset_timeout_s``, when the offset has been open for
          ``gnss_offset_max_s``, or when the estimate left the vehicle's envelope (fly-away guard):
          resets position, velocity and the IMU error states to the GNSS (``model.reset_to_fix``);
        * right after a fused fix (within ``gnss_offset_open_s``): a step, opens the offset
          hypothesis (offset = its innovation; the fix itself is not fused);
        * otherwise: rejected.
        A fix that passes the gate without the offset closes it (the fixes stepped back)."""
        _, z, r_given, zv, rv = fix
        T = (t_us - prev.t_us) * 1e-6
        alpha, w_dis, w_acc, k, ek, kn, ekn = self._decays(t_us - prev.t_us)
        sigma_b = prev.sigma_bias_m
        q_bias_unit = 1.0 - alpha * alpha
        q_b = q_bias_unit * sigma_b * sigma_b
        ints = self.imu.integrals(t_us)
        t = self._test(prev, fix, ints, T, alpha, q_bias_unit, q_b, prev.disagree)
        switched = False
        if (zv is not None and not t[_VEL_OK] and not prev.disagree and prev.vel_ratio > 1.0
                and self._gnss_consistent(prev, z, zv, rv, t[_R_NOM], T)):  # type: ignore[arg-type]
            # the IMU-propagated motion persistently (this fix and the last) disagrees with a
            # self-consistent GNSS: would the fix pass if the IMU were distrusted (its
            # white-acceleration density inflated)?
            t_dis = self._test(prev, fix, ints, T, alpha, q_bias_unit, q_b, True)
            if t_dis[_VEL_OK]:
                t, switched = t_dis, True
        x_prior, P_prior, hph, y, s0, terms, R, ratio, passes, r_nom, floor_h, floor_v, nis_v, vel_ok, \
            vel_ratio, k_max = t
        n_rej, n_res, n_off = prev.n_rejected, prev.n_resets, prev.n_offsets
        n_vt, n_vr = prev.n_vel_tested, prev.n_vel_rejected
        if zv is not None:
            n_vt += 1
            n_vr += not vel_ok
        off, t_off, t_fused = prev.offset, prev.t_offset_us, prev.t_fused_us
        acc, t_acc, n_ret = prev.accepted, prev.t_accepted_us, prev.n_returns
        glitch, rejected, fused_pos, reset, held = True, False, True, False, False
        hold_ref, hold_obs, ramp, track = prev.hold_ref, prev.hold_obs, prev.ramp, False
        shift: Vec3 | None = None  # moves the position after the update: an offset accepted, or a return
        y_fused, R_fused, terms_fused = y, R, terms
        if passes:  # closes an open offset: the fixes stepped back
            off, t_off, glitch = None, 0, False
        else:
            fused_pos = False
            if off is not None:  # the step still holds (the fix passes relative to the offset)?
                rel = self._relative(prev.state, terms, off, hph, floor_h, floor_v, k_max)
                if rel is not None and t_us - t_off >= self._offset_max_us:
                    # it lasted: the GNSS's new track (EKF2/EKF3 reset into it): the position moves onto
                    # this fix, which is fused with that zero innovation
                    fused_pos, shift, y_fused = True, y, (0.0, 0.0, 0.0)
                    R_fused, terms_fused = rel[1], rel[2]
                    acc, t_acc, n_res, glitch, off, t_off = y, t_us, n_res + 1, False, None, 0
                elif rel is not None and vel_ok:  # held on the receiver's velocity: dead reckoning
                    held, t_fused = True, t_us  # (fusing z − offset would drag the estimate with a fade)
                elif rel is not None and hold_ref is not None:
                    hold_obs, dr = self._hold_residual(hold_ref, hold_obs, t_us, z, ints)
                    is_ramp, imu_wrong = self._ramp_or_heading(hold_obs, r_nom[0], hold_ref[5])
                    if not ramp and is_ramp:
                        # a ramp of the fixes, the IMU right: dead reckoning from the opening (what the
                        # fixes relative to the offset dragged is undone)
                        ramp, (x_prior, P_prior), xd = True, dr, dr[0]
                        y = (z[0] - xd[0] - xd[6], z[1] - xd[1] - xd[7], z[2] - xd[2] - xd[8])
                    elif ramp and imu_wrong:  # the IMU found wrong after all: back to the fixes, untested
                        ramp, hold_ref = False, None
                    if ramp:  # held on the IMU; the offset follows the ramp (tested fix to fix)
                        held, t_fused, track = True, t_us, True
                    else:  # held, the fixes relative to it observing velocity (a wrong attitude)
                        fused_pos, (y_fused, R_fused, terms_fused) = True, rel
                elif rel is not None:  # held, the fixes relative to it observing velocity (without a
                    fused_pos, (y_fused, R_fused, terms_fused) = True, rel  # receiver velocity, a fade drags)
            if not fused_pos and not held and acc is not None and t_us - t_acc <= self._return_us:
                back = (-acc[0], -acc[1], -acc[2])  # the fix is back on the track kept before the step?
                rel = self._relative(prev.state, terms, back, hph, floor_h, floor_v, k_max)
                if rel is not None:
                    fused_pos, (y_fused, R_fused, terms_fused) = True, rel
                    shift, acc, t_acc, n_ret, glitch, off, t_off = back, None, 0, n_ret + 1, False, None, 0
        fit = prev.fit
        if fused_pos:
            x_post, P_post, nis = _update(x_prior, P_prior, y_fused, R_fused)
            if self._window_s > 0.0:  # each axis' innovation over the S it was fused with
                fit = fit_add3(fit, t_us, y_fused[0] / math.sqrt(hph[0][0] + R_fused[0]),
                               y_fused[1] / math.sqrt(hph[1][1] + R_fused[1]),
                               y_fused[2] / math.sqrt(hph[2][2] + R_fused[2]), self._window_s)
            state = self.method.update(prev.state, terms_fused)
            t_fused = t_us
            if shift is not None:
                x_post = (x_post[0] + shift[0], x_post[1] + shift[1], x_post[2] + shift[2], *x_post[3:])
        elif held:
            x_post, P_post, nis, state = x_prior, P_prior, _nis(y, hph, R), prev.state
        elif t_us - t_fused >= self._reset_us or prev.invalid:
            x_reset = x_prior
            if zv is None and self._outside_envelope(x_prior):  # a velocity no vehicle flies: zero (EKF2)
                x_reset = (*x_prior[0:3], 0.0, 0.0, 0.0, *x_prior[6:])
            x_post, P_post = model.reset_to_fix(x_reset, P_prior, z, r_nom, self._reset_var[0], zv, rv,
                                                self._reset_var[1], self._reset_var[2])
            state, nis, t_fused, glitch, reset = prev.state, _nis(y, hph, R), t_us, False, True
            off, t_off, n_res, vel_ok, acc, t_acc = None, 0, n_res + 1, False, None, 0
        else:  # rejected: the entry carries the prior; only a belief learns from the fix
            rejected = True
            x_post, P_post, nis = x_prior, P_prior, _nis(y, hph, R)
            state = self.method.update(prev.state, terms) if self._learn_rejected else prev.state
            if t_us - t_fused <= self._offset_open_us:  # a step in a consistent stream: (re)open the offset
                off, t_off, n_off = y, t_us, n_off + 1
                # dead reckoning from here is tested only from a state the fixes confirmed: the fix before
                # passed the gate on its own (not a step re-opened while its fixes wandered); the velocity
                # known to the filter's σ, widened by that fix's NIS per dof (covariance matching), and no
                # better than it agrees with the fixes' own velocity there (``receiver_spread``'s u over
                # the last block plus the IMU's velocity change over it: independent of the filter's state)
                nis_prev = prev.test_ratio * self._gate2 * 0.5
                sv2 = max(P_prior[3, 3], P_prior[4, 4]) * (nis_prev if nis_prev > 1.0 else 1.0)
                if prev.u_ned_m_s is not None and prev.block_s > 0.0:
                    dvn = prev.x[3] - prev.u_ned_m_s[0] - prev.dv_imu_m_s[0]
                    dve = prev.x[4] - prev.u_ned_m_s[1] - prev.dv_imu_m_s[1]
                    # less what the two fixes' own noise puts into u (2 R / T² per axis)
                    sv2 = max(sv2, dvn * dvn + dve * dve - 4.0 * r_nom[0] / (prev.block_s * prev.block_s))
                hold_ref = None if prev.glitch else (t_us, x_prior, P_prior, ints, prev.sigma_bias_m, sv2, y)
                hold_obs, ramp = ((0.0,) * 5,), False
        if off is None:
            hold_ref, hold_obs, ramp = None, (), False
        if vel_ok:
            x_post, P_post = _core.update_vel(x_post, P_post, zv, rv)
        scatter, scatter_v = prev.scatter, prev.scatter_v
        if fused_pos and self._window_s > 0.0:  # the fix as fused (less an open offset) and the receiver's
            v_h = (x_post[3], x_post[4])  # velocity (the filter's where it gives none)
            if vel_ok and zv is not None and zv[0] == zv[0] and zv[1] == zv[1]:
                v_h = (zv[0], zv[1])
            z_h = (x_prior[0] + x_prior[6] + y_fused[0], x_prior[1] + x_prior[7] + y_fused[1])
            scatter = scatter.add(t_us, z_h, v_h, self._window_s)
            v_d = zv[2] if vel_ok and zv is not None and zv[2] == zv[2] else x_post[5]
            scatter_v = scatter_v.add(t_us, x_prior[2] + x_prior[8] + y_fused[2], v_d, self._window_s)
        # the innovation the decision was made on: relative to a held step (so a step held does not
        # widen the gate until it passes), else the fix's own
        yd = y_fused if fused_pos else (
            (y[0] - off[0], y[1] - off[1], y[2] - off[2]) if held and off is not None else y)
        if track:
            off = y
        # the receiver's running centres (C core, the formulas below): its innovations' spread, and its
        # own noise: the change of u = (z − z_prev − D_imu) / T between blocks, less the IMU's velocity
        # change over the previous block, is white GNSS noise (variance σ² c) whatever the state
        scale_h, scale_v, noise_h, noise_v, u, dv_imu = _core.receiver_spread(
            prev.ints, ints, z, prev.z_ned_m, prev.u_ned_m_s, prev.dv_imu_m_s, prev.block_s, T, yd,
            (prev.scale_h_m, prev.scale_v_m, prev.noise_h_m, prev.noise_v_m), k, ek, kn, ekn)
        # IMU / GNSS disagreement, on the velocity innovations (position fixes alone cannot tell a
        # wrong attitude from a GNSS bias)
        level = prev.disagree_level
        e = nis_v
        if e == e:
            level += w_dis * ((e if e < self._dis_clip else self._dis_clip) - level)
        if switched:
            level = level if level > self._dis_on else self._dis_on
        disagree = switched or level > self._dis_on or (prev.disagree and level > self._dis_off)
        # fly-away guard: the velocity smoothed over acc_window_s (so (v − v̄)/window is the mean
        # acceleration over about that window, the updates' corrections included)
        v0, v1, v2 = x_post[3], x_post[4], x_post[5]
        if reset:
            vs = (v0, v1, v2)
        else:
            ps = prev.v_smooth
            vs = (ps[0] + w_acc * (v0 - ps[0]), ps[1] + w_acc * (v1 - ps[1]), ps[2] + w_acc * (v2 - ps[2]))
        a2 = (v0 - vs[0]) ** 2 + (v1 - vs[1]) ** 2 + (v2 - vs[2]) ** 2
        invalid = self._outside_envelope(x_post) or a2 > self._dv_max2
        beta = self.method.beta(state)
        f = self.cfg.bias_scale(r_nom[0])
        if reset and f != 1.0:  # the reset's bias prior at the receiver's scale (model.reset_to_fix's form)
            P_post = model.scale_bias_prior(P_post, f, self._reset_var[0])
        return _new(Fusion, (  # every field, in order (Fusion(...) without its generated __new__'s call)
            t_us, z, x_post, P_post, state, nis, ints, beta, self.cfg.sigma_bias_m(beta) * f,
            r_given, t_fused, ratio, glitch, n_rej + rejected, n_res, off, t_off, n_off, acc, t_acc, n_ret,
            zv, rv, vel_ratio,
            n_vt, n_vr, level, disagree, prev.n_disagree + (disagree and not prev.disagree), scale_h, scale_v,
            u, dv_imu, T, noise_h, noise_v, vs, invalid, prev.n_invalid + invalid, f, fit,
            hold_ref, hold_obs, ramp, scatter, scatter_v))

    def _hold_residual(self, ref: tuple[Any, ...], obs: tuple[Any, ...], t_us: int, z: Vec3, ints: Integrals
                       ) -> tuple[tuple[Any, ...], tuple[model.State, model.Cov]]:
        """``obs`` with this fix's horizontal residual against dead reckoning from the step's opening
        ``ref`` (z − the offset opened there − the opening's state carried on the IMU alone) and the IMU's
        own displacement D over that time; and that dead reckoning (x⁻, P⁻)."""
        t0, x0, P0, ints0, sigma_b, _, off = ref
        T = (t_us - t0) * 1e-6
        alpha = math.exp(-T / self._tau_s)
        q_b = (1.0 - alpha * alpha) * sigma_b * sigma_b
        x, P = self._prop.predict_from(x0, P0, ints0, ints, T, alpha, q_b)[0:2]
        tb = ints[0]
        d0 = tb * (ints[1] - ints0[1]) - (ints[4] - ints0[4])
        d1 = tb * (ints[2] - ints0[2]) - (ints[5] - ints0[5])
        r0 = z[0] - off[0] - x[0] - x[6]
        r1 = z[1] - off[1] - x[1] - x[7]
        return (*obs, (T, r0, r1, d0, d1)), (x, P)

    def _ramp_or_heading(self, obs: tuple[Any, ...], r_h: float, sv2: float) -> tuple[bool, bool]:
        """(a ramp of the fixes with the IMU right, the IMU's heading wrong) from ``_hold_fit``'s χ²: a ramp
        when it explains the drift better than any heading by more than gate² in the spread the fixes
        show (the evidence a fix needs to fail the gate) and a heading on top of it adds no more than
        gate²; the heading wrong when it adds more (the safe side: in the noise the model states)."""
        chi_ramp, chi_head, chi_both, s2 = self._hold_fit(obs, r_h, sv2)
        imu_wrong = chi_ramp - chi_both > self._gate2
        return (not imu_wrong and chi_head - chi_ramp > self._gate2 * s2), imu_wrong

    def _hold_fit(self, obs: tuple[Any, ...], r_h: float, sv2: float) -> tuple[float, float, float, float]:
        """Least-squares χ² of three explanations of the held fixes' drift against dead reckoning from
        the step's opening (``obs``: ``_hold_residual``'s; each residual's σ² the receiver's noise ``r_h``
        plus the dead reckoning's own spread over t, the filter's white-acceleration density σ_acc² t³/3):

        * a ramp of the fixes, r = a + b t (a fading reflection: the IMU right, the fixes moving at a
          rate b of their own);
        * the attitude's heading wrong by some angle δ, r = a + e t + (R(δ) − I) D (the fly-away: the
          IMU's horizontal specific force turned by δ, its magnitude kept; D the IMU's displacement since
          the opening; e the velocity error there, ~ N(0, ``sv2``) per axis);
        * both, r = a + b t + (R(δ) − I) D.

        and the scale s² ≥ 1 of the residuals' σ² the ramp leaves (its χ² per degree of freedom: real fixes
        wander more than their learned noise, so the comparison is made in the spread they show).
        A constant step (b = 0) is explained by all three alike; fewer than 4 fixes: (0, 0, 0, 1)."""
        n = len(obs)
        if n < 4:
            return 0.0, 0.0, 0.0, 1.0
        o = np.asarray(obs)
        t = o[:, 0]
        w = 1.0 / np.sqrt(r_h + self._q_acc * t * t * t / 3.0)
        zero, tw, dn, de = np.zeros(n), t * w, o[:, 3] * w, o[:, 4] * w
        # rows N, E, then the prior on e (the heading model's only); columns a_N, a_E, b_N / e_N, b_E / e_E
        m = 2 * n
        X = np.zeros((m + 2, 4))
        X[:n] = np.column_stack((w, zero, tw, zero))
        X[n:m] = np.column_stack((zero, w, zero, tw))
        X[m, 2] = X[m + 1, 3] = 1.0 / math.sqrt(sv2)
        y = np.concatenate((o[:, 1] * w, o[:, 2] * w, (0.0, 0.0)))
        # (R(δ) − I) D = (cos δ − 1) u + sin δ v: u = D, v = D turned by 90°
        u = np.concatenate((dn, de, (0.0, 0.0)))
        v = np.concatenate((-de, dn, (0.0, 0.0)))
        ramp = X[:m]
        chi_ramp = float(np.sum((y[:m] - ramp @ np.linalg.lstsq(ramp, y[:m], rcond=None)[0]) ** 2))
        s2 = chi_ramp / (m - 4)
        return (chi_ramp, _min_over_headings(X, y, u, v), _min_over_headings(ramp, y[:m], u[:m], v[:m]),
                s2 if s2 > 1.0 else 1.0)

    def _outside_envelope(self, x: model.State) -> bool:
        """The speed of ``x`` outside the vehicle's envelope (horizontal or vertical)."""
        return x[3] * x[3] + x[4] * x[4] > self._v_max2 or abs(x[5]) > self._vd_max

    def _decays(self, dt_us: int) -> tuple[float, float, float, float, float, float, float]:
        """(α(T) of the GNSS bias, the disagreement mean's and the smoothed velocity's weights
        1 − e^(−T/τ), the running centres' rates k = min(1, T/τ) and e^k: the innovation spread's and
        the receiver noise's) for T = ``dt_us``; cached by interval (fixes come at a few fixed rates)."""
        d = self._decay_cache.get(dt_us)
        if d is None:
            T = dt_us * 1e-6
            k, kn = min(1.0, T / self._scale_tau_s), min(1.0, T / self._noise_tau_s)
            d = (math.exp(-T / self._tau_s), 1.0 - math.exp(-T / self._dis_tau_s),
                 1.0 - math.exp(-T / self._acc_window_s), k, math.exp(k), kn, math.exp(kn))
            if len(self._decay_cache) > 256:
                self._decay_cache.clear()
            self._decay_cache[dt_us] = d
        return d

    def _test(self, prev: Fusion, fix: _Fix, ints: Integrals, T: float, alpha: float, q_bias_unit: float,
              q_b: float, distrust_imu: bool) -> _Test:
        """The prior at the fix (``prev`` predicted with the nominal or, ``distrust_imu``, the inflated
        IMU noise) and the fix tested against it: position (its R, learned where not reported, and
        the gate's floors) and velocity, as a plain tuple (``_Test``'s fields, in that order)."""
        z, r_given, zv, rv = fix.z, fix.r, fix.zv, fix.rv
        prop = self._prop_disagree if distrust_imu else self._prop
        # H P⁻ Hᵀ (3×3): the body-frame bias correlates axes
        x_prior, P_prior, hph, pht_p = prop.predict_from(prev.x, prev.P, prev.ints, ints, T, alpha, q_b)
        y = (z[0] - x_prior[0] - x_prior[6], z[1] - x_prior[1] - x_prior[7], z[2] - x_prior[2] - x_prior[8])
        s0 = (hph[0][0] - q_b, hph[1][1] - q_b, hph[2][2] - q_b)
        # the receiver's own spread (innovations minus the prediction's share): the gate's floor, and
        # the R of a fix without a reported accuracy
        sh, sv = prev.scale_h_m / _SCALE_H, prev.scale_v_m / _SCALE_V
        spread_h, spread_v = sh * sh - 0.5 * (hph[0][0] + hph[1][1]), sv * sv - hph[2][2]
        r_nom = r_given
        if r_given[0] == math.inf or r_given[2] == math.inf:  # not reported: the receiver's own noise
            h, v = self.learned_r_m2(prev)
            h = r_given[0] if r_given[0] != math.inf else h
            r_nom = (h, h, r_given[2] if r_given[2] != math.inf else v)
        floor_h = spread_h if spread_h > self._gate_r_min else self._gate_r_min
        floor_v = spread_v if spread_v > self._gate_r_min else self._gate_r_min
        bias_m2 = (x_prior[6] * x_prior[6] + P_prior[6, 6], x_prior[7] * x_prior[7] + P_prior[7, 7],
                   x_prior[8] * x_prior[8] + P_prior[8, 8]) if self._bias_level else _ZERO3  # read only by it
        terms = _new(InnovationTerms, (y, s0, q_bias_unit, r_nom, pht_p, prev.bias_scale, bias_m2))  # all 7
        # a receiver stating neither its accuracy nor a velocity: innovations beyond its own noise may be
        # the IMU's fault (a wrong attitude), so an R-learner may not learn much more than that noise
        k_max = self._r_max_blind if (r_given[0] == math.inf and zv is None) else self._r_max
        R = self._r_of(prev.state, terms, r_nom, k_max)
        ratio, passes = self._gate(y, hph, R, floor_h, floor_v)
        nis_v, vel_ok, vel_ratio = math.nan, False, math.nan
        if zv is not None:
            nis_vh, nis_vd = _core.vel_nis(x_prior, P_prior, zv, rv)
            vel_ratio = nis_vh / self._vel_gate2
            vel_ok = nis_vh <= self._vel_gate2 and nis_vd <= self._vel_gate2
            n_h = (zv[0] == zv[0]) + (zv[1] == zv[1])  # horizontal components reported (NaN != NaN)
            nis_v = nis_vh / n_h if n_h else math.nan
        return (x_prior, P_prior, hph, y, s0, terms, R, ratio, passes, r_nom, floor_h, floor_v, nis_v,
                vel_ok, vel_ratio, k_max)

    def learned_r_m2(self, entry: Fusion) -> tuple[float, float]:
        """(horizontal, vertical) R (m², per axis) of a fix without a reported accuracy fused after ``entry``:
        the receiver's learned noise, less the share a Gauss-Markov bias of ``sigma_gnss_unreported_bias_m``
        adds to it (``model.bias_share_of_noise_m2`` over ``entry``'s block; 0: none), floored at the
        configured ``sigma_gnss_*``."""
        nh, nv = entry.noise_h_m / _SCALE_H, entry.noise_v_m / _SCALE_V
        nh, nv = nh * nh, nv * nv
        if self._noise_bias_m > 0.0 and entry.block_s > 0.0:
            share = model.bias_share_of_noise_m2(self._noise_bias_m, entry.block_s, self._tau_s)
            nh, nv = nh - share, nv - share
        r0, r2 = self._r_nominal[0], self._r_nominal[2]
        return (nh if nh > r0 else r0), (nv if nv > r2 else r2)

    def _gnss_consistent(self, prev: Fusion, z: Vec3, zv: Vec3, rv: Vec3, r_nom: Vec3, T: float) -> bool:
        """The receiver agrees with itself since the previous fix: its horizontal position change over
        T equals the mean of its two velocities within 5σ (both positions' R, both velocities' R and
        an acceleration changing by up to the envelope's over T)."""
        pz, pv = prev.z_ned_m, prev.zv_ned_m_s
        if pz is None or pv is None or T <= 0.0:
            return False
        for i in (0, 1):
            d = (z[i] - pz[i]) / T - 0.5 * (zv[i] + pv[i])
            var = 2.0 * r_nom[i] / (T * T) + 0.25 * (rv[i] + prev.rv_m2[i]) + (0.25 * self._a_max * T) ** 2
            if not d * d <= 25.0 * var:  # NaN (a component not reported) is not consistent
                return False
        return True

    def _relative(self, state: Any, terms: InnovationTerms, off: Vec3, hph: _Hph, floor_h: float,
                  floor_v: float, k_max: float) -> tuple[Vec3, Vec3, InnovationTerms] | None:
        """(innovation, R, terms) of the fix relative to the offset ``off`` (y − off) if that passes
        the gate, else None."""
        y = terms.y
        y_off = (y[0] - off[0], y[1] - off[1], y[2] - off[2])
        terms_off = terms._replace(y=y_off)
        R_off = self._r_of(state, terms_off, terms.r_nominal, k_max)
        if self._gate(y_off, hph, R_off, floor_h, floor_v)[1]:
            return y_off, R_off, terms_off
        return None

    def _r_of(self, state: Any, terms: InnovationTerms, r_nom: Vec3, k: float) -> Vec3:
        """The method's R for this fix, bounded by ``k`` × the nominal R."""
        R = self.method.measurement_cov(state, terms)
        if R[0] > k * r_nom[0] or R[1] > k * r_nom[1] or R[2] > k * r_nom[2]:
            R = (min(R[0], k * r_nom[0]), min(R[1], k * r_nom[1]), min(R[2], k * r_nom[2]))
        return R

    def _gate(self, y: Vec3, hph: _Hph, R: Vec3, g: float, gv: float) -> tuple[float, bool]:
        """(horizontal NIS / gate², passed): horizontal NIS (2 dof, the 2×2 block of S) and
        vertical NIS (1 dof) against gate², R floored at ``g`` (horizontal) and ``gv`` (vertical):
        ``gnss_gate_r_floor_m``² or the receiver's spread."""
        r0, r1, r2 = R
        s00, s01, s11 = hph[0][0] + (r0 if r0 > g else g), hph[0][1], hph[1][1] + (r1 if r1 > g else g)
        s2 = hph[2][2] + (r2 if r2 > gv else gv)
        nis_h = (s11 * y[0] * y[0] - 2.0 * s01 * y[0] * y[1] + s00 * y[1] * y[1]) / (s00 * s11 - s01 * s01)
        ratio = nis_h / self._gate2
        return ratio, ratio <= 1.0 and y[2] * y[2] / s2 <= self._gate2

    # ------------------------------------------------------------- history
    def _anchor(self, e: Fusion, t_us: int, ints: Integrals) -> Fusion:
        x, P = self._predict(e, t_us, ints)
        return e._replace(t_us=t_us, z_ned_m=None, x=x, P=P, ints=ints)

    def _predict(self, f: Fusion, t_us: int, ints: Integrals) -> tuple[model.State, model.Cov]:
        """Entry ``f`` predicted to ``t_us`` (whose IMU integrals are ``ints``)."""
        T = (t_us - f.t_us) * 1e-6
        alpha = math.exp(-T / self._tau_s)
        sigma_b = f.sigma_bias_m
        q_b = (1.0 - alpha * alpha) * sigma_b * sigma_b
        prop = self._prop_disagree if f.disagree else self._prop
        x, P = prop.predict_from(f.x, f.P, f.ints, ints, T, alpha, q_b)[0:2]
        return x, P

    # -------------------------------------------------------------- output
    # the filter at the newest IMU time, or None before the first fix (cached): ``Timeline._output_now``
    # itself (no call of its own: the navigator's estimate() calls it at every output)
    snapshot = Timeline._output_now

    def _output(self, last: Fusion, now: int) -> Snapshot:
        T = (now - last.t_us) * 1e-6
        alpha = math.exp(-T / self._tau_s)
        sigma_b = last.sigma_bias_m
        prop = self._prop_disagree if last.disagree else self._prop
        x, out = prop.output_from(last.x, last.P, last.ints, self.imu, T, alpha,  # its newest sample
                                  (1.0 - alpha * alpha) * sigma_b * sigma_b)
        valid = (now - last.t_fused_us <= self._valid_us and not last.invalid  # (_outside_envelope, inline)
                 and not (x[3] * x[3] + x[4] * x[4] > self._v_max2 or abs(x[5]) > self._vd_max))
        return _new(Snapshot, (now, x, out, last.beta, last.nis, last.test_ratio, last.glitch, valid,
                               last.n_rejected, last.n_resets, last.vel_ratio, last.disagree))  # every field

    def covariance_now(self) -> model.Cov | None:
        """The full covariance (15×15) at the newest IMU time (None before the first fix)."""
        if not self.entries:
            return None
        return self._predict(self.entries[-1], self.imu.last_t_us, self.imu.last_integrals())[1]


_HEADINGS = np.radians(np.arange(-179.0, 181.0))  # δ, every degree
_COS1, _SIN = np.cos(_HEADINGS) - 1.0, np.sin(_HEADINGS)


def _min_over_headings(X: np.ndarray, y: np.ndarray, u: np.ndarray, v: np.ndarray) -> float:
    """min over δ of the least-squares χ² of y = X θ + (cos δ − 1) u + sin δ v (θ free; δ every degree)."""
    Q = np.linalg.qr(X)[0]
    p, q1, q2 = y - Q @ (Q.T @ y), u - Q @ (Q.T @ u), v - Q @ (Q.T @ v)
    c, s = _COS1, _SIN
    pp, p1, p2, q11, q22, q12 = p @ p, p @ q1, p @ q2, q1 @ q1, q2 @ q2, q1 @ q2
    return float(np.min(pp + c * c * q11 + s * s * q22 - 2.0 * (c * p1 + s * p2 - c * s * q12)))


_Hph = tuple[Vec3, Vec3, Vec3]  # H P⁻ Hᵀ (3×3, nested)
_NAN3: Vec3 = (math.nan, math.nan, math.nan)
_ZERO3: Vec3 = (0.0, 0.0, 0.0)
_INF = math.inf
# ``push_fix``'s R of a fix whose receiver reports no accuracy: learned (Fusion.scale_*_m); also per
# component (an infinite horizontal or vertical variance: that one learned)
LEARN: Vec3 = (math.inf, math.inf, math.inf)
# the running centre of |innovation| (clipped log-domain mean) over σ of a zero-mean Gaussian
# innovation: 2 dof (horizontal) and 1 dof (vertical); tests/test_estimator_gate.py checks both
_SCALE_H, _SCALE_V = 1.1014, 0.6245




# What ``FusionEngine._test`` returns, in this order (a plain tuple: it is built at every fix): the prior
# at the fix (x, P), H P Hᵀ, the position innovation y, s0, its InnovationTerms, the method's R, the
# horizontal NIS / gate², passed, the nominal R (reported or learned), the gate's R floors (horizontal,
# vertical), the horizontal velocity NIS per dof (NaN: no velocity), the velocity passed its gate, its
# horizontal NIS / gate², the bound on the method's R (× the nominal)
_Test = tuple[model.State, model.Cov, "_Hph", Vec3, Vec3, InnovationTerms, Vec3, float, bool, Vec3, float,
              float, float, bool, float, float]
_R_NOM, _VEL_OK = 9, 13


class _Fix(NamedTuple):
    """A fix as the engine fuses it (also what waits for the IMU and what a re-fusion replays)."""

    t_us: int  # validity time
    z: Vec3  # position (NED, m)
    r: Vec3  # its nominal R (variances, m²)
    zv: Vec3 | None  # the receiver's velocity (NED, m/s; NaN = not reported; None: none)
    rv: Vec3  # its variances ((m/s)²)
_update = _core.update  # (x⁻, P⁻, y, R) -> (x⁺, P⁺, NIS): model.update_fast
_new = tuple.__new__  # a NamedTuple from all its fields, without its generated __new__'s Python call


def _nis(y: Vec3, hph: _Hph, r: Vec3) -> float:
    """yᵀ S⁻¹ y for S = H P⁻ Hᵀ + diag(r)."""
    i = model.inv3([[hph[0][0] + r[0], hph[0][1], hph[0][2]], [hph[1][0], hph[1][1] + r[1], hph[1][2]],
                    [hph[2][0], hph[2][1], hph[2][2] + r[2]]])
    y0, y1, y2 = y
    return (y0 * (i[0] * y0 + i[1] * y1 + i[2] * y2) + y1 * (i[3] * y0 + i[4] * y1 + i[5] * y2)
            + y2 * (i[6] * y0 + i[7] * y1 + i[8] * y2))
