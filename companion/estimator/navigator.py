"""``Navigator``: the estimator's front end on a source-agnostic stream of wire samples.

It pairs each IMU sample with the latest attitude, rotates the specific force from body FRD to
NED and adds gravity (NED z is down: ``a_ned = R_ned_frd f_frd + [0, 0, g]``), hands the engine
that acceleration with R (its accelerometer bias is in body axes), converts fixes
from geodetic to local NED (``LocalNedFrame``; with ``frame=None`` the first good fix is home),
gates bad input with counted rejections and feeds ``FusionEngine``. No I/O.

The per-sample IMU path runs in the C core (``_core.c``); ``push_imu_batch`` is a vectorised path for
recorded or simulated blocks that gives the same result as pushing attitude + IMU one by one.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pymap3d
from pymap3d.ellipsoid import Ellipsoid

from companion.domain.geodesy import LocalNedFrame
from companion.domain.physics import MAX_SPECIFIC_FORCE_M_S2
from companion.domain.rotation import rotation_scaled
from companion.domain.samples import AttitudeSample, GnssFix, ImuSample, NavEstimate
from companion.errors import ConfigError
from companion.estimator._core import Front
from companion.estimator._core import fix_floors as _fix_floors
from companion.estimator._core import geodetic_ned as _geodetic_ned
from companion.estimator._core import inflation3 as _inflation3
from companion.estimator._core import reported as _reported
from companion.estimator._core import slots_new as _slots_new
from companion.estimator.config import EstimatorConfig
from companion.estimator.consistency import AXES3, fit_inflation3
from companion.estimator.engine import FusionEngine
from companion.estimator.methods import DEFAULT_METHOD, MethodContext

BATCH_MIN = 64  # below this many samples the per-sample float path is faster than numpy
# the counters the C front keeps (its attributes of these names)
_FRONT_COUNTS = ("attitude_used", "attitude_rejected_nonfinite", "imu_rejected_no_attitude")
# NavEstimate's fields' slot descriptors, in order: estimate() builds one through them (``_core.slots_new``,
# samples.new_nav_estimate's steps in C)
_ESTIMATE_FIELDS = tuple(NavEstimate.__dict__[f.name] for f in dataclasses.fields(NavEstimate))


class NedConverter:
    """``frame.to_ned_m`` with the home point's ECEF position and rotation computed once.

    pymap3d's geodetic → NED is ECEF(fix) − ECEF(home), rotated into the home's tangent plane;
    both the home ECEF and the rotation (from pymap3d, on the unit vectors) are constant, so
    each fix costs pymap3d's ``geodetic2ecef`` formula and a 3×3 product, in the C core
    (``_core.geodetic_ned``): the formula written out with each trigonometric value computed once
    (pymap3d calls cos(lat) three times), the degrees converted as ``math.radians`` does, cos, sin and
    hypot libm's, which numpy's float64 functions that pymap3d calls are here (docs/estimator.md,
    Speed): the same bits (tested against pymap3d and against the numpy form it replaced).
    """

    WGS84 = Ellipsoid.from_name("wgs84")
    _A = WGS84.semimajor_axis
    _A2 = _A**2
    _B = WGS84.semiminor_axis
    _B_A_2 = (WGS84.semiminor_axis / WGS84.semimajor_axis) ** 2

    def __init__(self, frame: LocalNedFrame) -> None:
        self.home_ecef_m = tuple(float(v) for v in pymap3d.geodetic2ecef(
            frame.home_lat_deg, frame.home_lon_deg, frame.home_alt_m))
        rows = []
        for unit in np.eye(3):
            e, n, u = pymap3d.uvw2enu(*unit, frame.home_lat_deg, frame.home_lon_deg)
            rows.append((float(n), float(e), -float(u)))  # column of R_ned_ecef for this ECEF axis
        self.r_ned_ecef = tuple(tuple(rows[j][i] for j in range(3)) for i in range(3))
        self._consts = (float(self._A), float(self._A2), float(self._B), float(self._B_A_2),
                        *self.home_ecef_m, *(v for row in self.r_ned_ecef for v in row))

    def __call__(self, lat_deg: float, lon_deg: float, alt_m: float) -> tuple[float, float, float]:
        return _geodetic_ned(self._consts, lat_deg, lon_deg, alt_m)


class Navigator:
    """Belief-adaptive GNSS/IMU navigation on wire samples pushed in arrival order.

    ``push(sample)`` consumes one ``ImuSample``, ``AttitudeSample`` or ``GnssFix`` (arrival order; another
    type: TypeError). It never raises on bad data: that is counted (``counters``)."""

    def __init__(self, cfg: EstimatorConfig | None = None, method: str = DEFAULT_METHOD,
                 frame: LocalNedFrame | None = None, context: MethodContext | None = None) -> None:
        """``context``: what the method needs beyond ``cfg`` (plugin parameters, the map); from a
        mission, ``companion.wiring.navigator_for`` builds the whole navigator."""
        self.cfg = cfg if cfg is not None else EstimatorConfig()
        try:
            self.cfg.validate()
        except ValueError as exc:
            raise ConfigError(f"estimator: {exc}") from None
        self.method = method
        self.frame = frame
        self._to_ned = NedConverter(frame) if frame is not None else None
        self._counts: dict[str, int] = {
            "attitude_used": 0, "attitude_rejected_nonfinite": 0, "imu_rejected_no_attitude": 0,
            "gnss_rejected_fix_type": 0, "gnss_rejected_frozen": 0,
        }
        # frozen-output check: the last fix's (lat, lon, alt) and the validity time it first had
        self._fix_seen: tuple[tuple[float, float, float], int, bool] | None = None
        self._frozen_us = int(round(self.cfg.gnss_frozen_s * 1e6))
        self.engine = FusionEngine(self.cfg, method, self._counts, context)
        # push(sample): attitude and IMU samples in the C core (the latest attitude as R_ned_frd, row-major:
        # ``_front.rot``; the IMU path as Timeline.push_frd, through Timeline.frd_sink's parts; their counters
        # _FRONT_COUNTS, which counters() reads), any other sample through _push_other
        _, g, waiting, pushed = self.engine.frd_sink()
        self._front = Front(self.engine.imu, g, ImuSample, AttitudeSample, self._push_other, pushed, waiting)
        self.push: Callable[[ImuSample | AttitudeSample | GnssFix], None] = self._front
        self._snapshot = self.engine.snapshot
        self._last: tuple[Any, NavEstimate] | None = None
        # (the Fit it is of, the factor)
        self._inflation: tuple[Any, float] = (None, 1.0)
        # the last fix's (correlation c, one fix's variance σ²) horizontally and vertically when its fixes
        # are correlated, else None (consistency.fix_floor: each variance is max(k P, min(c k P, σ²)))
        self._floor: tuple[float, float, float, float] | None = None
        self._g = self.cfg.gravity_m_s2

    # -------------------------------------------------------------- input
    def _push_other(self, sample: Any) -> None:
        """``push`` of a sample other than attitude and IMU (those the C front takes itself)."""
        if type(sample) is GnssFix:
            self._push_fix(sample)
        else:
            raise TypeError(f"Navigator.push: not a sample: {type(sample).__name__}")

    def push_imu_batch(self, t_us: np.ndarray, acc_frd_m_s2: np.ndarray, q_ned_frd: np.ndarray) -> None:
        """IMU samples (n,), (n, 3) with their attitudes (n, 4, w first), in time order.

        The same as pushing ``AttitudeSample(t, q)`` then ``ImuSample(t, f)`` for each row (a block
        with anything to gate, e.g. a specific force beyond ``MAX_SPECIFIC_FORCE_M_S2``, goes that way).
        """
        q = np.asarray(q_ned_frd, dtype=float)
        f = np.asarray(acc_frd_m_s2, dtype=float)
        w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
        n2 = w * w + x * x + y * y + z * z  # the per-sample expression, so the same bits
        if len(q) < BATCH_MIN or not (np.isfinite(n2).all() and (n2 > 1e-12).all()
                                      and (np.abs(f) <= MAX_SPECIFIC_FORCE_M_S2).all()):
            for t, fk, qk in zip(np.asarray(t_us).tolist(), f, q, strict=True):
                self.push(AttitudeSample(t, qk))
                self.push(ImuSample(t, fk, np.zeros(3)))
            return
        r = np.column_stack(rotation_scaled(w, x, y, z, 2.0 / n2))
        fx, fy, fz = f[:, 0], f[:, 1], f[:, 2]  # R f̃ + g as the per-sample expression: the same bits
        a = np.column_stack((r[:, 0] * fx + r[:, 1] * fy + r[:, 2] * fz,
                             r[:, 3] * fx + r[:, 4] * fy + r[:, 5] * fz,
                             r[:, 6] * fx + r[:, 7] * fy + r[:, 8] * fz + self._g))
        self._front.attitude_used += len(q)
        self._front.rot = r[-1]
        self.engine.push_acc_batch(np.asarray(t_us, dtype=np.int64), a, r)

    def _push_fix(self, fix: GnssFix) -> None:
        if fix.fix_type < 3:
            self._counts["gnss_rejected_fix_type"] += 1
            return
        if not (math.isfinite(fix.lat_deg) and math.isfinite(fix.lon_deg) and math.isfinite(fix.alt_m)
                and abs(fix.lat_deg) <= 90.0 and abs(fix.lon_deg) <= 180.0):
            self._counts["gnss_rejected_nonfinite"] += 1
            return
        if self._frozen(fix):
            self._counts["gnss_rejected_frozen"] += 1
            return
        if self.frame is None:
            if not len(self.engine.imu):  # home is set by a fix the filter can start from
                self._counts["gnss_rejected_before_imu"] += 1
                return
            self.frame = LocalNedFrame(fix.lat_deg, fix.lon_deg, fix.alt_m)
            self._to_ned = NedConverter(self.frame)
        v = fix.v_ned_m_s
        self.engine.push_fix(fix.t_validity_us, self._to_ned(fix.lat_deg, fix.lon_deg, fix.alt_m),  # type: ignore[misc]
                             self.fix_r_nominal_m2(fix.h_acc_m, fix.v_acc_m),
                             v, None if v is None else self.fix_r_velocity_m2(fix.vel_acc_m_s))

    def _frozen(self, fix: GnssFix) -> bool:
        """True when this fix repeats the position first received more than ``gnss_frozen_s``
        before and the vehicle moved faster than ``gnss_frozen_speed_m_s`` at some time since
        (arrival order, like the other receiver-stream checks)."""
        where = (fix.lat_deg, fix.lon_deg, fix.alt_m)
        seen = self._fix_seen
        if seen is None or seen[0] != where:
            self._fix_seen = (where, fix.t_validity_us, self._moving())
            return False
        if not seen[2] and self._moving():  # moved since: stays so until the position changes
            seen = self._fix_seen = (where, seen[1], True)
        return seen[2] and fix.t_validity_us - seen[1] > self._frozen_us

    def _moving(self) -> bool:
        """Horizontal speed at the last fusion above ``gnss_frozen_speed_m_s`` (no prediction)."""
        fusions = self.engine.fusions
        if not fusions:
            return False
        x = fusions[-1].x
        return math.hypot(x[3], x[4]) > self.cfg.gnss_frozen_speed_m_s

    def fix_r_nominal_m2(self, h_acc_m: float, v_acc_m: float) -> tuple[float, float, float]:
        """A fix's nominal R (NED variances, m²): the receiver-reported 1σ accuracy where known (finite,
        > 0), floored at the configured nominal std (as PX4 EKF2: max(hacc, EKF2_GPS_P_NOISE)); where
        not, infinite: the engine learns it from the receiver's own fixes (``engine.LEARN``). HDOP is
        not used: HDOP × a UERE measured both too pessimistic for a good receiver (3.6 m for quad106's
        decimetre fixes) and too optimistic for an urban one (docs/estimator.md)."""
        c = self.cfg
        inf = math.inf
        h = max(h_acc_m, c.sigma_gnss_horizontal_m) if math.isfinite(h_acc_m) and h_acc_m > 0.0 else inf
        v = max(v_acc_m, c.sigma_gnss_vertical_m) if math.isfinite(v_acc_m) and v_acc_m > 0.0 else inf
        return h * h, h * h, v * v

    def fix_r_velocity_m2(self, vel_acc_m_s: float) -> tuple[float, float, float]:
        """The R of a fix's velocity (NED variances, (m/s)²): the receiver's 1σ speed accuracy where
        known, floored at the configured std of each component (EKF2: max(sacc, EKF2_GPS_V_NOISE));
        the configured std where unknown (NaN, 0, negative or infinite)."""
        c = self.cfg
        h, d = c.sigma_gnss_velocity_m_s, c.sigma_gnss_velocity_vertical_m_s
        if math.isfinite(vel_acc_m_s):
            h, d = max(h, vel_acc_m_s), max(d, vel_acc_m_s)
        return h * h, h * h, d * d

    def push_fix_ned(self, t_validity_us: int, p_ned_m: np.ndarray, h_acc_m: float = math.nan,
                     v_acc_m: float = math.nan, v_ned_m_s: Any = None, vel_acc_m_s: float = math.nan) -> None:
        """A fix already converted to this navigator's frame (e.g. vectorised by a log reader),
        with the receiver's velocity ``v_ned_m_s`` (NED, m/s; NaN components not reported; None:
        none) and its speed accuracy.

        Gated like ``push`` after the geodesy (the caller checked ``fix_type``); needs ``frame``.
        """
        if self.frame is None:
            raise ValueError("push_fix_ned needs a navigator with a frame (home)")
        self.engine.push_fix(t_validity_us, p_ned_m, self.fix_r_nominal_m2(h_acc_m, v_acc_m), v_ned_m_s,
                             None if v_ned_m_s is None else self.fix_r_velocity_m2(vel_acc_m_s))

    # ------------------------------------------------------------- output
    def estimate(self) -> NavEstimate | None:
        """The estimate at the newest IMU time; None until the first good fix and IMU."""
        snap = self._snapshot()
        if snap is None:
            return None
        last = self._last
        if last is not None and last[0] is snap:
            return last[1]
        if self._inflation[0] is not self.engine.entries[-1].fit:  # (a snapshot: an entry)
            self.accuracy_inflation()  # P's positions × k (the factor and its floor cached per fix)
        # p, v, b and the variances, the positions' × k, floored where the fixes' errors are correlated over
        # seconds (not averaged down, up to one fix's variance; consistency.floored_axis), in the C core
        p, v, b, var = _reported(snap.out, self._inflation[1], self._floor)
        est = _slots_new(NavEstimate, _ESTIMATE_FIELDS, snap.t_us, p, v, b, var, snap.beta, snap.nis,
                         self.method, snap.test_ratio, snap.glitch, snap.pos_valid, snap.n_rejected,
                         snap.n_resets, snap.vel_ratio, snap.disagree)  # NavEstimate(...), every field, in C
        self._last = (snap, est)
        return est

    def accuracy_inflation(self) -> float:
        """The factor (≥ 1) on the position variances the estimates report: the fused fixes' NIS per
        degree of freedom over the last ``accuracy_window_s`` (1 when that is 0, or before a fix;
        ``companion.estimator.consistency``, the tight filter's rule)."""
        entries = self.engine.entries
        fit = entries[-1].fit if entries else None
        if self._inflation[0] is not fit:  # a function of the last fix's Fit alone (the entries between
            w = self.cfg.accuracy_window_s  # fixes share it): once per fix; consistency.accuracy_inflation
            if fit is None or w <= 0.0:
                k = 1.0
            elif fit.key is AXES3:  # fit_inflation3's float path, in C
                k = _inflation3(fit.nu_sum, fit.w2_sum)
            else:
                k = fit_inflation3(fit)
            self._inflation = (fit, k)
            self._floor = None
            if entries and w > 0.0:  # the fixes' own correlation: a floor (c, s2, c_v, s2_v) where c or c_v
                last, r = entries[-1], entries[-1].r_nominal_m2  # > 1 (consistency.fix_floor of each, in C)
                self._floor = _fix_floors(last.scatter, last.scatter_v, r[0], r[2])
        return self._inflation[1]

    def counters(self) -> dict[str, int]:
        """Samples used and rejected by reason (stable names)."""
        front = self._front
        self._counts.update((name, getattr(front, name)) for name in _FRONT_COUNTS)
        return dict(self.engine.counts)  # the same dict, with the core's IMU counters
