"""``TightNavigator``: the tightly coupled filter on a stream of wire samples (no I/O).

Takes what ``companion.estimator.Navigator`` takes for the IMU (``AttitudeSample``, ``ImuSample``)
and, instead of position fixes, raw receiver epochs (``RawGnss``) and a ground vehicle's odometry
(``Odometry``), and a barometer's height with the IMU samples (``ImuSample.pressure_alt_m``: the engine's
baro offset state, ``companion.tight.engine``); gives the same ``NavEstimate`` (``b_ned_m`` is zero:
there is no fix-level bias, the per-satellite beliefs replace it; ``beta`` is the mean belief of the last
epoch's satellites).

Epochs without satellite states (a receiver's RXM-RAWX) are completed from the broadcast
ephemerides given at construction, through ``SatelliteCache`` (evaluated every
``sat_cache_period_s``, 5 s: < 0.5 mm and < 0.5 mm/s from the full evaluation, ``beliefnav bench tight``).
``line_of_sight`` (optional, a map): ``(p_ned_m (K, 3), azimuth_rad (n,), elevation_rad (n,)) -> hidden
(bool (K, n))`` (``companion.mission.city3d.City.line_of_sight_blocked``; ``companion.wiring.
tight_navigator_for`` passes the mission's) sets the belief rows' prior from the predicted line of sight.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from companion.domain.geodesy import LocalNedFrame
from companion.domain.samples import AttitudeSample, GnssFix, ImuSample, NavEstimate, new_nav_estimate
from companion.errors import ConfigError
from companion.estimator._core import rotation_q
from companion.estimator.consistency import (
    SnapshotFloor,
    accuracy_inflation,
    snapshot_parts,
    variance_scale,
)
from companion.gnss.constants import C_M_S
from companion.gnss.ephemeris import EphemerisStore
from companion.tight import _tight
from companion.tight import engine as tight_engine
from companion.tight.belief import LineOfSight
from companion.tight.cn0cal import Cn0Calibration
from companion.tight.config import TightConfig
from companion.tight.model import Frame
from companion.tight.samples import Odometry, RawGnss
from companion.tight.satcache import AtmosphereCache, SatelliteCache
from companion.tight.weighting import DEFAULT_WEIGHTING


class TightNavigator:
    """Tightly coupled GNSS/IMU (or GNSS/odometry) navigation on samples pushed in arrival order."""

    def __init__(self, cfg: TightConfig | None = None, method: str = DEFAULT_WEIGHTING,
                 frame: LocalNedFrame | None = None, ephemerides: EphemerisStore | None = None,
                 line_of_sight: LineOfSight | None = None, sat_cache_period_s: float = 5.0) -> None:
        self.cfg = cfg if cfg is not None else TightConfig()
        try:
            self.cfg.validate()
        except ValueError as exc:
            raise ConfigError(f"tight estimator: {exc}") from None
        self.method = method
        self._counts: dict[str, int] = {"attitude_used": 0, "attitude_rejected_nonfinite": 0,
                                        "imu_rejected_no_attitude": 0, "gnss_fix_ignored": 0,
                                        "gnss_rejected_no_ephemeris": 0, "gnss_rejected_empty": 0,
                                        "odometry_rejected": 0}
        f = None if frame is None else Frame.at_geodetic(math.radians(frame.home_lat_deg),
                                                         math.radians(frame.home_lon_deg), frame.home_alt_m)
        klob = None if ephemerides is None else ephemerides.klobuchar
        self.engine = tight_engine.TightEngine(self.cfg, method, self._counts, f, klob, line_of_sight)
        # the IMU path without Timeline.push_frd's own call (the same steps: Timeline.frd_sink)
        self._imu_push, self._imu_g, self._imu_waiting, self._imu_pushed = self.engine.frd_sink()
        self._sats = None if ephemerides is None else SatelliteCache(ephemerides, sat_cache_period_s)
        self._atmo: AtmosphereCache | None = None
        self._sat_period_s = sat_cache_period_s
        self._rot: Any = None
        self._odo: tuple[int, float, float] | None = None  # (t_us, yaw rate, its integral)
        self._last: tuple[Any, NavEstimate] | None = None
        # (the engine's last epoch entry, consistency.variance_scale, the common-mode floor's variances,
        # (k, the snapshots' floors N/E and D, the delay bias² N, E, D) or None) of it
        self._reported: tuple[Any, np.ndarray | None, np.ndarray | None,
                              tuple[float, SnapshotFloor | None, SnapshotFloor | None,
                                    tuple[float, float, float]] | None] = (None, None, None, None)
        self._delay2 = self.cfg.accuracy_delay_fraction**2
        self._valid_us = self.cfg.reset_timeout_s * 1e6
        c = self.cfg
        self._cn0 = None if math.isnan(c.cn0_calibration_ref_dbhz) else Cn0Calibration(
            c.cn0_calibration_quantile, c.cn0_calibration_ref_dbhz, c.cn0_calibration_prior_obs)

    def push(self, sample: Any) -> None:
        """Consume one sample (arrival order). Never raises on bad data: it is counted."""
        kind = type(sample)
        if kind is ImuSample:
            if self._rot is None:
                self._counts["imu_rejected_no_attitude"] += 1
                return
            if self._imu_push(sample.t_us, sample.acc_frd_m_s2, self._rot, self._imu_g) or self._imu_waiting:
                self._imu_pushed()
            if sample.pressure_alt_m is not None:  # the barometer's height, after its IMU sample
                self.engine.push_baro(sample.t_us, sample.pressure_alt_m)
        elif kind is AttitudeSample:
            r = rotation_q(sample.q_ned_frd)
            if r is None:
                self._counts["attitude_rejected_nonfinite"] += 1
                return
            self._rot = r
            self._counts["attitude_used"] += 1
        elif kind is RawGnss:
            self._push_raw(sample)
        elif kind is Odometry:
            self._push_odometry(sample)
        elif kind is GnssFix:
            self._counts["gnss_fix_ignored"] += 1
        else:
            raise TypeError(f"TightNavigator.push: not a sample: {kind.__name__}")

    def _count_no_prediction(self, epoch: Any, valid: np.ndarray) -> None:
        """Count the satellites left out because their ephemeris broadcasts "no accuracy prediction"
        (``sat_rejected_no_accuracy_prediction``, present once one is)."""
        assert self._sats is not None
        gone = ~valid & self._sats.store.no_prediction(epoch.system, epoch.prn,
                                                        epoch.t_gps_s - epoch.pseudorange_m / C_M_S)
        if gone.any():
            key = "sat_rejected_no_accuracy_prediction"
            self._counts[key] = self._counts.get(key, 0) + int(gone.sum())

    def _push_raw(self, raw: RawGnss) -> None:
        epoch = raw.epoch
        atmosphere = None
        if epoch.n and not np.isfinite(epoch.sat_pos_ecef_m).any():
            if self._sats is None or epoch.time_base != "gps":
                self._counts["gnss_rejected_no_ephemeris"] += 1
                return
            st, t_tx = self._sats.transmission_states(epoch)  # transmission_states(self._sats, epoch)
            epoch = epoch.replace(sat_pos_ecef_m=st.pos_ecef_m, sat_vel_ecef_m_s=st.vel_ecef_m_s,
                                  sat_clock_s=st.clock_s, sat_clock_drift_s_s=st.clock_drift_s_s)
            if not st.valid.all():  # no (usable) ephemeris for some: as attach_broadcast, without them
                self._count_no_prediction(epoch, st.valid)
                epoch, t_tx = epoch.select(st.valid), t_tx[st.valid]
            if self.engine.frame is not None:
                atmosphere = self._atmosphere().delays_m(epoch.system, epoch.prn, t_tx,
                                                         self._sats.keys(epoch.system, epoch.prn))
        eng = self.engine
        if epoch.n == 0:
            self._counts["gnss_rejected_empty"] += 1
            return
        if not len(eng.imu):
            self._counts["gnss_rejected_before_imu"] += 1
            return
        if not eng.ensure_frame(epoch):
            self._counts["gnss_rejected_no_solution"] += 1
            return
        assert eng.frame is not None
        if self._cn0 is not None:  # C/N0 as the reference receiver would report it (cn0cal)
            self._cn0.add(epoch.cn0_dbhz)
            epoch = epoch.replace(cn0_dbhz=self._cn0.calibrated(epoch.cn0_dbhz))
        m = tight_engine.prepare_epoch(epoch, eng.frame, self.cfg, eng.klobuchar, atmosphere)
        if m is None:
            self._counts["gnss_rejected_empty"] += 1
            return
        eng.push_epoch(raw.t_us, m)

    def update_ephemerides(self, store: EphemerisStore) -> None:
        """Broadcast ephemerides for the epochs from now on (a receiver decodes them as it runs)."""
        self._sats = SatelliteCache(store, self._sats.period_s if self._sats else self._sat_period_s)
        self._atmo = None
        self.engine.klobuchar = store.klobuchar if store.klobuchar is not None else self.engine.klobuchar

    def _atmosphere(self) -> AtmosphereCache:
        """The atmosphere's delays at home, once per satellite and 5 s (``AtmosphereCache``)."""
        f = self.engine.frame
        assert f is not None and self._sats is not None
        if self._atmo is None:
            self._atmo = AtmosphereCache(self._sats, f.lat_rad, f.lon_rad, f.h_m, f.r0_ecef_m, f.c_ecef_ned,
                                         self.engine.klobuchar)
        return self._atmo

    def _push_odometry(self, o: Odometry) -> None:
        # a speed of NaN is a gyro alone (no wheel speed); an infinite one is damaged
        if math.isinf(o.speed_m_s) or not math.isfinite(o.yaw_rate_rad_s) or (
                self._odo is not None and o.t_us <= self._odo[0]):
            self._counts["odometry_rejected"] += 1
            return
        integral = 0.0
        if self._odo is not None:  # trapezoid
            t0, w0, i0 = self._odo
            integral = i0 + 0.5 * (w0 + o.yaw_rate_rad_s) * (o.t_us - t0) * 1e-6
        self._odo = (o.t_us, o.yaw_rate_rad_s, integral)
        self.engine.push_speed(o.t_us, o.speed_m_s, integral)

    def estimate(self) -> NavEstimate | None:
        """The estimate at the newest IMU time; None before the first epoch."""
        now = self.engine.output_now()
        if now is None:
            return None
        if self._last is not None and self._last[0] is now:
            return self._last[1]
        t_us, out, last = now  # one array, handed out as views (as the loose navigator does)
        info = last.info
        entries = self.engine.entries
        entry = entries[-1] if entries else None
        if self._reported[0] is not entry:  # a function of the last epoch alone: once per epoch
            k = self.accuracy_inflation()
            self._reported = (entry, variance_scale(k), self.accuracy_floor_m2(), self._snapshot_floor(k))
        _, scale, floor, snap = self._reported
        if snap is not None:  # snapshots correlated over seconds: not averaged down, up to one snapshot's;
            k, f_h, f_v, d = snap  # at least the one-signed delays' bias (snapshot_axis per axis, in C)
            cov = _tight.report_cov(out, k, f_h, f_v, d[0], d[1], d[2])  # a new array
        elif scale is not None:
            cov = out[9:18] * scale  # P's positions × k
        else:  # out's own view, copied only to be changed
            cov = out[9:18] if floor is None else out[9:18].copy()
        if floor is not None:  # + the common-mode floor, in quadrature
            cov[0:3] += floor
        est = new_nav_estimate(t_us, out[0:3], out[3:6], out[6:9], cov, info.beta_mean, info.nis,
                               self.method, pos_valid=t_us - last.t_good_us <= self._valid_us,
                               gnss_resets=last.totals[2])
        self._last = (now, est)
        return est

    def accuracy_inflation(self) -> float:
        """The factor (≥ 1) on the position variances the estimates report: the used pseudoranges'
        NIS per degree of freedom over the last ``accuracy_window_s`` (1 when that is 0)."""
        entries = self.engine.entries
        return accuracy_inflation(entries[-1].fit if entries else None, self.cfg.accuracy_window_s)

    def _snapshot_floor(self, k: float) -> tuple[float, SnapshotFloor | None, SnapshotFloor | None,
                                                  tuple[float, float, float]] | None:
        """(k, the floors of the epochs' own snapshot positions horizontal and vertical
        (``consistency.snapshot_parts``), the one-signed delays' bias² N, E, D: ``accuracy_delay_fraction``²
        × the last snapshot's ``delay_m2``); None without either (the report is k P)."""
        entries = self.engine.entries
        if not entries or self.cfg.accuracy_window_s <= 0.0:
            return None
        e = entries[-1]
        f_h = snapshot_parts(e.scatter_h, e.fix_var_m2[0], e.kept[0])
        f_v = snapshot_parts(e.scatter_v, e.fix_var_m2[1], e.kept[1])
        f2 = self._delay2
        d = (f2 * e.delay_m2[0], f2 * e.delay_m2[1], f2 * e.delay_m2[2])
        return None if f_h is None and f_v is None and not max(d) > 0.0 else (k, f_h, f_v, d)

    def accuracy_floor_m2(self) -> np.ndarray | None:
        """The variances (3,: N, E, D) added to the reported position's: ``accuracy_floor_m``² × the last
        used satellites' position DOPs; None when the floor is 0 or no geometry fixed a position yet."""
        entries = self.engine.entries
        q = entries[-1].info.q_pos_ned if entries and self.cfg.accuracy_floor_m > 0.0 else None
        if q is None or not np.isfinite(q).all():
            return None
        return self.cfg.accuracy_floor_m**2 * q

    def counters(self) -> dict[str, int]:
        return dict(self.engine.counts)
