"""The tightly coupled filter: pseudoranges, Doppler and odometry speed into one state, out-of-sequence
exact, on the loose filter's IMU history (``companion.estimator.history.ImuHistory``: held NED
accelerations with prefix integrals, so any interval's mean and transition are one closed-form step).

Like the loose engine (``companion.estimator.engine``) the filter is a time-ordered list of entries
(``companion.estimator.timeline.Timeline``, shared with it), each the posterior at one measurement's
time with everything needed to re-fuse the later ones: a late epoch rolls back to the entry before
it, is fused, and the later measurements are re-fused from their stored data — the same result as in
order (tested to 1e-9). Measurements valid after the newest IMU sample wait for it.

An epoch (``SatEpoch``: prepared once by ``prepare_epoch``, state-independent) is fused as

1. predict the last entry to the epoch's time;
2. (the belief rows, with a map) each satellite's prior gets the map's line of sight at the predicted
   position, over its uncertainty (``belief.blocked_probability``): a function of the predicted
   state, so re-fusion after a late epoch stays exact; with ``shadow_matching`` the map's shadows also
   give a horizontal position fix (``shadow.shadow_fix``, at the predicted state: exact too), gated against
   the prediction and fused on it (``shadow_stage`` "before") or after the pseudoranges ("after");
3. a system seen for the first time gets a clock from its satellites' median residual (σ
   ``sigma_clock0_m``); a system whose satellites all disagree with its predicted clock by more
   than ``clock_jump_m`` had a clock jump: its clock is re-initialised (counted), not the position;
4. the weighting (``weighting.py``, by name) decides each satellite's variance and whether it is
   used (innovation gate, FDE, Student-t, per-satellite belief);
5. one batch Kalman update with the used pseudoranges and their range rates (Doppler, with the
   same per-satellite inflation).

No satellite passing for ``reset_timeout_s`` re-starts position and clocks from a single-point
solution of the epoch (counted ``resets``); velocity and the IMU error states are kept.

A barometer's height (``push_baro``: one sample per ``baro_period_s``) is an entry of its own, re-fused
after a late epoch like the others: the first one (after the filter started) adds the baro offset
state ``b_baro`` (``model.I_BARO``) as the sample's height minus the filter's, so that it starts as a
relative height (its variance the filter's vertical one plus the sample's; correlated with the position
as that difference is); the later ones are a scalar update of −p_D + b_baro, gated at
``baro_gate_sigma``. Without a barometer the state stays at 21, bit for bit as before.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from companion.domain.physics import MAX_PRESSURE_ALT_M
from companion.estimator.consistency import Fit, Scatter, Scatter1
from companion.estimator.history import Integrals, mean_between
from companion.estimator.model import BlockPropagator
from companion.estimator.timeline import Timeline
from companion.gnss.atmosphere import iono_frequency_scale
from companion.gnss.constants import C_M_S
from companion.gnss.observations import GnssEpoch
from companion.gnss.spp import SppConfig, SppSolution, preload_chi2, solve_position
from companion.gnss.systems import System
from companion.tight import _tight, model, shadow, weighting
from companion.tight.belief import LineOfSight, blocked_probability, map_theta, theta_prior
from companion.tight.config import TightConfig
from companion.tight.model import (
    I_BARO,
    I_CLK,
    I_DRIFT,
    I_HEADING,
    I_YAW_BIAS,
    N_CLK,
    N_STATE,
    Frame,
    position_dop_ned,
)

_IMU_COUNTS = ("imu_used", "imu_gaps", "imu_rejected_nonfinite", "imu_rejected_time_backwards",
               "imu_rejected_out_of_range")
# initialisation and reset: the filter's own single-point solution (C/N0 + elevation weights, FDE)
SPP_INIT = SppConfig(raim=True)
# L1 ionospheric delay → each system's signal (GLONASS at its centre frequency), per clock slot
_IONO_SCALE = iono_frequency_scale(np.array([int(s) for s in model.CLOCK_SLOTS]))
_GLONASS = int(System.GLONASS)  # (an enum member's look-up costs more than the comparison)
# the loose 15-state's (p, v, a, d) block inside the tight state's covariance (the output's P15)
_IX_NAV = np.ix_(model.NAV_OF_LOOSE, model.NAV_OF_LOOSE)
# a reset also widens the position: the canyon's single-point solution is often tens of metres off
SIGMA_SPP_EXTRA_M = 10.0


class SatEpoch(NamedTuple):
    """One receiver epoch prepared for the filter (every array (m,) or (m, 3), mask applied)."""

    epoch: GnssEpoch  # as received (single-point solution at start and reset)
    key: np.ndarray  # system × 1000 + PRN
    slot: np.ndarray  # clock slot (model.CLOCK_SLOTS)
    slot_f: np.ndarray  # the same as float64 (the C core's)
    z_m: np.ndarray  # pseudorange free of satellite clock and atmosphere (m)
    r_model_m2: np.ndarray  # σ² of the C/N0 + elevation model
    r_uniform_m2: np.ndarray  # sigma_uniform_m²
    r_los_m2: np.ndarray  # σ² of a line-of-sight signal: C/N0 only (the belief inflates the rest)
    theta_prior: np.ndarray  # prior logit from C/N0 and elevation (unclamped; the map's is added at fusion)
    elevation_deg: np.ndarray
    azimuth_rad: np.ndarray  # at the frame's origin (a few hundred metres away: < 0.01°), for the map
    sat_pos_ecef_m: np.ndarray
    sat_vel_ecef_m_s: np.ndarray
    z_rate_m_s: np.ndarray  # pseudorange rate free of the satellite clock drift (NaN: none)
    r_rate_m2_s2: np.ndarray
    systems: tuple[int, ...]  # the clock slots of the epoch's systems
    # (the keys sorted (read-only, the same object for the same satellites), the order that sorts them) or
    # None: the consistency's channels in its own order (``Fit.add``'s path for the keys it holds: the same
    # sums)
    key_sorted: tuple[np.ndarray, np.ndarray] | None = None


class Speed(NamedTuple):
    """Odometry: forward speed, its variance and (NaN: none) the integral of the yaw rate since start."""

    speed_m_s: float
    r_m2_s2: float
    yaw_integral_rad: float = math.nan


class Baro(NamedTuple):
    """A barometer's height (m: the pressure altitude, any datum) and its variance (m²)."""

    height_m: float
    r_m2: float


class EpochInfo(NamedTuple):
    """What one entry's fusion did (for outputs and diagnostics)."""

    n_sats: int = 0
    n_used: int = 0
    nis: float = math.nan  # of the used pseudoranges (and range rates)
    beta_mean: float = math.nan  # mean belief of the epoch's satellites
    key: np.ndarray | None = None  # per satellite: keys, beliefs, pre-fit innovations, used
    beta: np.ndarray | None = None
    y_m: np.ndarray | None = None
    used: np.ndarray | None = None
    # the used satellites' position DOPs (N, E, D: diag of (GᵀG)⁻¹), when accuracy_floor_m > 0
    q_pos_ned: np.ndarray | None = None


class Entry(NamedTuple):
    t_us: int
    meas: SatEpoch | Speed | Baro | None  # None: an anchor (start, re-based base)
    x: np.ndarray  # posterior (never written again)
    P: np.ndarray
    ints: Integrals
    live: tuple[bool, ...]  # clock slots initialised
    state: Any  # the weighting's state after this entry (immutable)
    t_good_us: int  # last time a satellite passed
    info: EpochInfo
    # cumulative: satellites used, satellites rejected, resets, clock resets, epochs
    totals: tuple[int, int, int, int, int]
    fit: Fit  # the used pseudoranges' consistency so far (the reported accuracy's inflation)
    # the epochs' own snapshot positions' scatter and correlation, horizontal (N, E) and vertical, and the
    # last snapshot's own variances (horizontal per axis, vertical; m²): the reported accuracy's floor
    scatter_h: Scatter = Scatter()
    scatter_v: Scatter1 = Scatter1()
    fix_var_m2: tuple[float, float] = (math.nan, math.nan)
    # the last snapshot's correction for every used satellite late by its own σ, squared (N, E, D; m²:
    # snapshot.delay_bias), the reported accuracy's one-signed delays
    delay_m2: tuple[float, float, float] = (0.0, 0.0, 0.0)
    # the share of the position's variance (N + E, D) the last epoch's update kept, P⁺/P⁻: the filter's memory
    # of its past epochs, per epoch (the reported accuracy's averaging of a correlated error)
    kept: tuple[float, float] = (1.0, 1.0)
    baro_gated_since_us: int = -1  # the barometer's first gated sample since its last fused (-1: none)


def prepare_epoch(epoch: GnssEpoch, frame: Frame, cfg: TightConfig, klobuchar: Any = None,
                  atmosphere_m: np.ndarray | None = None) -> SatEpoch | None:
    """The state-independent part of an epoch, at the frame's origin (elevation, azimuth, atmosphere,
    σ model, C/N0 and elevation prior). Observations without a finite pseudorange or satellite
    position, or below the elevation mask, are dropped. ``atmosphere_m``: (n,) the raw pseudoranges'
    atmospheric delays when already known
    (``satcache.AtmosphereCache``), else computed here.

    σ models (``companion.gnss.spp.sigma_model_m``'s, written out for speed and tested equal):
    "cn0-elevation" σ² = a² + b² w / sin² el and the line-of-sight σ² = a² + c² w, with
    w = 10^((C/N0_ref − C/N0)/10), sin el floored at 0.05, GLONASS σ × ``glonass_sigma_factor``.

    A receiver's raw epoch with its satellite states and atmosphere known and every observation kept is
    prepared in C (``_tight.prepare``: the same arithmetic element by element; its ``arcsin``,
    ``arctan2``, power and 3-term dot products rounded by the C library, not numpy's: equal to within
    1e-12 relative, tested); any other epoch by the numpy below."""
    if atmosphere_m is not None and not epoch.corrected:
        ids = _epoch_ids(epoch, cfg)
        got = _tight.prepare(epoch.sat_pos_ecef_m, frame.r0_ecef_m, frame.c_ecef_ned, epoch.pseudorange_m,
                             epoch.sat_clock_s, atmosphere_m, epoch.pseudorange_rate_m_s,
                             epoch.sat_clock_drift_s_s, epoch.cn0_dbhz, ids[4], epoch.sat_vel_ecef_m_s,
                             _prepare_params(cfg))
        if got is not None:
            z, r_model, r_los, theta, el_deg, az, rate, r_rate, vel_all = got
            vel = epoch.sat_vel_ecef_m_s
            if not vel_all:
                vel = np.where(np.isfinite(rate)[:, None], vel, np.nan)
            return SatEpoch(epoch, ids[0], ids[1], ids[2], z, r_model, ids[5], r_los, theta, el_deg, az,
                            epoch.sat_pos_ecef_m, vel, rate, r_rate, ids[3], ids[6])
    return _prepare_numpy(epoch, frame, cfg, klobuchar, atmosphere_m)


# an epoch's satellites' keys, clock slots (int, float), systems, GLONASS σ² factors and uniform σ²s, per
# satellite list and configuration (read-only arrays shared by the epochs of the same satellites)
_IDS: dict[tuple[bytes, bytes, str, str, float, float], tuple[Any, ...]] = {}
_IDS_MAX = 512


def _epoch_ids(ep: GnssEpoch, cfg: TightConfig) -> tuple[Any, ...]:
    k = (ep.system.tobytes(), ep.prn.tobytes(), ep.system.dtype.str, ep.prn.dtype.str,
         cfg.glonass_sigma_factor, cfg.sigma_uniform_m)
    ids = _IDS.get(k)
    if ids is None:
        sysi = ep.system.astype(int)
        slots = model.SLOT_OF[sysi]
        arrays = (sysi * 1000 + ep.prn.astype(int), slots, slots.astype(float),
                  np.where(ep.system == _GLONASS, cfg.glonass_sigma_factor**2, 1.0),
                  np.full(ep.n, cfg.sigma_uniform_m**2))
        order = np.argsort(arrays[0], kind="stable")
        key_sorted = arrays[0][order]
        for a in (*arrays, key_sorted, order):
            a.flags.writeable = False
        ids = (*arrays[0:3], tuple(sorted(set(slots.tolist()))), *arrays[3:5], (key_sorted, order))
        if len(_IDS) >= _IDS_MAX:
            _IDS.clear()
        _IDS[k] = ids
    return ids


def _prepare_params(cfg: TightConfig) -> tuple[float, ...]:
    a2 = cfg.sigma_floor_m**2
    return (math.sin(math.radians(cfg.elevation_mask_deg)), cfg.cn0_ref_dbhz, a2, cfg.sigma_zenith_m**2,
            cfg.sigma_los_cn0_m**2, cfg.sigma_range_rate_m_s**2 / (a2 + cfg.sigma_zenith_m**2),
            cfg.prior_cn0_mid_dbhz, cfg.prior_cn0_per_db, cfg.prior_el_per_deg, cfg.prior_el_mid_deg)


def _prepare_numpy(epoch: GnssEpoch, frame: Frame, cfg: TightConfig, klobuchar: Any = None,
                   atmosphere_m: np.ndarray | None = None) -> SatEpoch | None:
    """``prepare_epoch`` in numpy: any epoch (the reference of the C path in the tests)."""
    d = epoch.sat_pos_ecef_m - frame.r0_ecef_m
    rng = np.sqrt(np.einsum("ij,ij->i", d, d))
    sin_el = -(d @ frame.c_ecef_ned[:, 2]) / rng
    ok = np.isfinite(epoch.pseudorange_m) & np.isfinite(sin_el) & (sin_el >= math.sin(math.radians(
        cfg.elevation_mask_deg)))
    if not epoch.corrected:
        ok &= np.isfinite(epoch.sat_clock_s)
    ep = epoch
    if not ok.all():
        if not ok.any():
            return None
        ep, d, rng, sin_el = epoch.select(ok), d[ok], rng[ok], sin_el[ok]
        atmosphere_m = None if atmosphere_m is None else atmosphere_m[ok]
    el = np.arcsin(np.minimum(np.maximum(sin_el, -1.0), 1.0))  # np.clip's values, without its wrapper
    z = ep.pseudorange_m
    rate = ep.pseudorange_rate_m_s
    if not ep.corrected and atmosphere_m is not None:
        z = z + C_M_S * ep.sat_clock_s - atmosphere_m
    ne = d @ frame.c_ecef_ned[:, 0:2]
    az = np.arctan2(ne[:, 1], ne[:, 0]) % (2 * np.pi)
    if not ep.corrected and atmosphere_m is None:
        from companion.gnss.atmosphere import klobuchar_m, saastamoinen_m
        from companion.gnss.timescale import week_tow

        z = z + C_M_S * ep.sat_clock_s - saastamoinen_m(frame.lat_rad, frame.h_m, el)
        if klobuchar is not None:
            z = z - klobuchar_m(klobuchar[0], klobuchar[1], frame.lat_rad, frame.lon_rad, az, el,
                                week_tow(ep.t_gps_s)[1]) * _IONO_SCALE[model.SLOT_OF[ep.system]]
    if not ep.corrected:
        drift = ep.sat_clock_drift_s_s
        rate = rate + C_M_S * np.where(np.isfinite(drift), drift, 0.0)
    cn0 = ep.cn0_dbhz
    weak = 10.0 ** ((cfg.cn0_ref_dbhz - np.where(np.isfinite(cn0), cn0, cfg.cn0_ref_dbhz)) / 10.0)
    glo = np.where(ep.system == _GLONASS, cfg.glonass_sigma_factor**2, 1.0)
    a2 = cfg.sigma_floor_m**2
    r_model = (a2 + cfg.sigma_zenith_m**2 * weak / np.maximum(sin_el, 0.05) ** 2) * glo
    r_los = (a2 + cfg.sigma_los_cn0_m**2 * weak) * glo
    r_rate = r_model * (cfg.sigma_range_rate_m_s**2 / (a2 + cfg.sigma_zenith_m**2))
    vel = ep.sat_vel_ecef_m_s
    vel_ok = np.isfinite(rate) & np.isfinite(vel).all(axis=1)
    if not vel_ok.all():
        vel, rate = np.where(vel_ok[:, None], vel, np.nan), np.where(vel_ok, rate, np.nan)
    el_deg = np.degrees(el)
    sysi = ep.system.astype(int)
    slots = model.SLOT_OF[sysi]
    return SatEpoch(ep, sysi * 1000 + ep.prn.astype(int), slots, slots.astype(float),
                    z, r_model, np.full(ep.n, cfg.sigma_uniform_m**2), r_los,
                    theta_prior(cn0, el_deg, cfg), el_deg, az, ep.sat_pos_ecef_m,
                    vel, rate, r_rate,
                    tuple(sorted(set(slots.tolist()))))


class TightEngine(Timeline[Entry, SatEpoch | Speed | Baro, tuple[int, np.ndarray, Entry]]):
    """The filter on NED accelerations (with attitudes: ``push_acc``, ``push_frd``, ``push_acc_batch``,
    ``Timeline``'s) and prepared epochs, in arrival order."""

    def __init__(self, cfg: TightConfig, method: str = weighting.DEFAULT_WEIGHTING,
                 counts: dict[str, int] | None = None, frame: Frame | None = None,
                 klobuchar: Any = None, line_of_sight: LineOfSight | None = None) -> None:
        cfg.validate()
        self.line_of_sight = line_of_sight  # a map: (p_ned_m (K, 3), az (n,), el (n,)) -> hidden (K, n)
        self.cfg = cfg
        self.method = method
        self.weighting = weighting.make(method, cfg)
        self._snapshot = self.weighting.uses_prior and cfg.belief_innovation == "snapshot"
        self.frame = frame
        self.klobuchar = klobuchar
        preload_chi2()
        self._reset_us = int(round(cfg.reset_timeout_s * 1e6))
        c = cfg
        self._q = (c.sigma_acc_m_s2**2, c.sigma_acc_vertical_m_s2**2, c.sigma_acc_bias_rw_m_s2_sqrt_s**2,
                   c.sigma_acc_ned_rw_m_s2_sqrt_s**2, c.q_clock_m2_s, c.q_isb_m2_s, c.q_drift_m2_s3,
                   c.sigma_heading_rw_rad_sqrt_s**2, c.sigma_yaw_rate_bias_rw_rad_s_sqrt_s**2)
        self._counts = counts if counts is not None else {}
        for k in ("gnss_epochs", "gnss_rejected_too_old", "gnss_rejected_future", "gnss_rejected_before_imu",
                  "gnss_rejected_no_solution", "gnss_rejected_duplicate", "gnss_out_of_order", "gnss_refused",
                  "speed_fused"):
            self._counts.setdefault(k, 0)
        self._q_baro = c.sigma_baro_drift_m_sqrt_s**2
        self._baro_period_us = int(round(c.baro_period_s * 1e6))
        self._baro_last_us: int | None = None  # the last barometer sample pushed
        super().__init__(cfg.imu_hold_max_s, cfg.history_s, cfg.future_tolerance_s, cfg.gravity_m_s2,
                         self._counts, cfg.imu_hold_periods)
        self._nav15: tuple[Entry, tuple[float, ...], np.ndarray] | None = None
        # held IMU time (lost samples, history.py "Held time"), as the loose filter: the held sample's white
        # density (horizontal, vertical), the acceleration's change and a gap's coast (1: on), on p and v
        self._q_hold = (self._q[0], self._q[1], c.imu_hold_acc_rw_m_s2_sqrt_s**2, 1.0)
        self._prop = BlockPropagator(self._q[0], self._q[2], self._q[3], self._q_hold[0], self._q_hold[2],
                                     self._q_hold[3])
        nominal_fields = {"uniform": "r_uniform_m2", "model": "r_model_m2", "los": "r_los_m2"}
        self._r_field = nominal_fields[self.weighting.nominal]
        self._n_fused = 0  # epochs with at least one satellite used (in order of arrival)

    # ------------------------------------------------------------------ IMU
    @property
    def counts(self) -> dict[str, int]:
        c = self._counts
        for k, v in zip(_IMU_COUNTS, self.imu.counts, strict=True):
            c[k] = v
        if self.entries:
            used, rejected, resets, clock_resets, _ = self.entries[-1].totals
            c.update(sat_used=used, sat_rejected=rejected, gnss_resets=resets, clock_resets=clock_resets,
                     gnss_fused=self._n_fused)
        return c

    # ------------------------------------------------------------ measurements
    def push_epoch(self, t_us: int, epoch: SatEpoch) -> None:
        """A prepared epoch valid at ``t_us`` (boot time); fused now, later, or rejected (counted)."""
        self._counts["gnss_epochs"] += 1
        self._push(t_us, epoch)

    def push_speed(self, t_us: int, speed_m_s: float, yaw_integral_rad: float = math.nan) -> None:
        """A ground vehicle's forward speed (odometry) as a measurement of |v_NE|; with the integral of
        its yaw rate (rad since any fixed start), of its horizontal velocity (heading ψ₀ + integral)."""
        if math.isnan(speed_m_s) and math.isfinite(yaw_integral_rad):  # a gyro alone: no wheel speed
            self._push(t_us, Speed(math.nan, math.nan, yaw_integral_rad))
            return
        if not (math.isfinite(speed_m_s) and speed_m_s >= 0.0):
            self._counts["speed_rejected_nonfinite"] = self._counts.get("speed_rejected_nonfinite", 0) + 1
            return
        sd = self.cfg.sigma_speed_m_s + self.cfg.speed_sigma_fraction * speed_m_s
        self._push(t_us, Speed(speed_m_s, sd * sd, yaw_integral_rad))

    def push_baro(self, t_us: int, height_m: float) -> None:
        """A barometer's height (m, its pressure altitude: any datum) valid at ``t_us``; one per
        ``baro_period_s`` is kept (the first of each), the rest are dropped (not counted: the barometer
        runs at the IMU's rate). Before the first epoch it is dropped (``baro_before_start``); a value not
        finite or beyond ``MAX_PRESSURE_ALT_M`` (a damaged log's, the codec's NaN) is counted
        (``baro_rejected_invalid``), not used."""
        c = self._counts
        if not abs(height_m) <= MAX_PRESSURE_ALT_M:  # (NaN fails it too)
            c["baro_rejected_invalid"] = c.get("baro_rejected_invalid", 0) + 1
            return
        last = self._baro_last_us
        if last is not None and 0 <= t_us - last < self._baro_period_us:
            return
        self._baro_last_us = t_us
        if not self.entries:
            c["baro_before_start"] = c.get("baro_before_start", 0) + 1
            return
        c["baro_samples"] = c.get("baro_samples", 0) + 1
        self._push(t_us, Baro(height_m, self.cfg.sigma_baro_m**2))

    def ensure_frame(self, epoch: GnssEpoch) -> bool:
        """Set the local frame at this epoch's single-point solution if there is none yet."""
        if self.frame is None:
            sol = solve_position(epoch, SPP_INIT, klobuchar=self.klobuchar)
            if not sol.ok:
                return False
            self.frame = Frame.at_ecef(sol.p_ecef_m)
        return True

    def _measurement(self, e: Entry) -> SatEpoch | Speed | Baro | None:
        return e.meas

    # --------------------------------------------------------------- start / reset
    def _spp(self, meas: SatEpoch) -> SppSolution | None:
        sol = solve_position(meas.epoch, SPP_INIT, klobuchar=self.klobuchar)
        return sol if sol.ok else None

    def _start(self, t_us: int, meas: SatEpoch | Speed | Baro) -> Entry | None:
        """The first entry, at an epoch's single-point solution (None for odometry, a barometer or no
        solution)."""
        if not isinstance(meas, SatEpoch):
            return None
        sol = self._spp(meas)
        if sol is None:
            self._counts["gnss_rejected_no_solution"] += 1
            return None
        if self.frame is None:
            self.frame = Frame.at_ecef(sol.p_ecef_m)
        c = self.cfg
        x = np.zeros(N_STATE)
        P = np.zeros((N_STATE, N_STATE))
        P[3:6, 3:6] = np.diag([c.sigma_velocity0_m_s**2] * 2 + [c.sigma_velocity0_vertical_m_s**2])
        P[6:9, 6:9] = np.eye(3) * c.sigma_acc_bias0_m_s2**2
        P[9:12, 9:12] = np.eye(3) * c.sigma_acc_ned0_m_s2**2
        P[I_DRIFT, I_DRIFT] = c.sigma_drift0_m_s**2
        if np.isfinite(sol.v_ecef_m_s).all():
            x[3:6] = self.frame.c_ecef_ned.T @ sol.v_ecef_m_s
            x[I_DRIFT] = sol.clock_drift_m_s
        x, P, live = self._from_solution(x, P, sol, (False,) * N_CLK)
        return Entry(t_us, None, x, P, self.imu.integrals(t_us), live, self.weighting.initial_state(),
                     t_us, EpochInfo(), (0, 0, 0, 0, 1), Fit())

    def _from_solution(self, x: np.ndarray, P: np.ndarray, sol: SppSolution, live: tuple[bool, ...]
                       ) -> tuple[np.ndarray, np.ndarray, tuple[bool, ...]]:
        """Position and clocks set to a single-point solution (their covariance reset), the rest kept."""
        assert self.frame is not None
        C = self.frame.c_ecef_ned
        x = x.copy()
        x[0:3] = self.frame.ned(sol.p_ecef_m)
        reset = np.r_[0:3, I_CLK:I_DRIFT]
        P = P.copy()
        P[reset, :] = 0.0
        P[:, reset] = 0.0
        P[0:3, 0:3] = C.T @ sol.cov_ecef_m2 @ C + np.eye(3) * SIGMA_SPP_EXTRA_M**2
        live_l = [False] * N_CLK
        for s, b in zip(sol.clock_systems, sol.clock_bias_m, strict=True):
            j = int(model.SLOT_OF[int(s)])
            x[I_CLK + j] = b
            live_l[j] = True
        for j in np.flatnonzero(live_l).tolist():
            P[I_CLK + j, I_CLK + j] = self.cfg.sigma_clock0_m**2
        x[I_CLK:I_DRIFT] = np.where(live_l, x[I_CLK:I_DRIFT], 0.0)
        return x, P, tuple(live_l)

    # ---------------------------------------------------------------------- fusion
    def _predict(self, e: Entry, t_us: int, ints: Integrals) -> tuple[np.ndarray, np.ndarray]:
        """Entry ``e`` predicted to ``t_us``: (x, P)."""
        T = (t_us - e.t_us) * 1e-6
        x15 = (*e.x[0:6].tolist(), 0.0, 0.0, 0.0, *e.x[6:12].tolist())
        m15, nA, nB = mean_between(x15, e.ints, ints, 1.0)
        x = _tight.predict_mean(e.x, m15, T, e.live)  # (p, v, a, d) from m15, the live clocks + T drift
        if T <= 0.0:
            return x, e.P.copy()
        # F P Fᵀ + Q (model.transition, model.process_noise) and the held-time noise of the block
        # (e.ints → ints) in C; no odometry heading yet: its states stay at rest
        # (the baro offset's random walk, when the state has it)
        return x, _tight.predict_cov(e.P, T, nA, nB, e.live, *self._q, bool(e.P[I_HEADING, I_HEADING] > 0.0),
                                     e.ints, ints, *self._q_hold, self._q_baro)

    def _fuse(self, prev: Entry, t_us: int, meas: SatEpoch | Speed | Baro) -> Entry:
        ints = self.imu.integrals(t_us)
        x, P = self._predict(prev, t_us, ints)
        if isinstance(meas, SatEpoch):
            return self._fuse_epoch(prev, t_us, meas, x, P, ints)
        if isinstance(meas, Speed):
            return self._fuse_speed(prev, t_us, meas, x, P, ints)
        return self._fuse_baro(prev, t_us, meas, x, P, ints)

    def _fuse_baro(self, prev: Entry, t_us: int, m: Baro, x: np.ndarray, P: np.ndarray, ints: Integrals
                   ) -> Entry:
        """The barometer's height: the first adds b_baro = h + p_D (the state's height −p_D: a relative
        height, var(b) = P_DD + R, cov(b, ·) = P_D·), or the known datum ``baro_datum_m`` (σ
        ``baro_datum_sigma_m``, then fused as the later ones but without the gate); the later ones a gated
        scalar update."""
        c = self._counts
        gated = True
        if len(x) == N_STATE:
            c["baro_started"] = c.get("baro_started", 0) + 1
            Pn = np.zeros((N_STATE + 1, N_STATE + 1))
            Pn[:N_STATE, :N_STATE] = P
            datum = self.cfg.baro_datum_m
            if datum != datum:  # unknown: relative to the filter's height, this sample spent on it
                x = np.append(x, m.height_m + x[2])
                Pn[I_BARO, :N_STATE] = Pn[:N_STATE, I_BARO] = P[2]
                Pn[I_BARO, I_BARO] = P[2, 2] + m.r_m2
                return prev._replace(t_us=t_us, meas=m, x=x, P=Pn, ints=ints)
            # known: absolute, and this sample fused below without the gate (it sets the height: the
            # filter's start, a single-point solution, can be tens of metres off in a canyon)
            x = np.append(x, datum)
            Pn[I_BARO, I_BARO] = self.cfg.baro_datum_sigma_m**2
            P, gated = Pn, False
        pred, h = model.baro_height(x)
        y = m.height_m - pred
        ph = P @ h
        s = float(h @ ph) + m.r_m2
        if not gated or y * y <= self.cfg.baro_gate_sigma**2 * s:
            k = ph / s
            x = x + k * y
            P = P - np.outer(k, ph)
            P = 0.5 * (P + P.T)
            c["baro_fused"] = c.get("baro_fused", 0) + 1
            return prev._replace(t_us=t_us, meas=m, x=x, P=P, ints=ints, baro_gated_since_us=-1)
        c["baro_rejected_gate"] = c.get("baro_rejected_gate", 0) + 1
        since = prev.baro_gated_since_us if prev.baro_gated_since_us >= 0 else t_us
        if t_us - since < self.cfg.baro_restart_s * 1e6:
            return prev._replace(t_us=t_us, meas=m, x=x, P=P, ints=ints, baro_gated_since_us=since)
        # gated for baro_restart_s: the datum stepped (ArduPilot's pressure altitude is 0 until its barometer
        # is calibrated, then jumps to its altitude), not the height: b_baro re-starts relative, this sample
        # spent on it (as the first one), the height kept
        c["baro_datum_restarts"] = c.get("baro_datum_restarts", 0) + 1
        x = x.copy()
        x[I_BARO] = m.height_m + x[2]
        P = P.copy()
        P[I_BARO, :] = P[:, I_BARO] = P[2]
        P[I_BARO, I_BARO] = P[2, 2] + m.r_m2
        return prev._replace(t_us=t_us, meas=m, x=x, P=P, ints=ints, baro_gated_since_us=-1)

    def _fuse_speed(self, prev: Entry, t_us: int, m: Speed, x: np.ndarray, P: np.ndarray,
                    ints: Integrals) -> Entry:
        c = self.cfg
        heading_live = P[I_HEADING, I_HEADING] > 0.0
        start = self.entries[0].t_us if self.entries else t_us
        speed = math.hypot(x[3], x[4])
        sigma_v = math.sqrt(max(P[3, 3] + P[4, 4], 0.0))
        wheel = math.isfinite(m.speed_m_s)  # False: a gyro's yaw rate alone (the filter's own speed)
        moving = m.speed_m_s if wheel else speed
        if (not heading_live and math.isfinite(m.yaw_integral_rad) and moving > 2.0
                and t_us - start >= c.odometry_heading_start_s * 1e6
                and speed > 0.7 * moving and sigma_v < 0.3 * speed):
            # heading offset from the filter's velocity direction (the car moves along its heading),
            # once that direction is known: the filter moves at the odometry's speed, to 30 %
            x[I_HEADING] = math.atan2(x[4], x[3]) - m.yaw_integral_rad
            x[I_YAW_BIAS] = 0.0
            P[I_HEADING:I_YAW_BIAS + 1, :] = 0.0
            P[:, I_HEADING:I_YAW_BIAS + 1] = 0.0
            P[I_HEADING, I_HEADING] = max(c.odometry_heading0_rad, sigma_v / speed) ** 2
            P[I_YAW_BIAS, I_YAW_BIAS] = c.sigma_yaw_rate_bias0_rad_s**2
            heading_live = True
        if heading_live and math.isfinite(m.yaw_integral_rad) and not wheel:
            # no side slip: the velocity across the heading is zero (its speed along it is the filter's)
            y, H = model.lateral_velocity(x, m.yaw_integral_rad)
            R = np.array([[c.sigma_lateral_m_s**2]])
        elif heading_live and math.isfinite(m.yaw_integral_rad):
            y, H = model.odometry_velocity(x, m.speed_m_s, m.yaw_integral_rad)
            psi = float(x[I_HEADING]) + m.yaw_integral_rad
            u = np.array([[math.cos(psi), math.sin(psi)], [-math.sin(psi), math.cos(psi)]])  # along, across
            R = u.T @ np.diag([m.r_m2_s2, c.sigma_lateral_m_s**2]) @ u
        else:
            s, h = model.speed(x)
            if s <= 0.5 or not wheel:  # below 0.5 m/s the direction is unknown; a gyro alone: no speed
                return Entry(t_us, m, x, P, ints, prev.live, prev.state, prev.t_good_us, prev.info,
                             prev.totals, prev.fit, prev.scatter_h, prev.scatter_v, prev.fix_var_m2,
                             prev.delay_m2, prev.kept, prev.baro_gated_since_us)
            y, H, R = np.array([m.speed_m_s - s]), h[None, :], np.array([[m.r_m2_s2]])
        PHt = P @ H.T
        S = H @ PHt + R
        w = np.linalg.solve(S, y)
        if float(y @ w) <= c.gate_sigma**2 * len(y):
            x = x + PHt @ w
            P = P - PHt @ np.linalg.solve(S, PHt.T)
            P = 0.5 * (P + P.T)
            self._counts["speed_fused"] += 1
        return Entry(t_us, m, x, P, ints, prev.live, prev.state, prev.t_good_us, prev.info,
                     prev.totals, prev.fit, prev.scatter_h, prev.scatter_v, prev.fix_var_m2,
                     prev.delay_m2, prev.kept, prev.baro_gated_since_us)

    def _fuse_epoch(self, prev: Entry, t_us: int, m: SatEpoch, x: np.ndarray, P: np.ndarray,
                    ints: Integrals) -> Entry:
        assert self.frame is not None
        c = self.cfg
        used_tot, rej_tot, resets, clock_resets, epochs = prev.totals
        frame = self.frame
        # y = z − h(x⁻), H, H P⁻ and (H P⁻ Hᵀ)_ii: model.pseudorange in C
        r0, C = frame.r0_ecef_m, frame.c_ecef_ned
        y, H, HP, s0, min_abs_y = _tight.innovations(x, P, r0, C, m.sat_pos_ecef_m, m.slot_f, m.z_m)
        live = list(prev.live)
        restarted = False
        for j in m.systems:
            if live[j] and min_abs_y[j] <= c.clock_jump_m:
                continue  # the usual case: a known clock, no jump
            med = float(np.median(y[m.slot == j]))
            clock_resets += int(live[j])
            x[I_CLK + j] += med
            P[I_CLK + j, :] = 0.0
            P[:, I_CLK + j] = 0.0
            P[I_CLK + j, I_CLK + j] = c.sigma_clock0_m**2
            live[j] = restarted = True
        if restarted:
            y, H, HP, s0, _ = _tight.innovations(x, P, r0, C, m.sat_pos_ecef_m, m.slot_f, m.z_m)
        fix = None
        if c.shadow_matching and self.line_of_sight is not None:  # the map's shadows as a position fix
            fix = self._shadow_fix(m, x, P)
            if fix is not None and c.shadow_stage == "before":
                x, P = _fuse_shadow(fix, x, P)
                y, H, HP, s0, _ = _tight.innovations(x, P, r0, C, m.sat_pos_ecef_m, m.slot_f, m.z_m)
                fix = None
        r_nom = getattr(m, self._r_field)
        prior = m.theta_prior
        if self.weighting.uses_prior:
            if self.line_of_sight is not None:  # the map at the predicted position, over its uncertainty
                p_los = 1.0 / (1.0 + np.exp(-prior)) if c.map_shadow_matching else None
                p_hidden = blocked_probability(self.line_of_sight, x[0:3], P[0:3, 0:3], m.azimuth_rad,
                                               np.radians(m.elevation_deg), p_los, c.map_position_sigma_m)
                prior = prior + map_theta(p_hidden, c)
            prior = np.minimum(np.maximum(prior, c.theta_min), c.theta_max)  # np.clip's values
        terms = weighting.SatTerms(m.key, y, s0, r_nom, prior, m.r_model_m2)
        if self._snapshot:  # the epoch's own solution as the belief's reference (companion.tight.snapshot)
            cols = [0, 1, 2, *(I_CLK + j for j in m.systems)]
            terms = terms._replace(geometry=H[:, cols], p_pos_m2=P[np.ix_(cols, cols)])

        def solve(r: np.ndarray, used: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            u = np.flatnonzero(used)
            S = HP[u] @ H[u].T + np.diag(r[u])
            dx = HP[u].T @ np.linalg.solve(S, y[u])
            return y - H @ dx, S

        r, used, state, beta = self.weighting.weigh(prev.state, terms, solve)
        n_used = int(used.sum())
        nis = math.nan
        fit = prev.fit
        scatter_h, scatter_v, fix_var, delay = prev.scatter_h, prev.scatter_v, prev.fix_var_m2, prev.delay_m2
        kept = prev.kept
        u = None if n_used == len(used) else np.flatnonzero(used)  # None: every satellite
        snap = None
        r_rate, used_f = m.r_rate_m2_s2 * (r / r_nom), used.astype(float)
        if n_used and c.accuracy_window_s > 0.0:  # this epoch's own position, weighted as fused, its
            # variances, its own Doppler velocity and its delay bias (snapshot.epoch_fix, .epoch_velocity,
            # .delay_bias: in C)
            snap = _tight.snapshot(H, y, r, used_f, x[0:3], m.sat_pos_ecef_m, m.sat_vel_ecef_m_s,
                                   m.z_rate_m_s, r_rate, r0, C)
        if n_used:
            if u is None and m.key_sorted is not None:  # every satellite, in the order of their keys (Fit.add
                # then finds its own keys at once; each channel's sums the same)
                keys, order = m.key_sorted
                fit = fit.add(t_us, keys, (y / np.sqrt(s0 + r))[order], c.accuracy_window_s)
            elif u is None:  # every satellite (the same values as indexed by all of them)
                fit = fit.add(t_us, m.key, y / np.sqrt(s0 + r), c.accuracy_window_s)
            else:
                fit = fit.add(t_us, m.key[u], y[u] / np.sqrt(s0[u] + r[u]), c.accuracy_window_s)
            p_h, p_v = P[0, 0] + P[1, 1], P[2, 2]
            # the used pseudoranges and their range rates (inflated like their pseudoranges, gated on
            # their own) in one update, in C (model.range_rate; the numpy form in the tests)
            x, P, nis, _ = _tight.update(x, P, H, HP, y, r, used_f, r0, C, m.sat_pos_ecef_m,
                                         m.sat_vel_ecef_m_s, m.z_rate_m_s, r_rate, c.gate_sigma**2)
            if snap is not None:  # the motion between snapshots: the epoch's own Doppler velocity, else the
                # filter's (after this update)
                sn, se, sd, vn, ve, vd, un, ue, ud, bn, be, bd = snap.tolist()
                if un != un:
                    un, ue, ud = float(x[3]), float(x[4]), float(x[5])
                w = c.accuracy_window_s
                scatter_h = scatter_h.add(t_us, (sn, se), (un, ue), w)
                scatter_v = scatter_v.add(t_us, sd, ud, w)
                fix_var = (0.5 * (vn + ve), vd)
                delay = (bn * bn, be * be, bd * bd)
                kept = (float(P[0, 0] + P[1, 1]) / p_h, float(P[2, 2]) / p_v)
        if fix is not None:  # "after": gated against the prediction, fused after the pseudoranges
            x, P = _fuse_shadow(fix, x, P)
        t_good = t_us if n_used else prev.t_good_us
        self._n_fused += bool(n_used)
        if not n_used and t_us - prev.t_good_us >= self._reset_us:
            sol = self._spp(m)
            if sol is not None:
                x, P, live_t = self._from_solution(x, P, sol, tuple(live))
                live = list(live_t)
                resets += 1
                t_good = t_us
        q_pos = prev.info.q_pos_ned  # an epoch with none used keeps the last geometry's
        if n_used and c.accuracy_floor_m > 0.0:
            u = np.flatnonzero(used)
            q_new = position_dop_ned(m.elevation_deg[u], m.azimuth_rad[u], m.slot[u])
            q_pos = q_new if np.isfinite(q_new).all() else q_pos
        info = EpochInfo(m.epoch.n, n_used, nis, float(beta.sum()) / len(beta) if len(beta) else math.nan,
                         m.key, beta, y, used, q_pos)
        return Entry(t_us, m, x, P, ints, tuple(live), state, t_good, info,
                     (used_tot + n_used, rej_tot + len(y) - n_used, resets, clock_resets, epochs + 1), fit,
                     scatter_h, scatter_v, fix_var, delay, kept, prev.baro_gated_since_us)

    def _shadow_fix(self, m: SatEpoch, x: np.ndarray, P: np.ndarray) -> shadow.ShadowFix | None:
        """The epoch's shadow-matching fix at the predicted (x, P) if it passes the gate (counted
        ``shadow_fused`` / ``shadow_rejected_gate`` / ``shadow_none``), else None."""
        assert self.line_of_sight is not None
        c = self._counts
        fix = shadow.shadow_fix(self.line_of_sight, x[0:3], P[0:3, 0:3], m.azimuth_rad,
                                np.radians(m.elevation_deg), m.theta_prior, self.cfg)
        if fix is None:
            c["shadow_none"] = c.get("shadow_none", 0) + 1
            return None
        if not shadow.passes_gate(fix, x[0:2], P[0:2, 0:2], self.cfg.shadow_gate_sigma):
            c["shadow_rejected_gate"] = c.get("shadow_rejected_gate", 0) + 1
            return None
        c["shadow_fused"] = c.get("shadow_fused", 0) + 1
        return fix

    # --------------------------------------------------------------------- history
    def _anchor(self, e: Entry, t_us: int, ints: Integrals) -> Entry:
        x, P = self._predict(e, t_us, ints)
        return e._replace(t_us=t_us, meas=None, x=x, P=P, ints=ints)

    # ---------------------------------------------------------------------- output
    def state_now(self) -> tuple[int, np.ndarray, np.ndarray, Entry] | None:
        """(t_us, x, P, the last entry) at the newest IMU time; None before the first epoch."""
        if not self.entries:
            return None
        last = self.entries[-1]
        now = self.imu.last_t_us
        x, P = self._predict(last, now, self.imu.last_integrals())
        return now, x, P, last

    # (t_us, [p, v, 0 (3), the variances of p, v, 0 (3)] (18,), the last entry) at the newest IMU time, by the
    # loose filter's C output path (``BlockPropagator.output_from``: the mean from the IMU history's newest
    # integrals and the variances of p and v, which depend on (p, v, a, d) alone), the vertical
    # white-acceleration density added where it differs; cached (``Timeline._output_now`` itself: one
    # Python call fewer per estimate, as the loose engine's ``snapshot``)
    output_now = Timeline._output_now

    def _output(self, last: Entry, now: int) -> tuple[int, np.ndarray, Entry]:
        if self._nav15 is None or self._nav15[0] is not last:
            P15 = np.zeros((15, 15))
            P15[_IX_NAV] = last.P[:12, :12]
            # the mean as floats (the same values as the array's elements; the C core reads floats faster)
            self._nav15 = (last, (*last.x[0:6].tolist(), 0.0, 0.0, 0.0, *last.x[6:12].tolist()), P15)
        T = (now - last.t_us) * 1e-6
        _, out = self._prop.output_from(self._nav15[1], self._nav15[2], last.ints, self.imu, T, 1.0, 0.0)
        # out: p, v, b (9) then their variances (9); b and its variances are zero here (its mean and
        # variance enter as 0, with no process noise: no fix-level bias in this filter)
        dq = self._q[1] - self._q[0]
        if dq:
            out[11] += dq * T * T * T / 3.0
            out[14] += dq * T
            # the held sample's white noise vertically: the same difference of densities over held time
            held = _tight.held_noise(last.ints, self.imu.last_integrals(), (0.0, 0.0, dq), 0.0, 0.0)
            if held is not None:
                out[11] += held[6]
                out[14] += held[8]
        return now, out, last

    def clock_bias_m(self, x: np.ndarray, system: System) -> float:
        return float(x[I_CLK + int(model.SLOT_OF[int(system)])])


def _fuse_shadow(fix: shadow.ShadowFix, x: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(x, P) after the shadow-matching rows z = H p_NE (variances R, independent)."""
    y, S = shadow.innovation(fix, x[0:2], P[0:2, 0:2])
    PHt = P[:, 0:2] @ fix.H.T
    K = np.linalg.solve(S, PHt.T).T
    x = x + K @ y
    P = P - K @ PHt.T
    return x, 0.5 * (P + P.T)
