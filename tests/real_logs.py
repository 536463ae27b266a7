"""The real quad106 log as domain samples in arrival order, and GNSS glitches injected into it.

Used by the estimator's real-data tests: ``load_quad106()`` decodes tests/data/quad106.tlog once
(HIGHRES_IMU, ATTITUDE_QUATERNION, GPS_RAW_INT, as ``beliefnav replay`` does); ``run()`` feeds a
sample list to a ``Navigator`` and records the estimate at every GNSS fix's arrival.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from companion.domain.geodesy import LocalNedFrame
from companion.domain.samples import AttitudeSample, GnssFix, ImuSample, NavEstimate
from companion.estimator import EstimatorConfig, Navigator
from companion.mavlink import codec
from companion.mavlink.tlog import read_tlog

QUAD106 = Path(__file__).parent / "data" / "quad106.tlog"
TYPES = ("HIGHRES_IMU", "ATTITUDE_QUATERNION", "GPS_RAW_INT")


@dataclass(frozen=True)
class Log:
    samples: tuple  # ImuSample | AttitudeSample | GnssFix, arrival order
    frame: LocalNedFrame  # home = the first 3-D fix

    def fix_indices(self) -> list[int]:
        return [i for i, s in enumerate(self.samples) if type(s) is GnssFix]

    def without_gnss_after(self, t_s: float) -> Log:
        """The log with every fix valid after ``t_s`` s (log time) removed: GNSS ends there."""
        t_first = _t_us(self.samples[0])
        return Log(tuple(s for s in self.samples
                         if type(s) is not GnssFix or s.t_validity_us - t_first <= t_s * 1e6), self.frame)

    def window(self, t0_s: float, t1_s: float) -> Log:
        """Samples whose time lies in [t0, t1) s after the first sample (same home)."""
        t_first = _t_us(self.samples[0])
        keep = tuple(s for s in self.samples if t0_s * 1e6 <= _t_us(s) - t_first < t1_s * 1e6)
        return Log(keep, self.frame)


def _t_us(s) -> int:
    return s.t_validity_us if type(s) is GnssFix else s.t_us


def load_quad106() -> Log:
    samples = []
    for _, msg in read_tlog(QUAD106, TYPES):
        s = codec.decode_sample(msg)
        if s is not None:
            samples.append(s)
    return _with_home(samples)


def load_log(path: Path) -> Log:
    """Any log ``beliefnav replay`` reads (.ulg, .bin, tlog): its IMU, attitude and GNSS samples."""
    from gcs_tools.replay.logs import open_log

    return _with_home([e for e in open_log(path) if type(e) in (ImuSample, AttitudeSample, GnssFix)])


def _with_home(samples: list) -> Log:
    first = next(s for s in samples if type(s) is GnssFix and s.fix_type >= 3)
    return Log(tuple(samples), LocalNedFrame(first.lat_deg, first.lon_deg, first.alt_m))


# A glitch: (time of the fix relative to the glitch start (s), clean fix NED (m)) -> glitched NED
# or None (unchanged)
Offset = Callable[[float, np.ndarray], np.ndarray | None]


def inject(log: Log, t0_s: float, duration_s: float, offset: Offset) -> Log:
    """The log with the fixes valid in [t0, t0 + duration) s (log time) replaced by ``offset``."""
    t_first = _t_us(log.samples[0])
    out = []
    for s in log.samples:
        if type(s) is GnssFix:
            t = (s.t_validity_us - t_first) * 1e-6 - t0_s
            if 0.0 <= t < duration_s:
                p = log.frame.to_ned_m(s.lat_deg, s.lon_deg, s.alt_m)
                q = offset(t, np.asarray(p, dtype=float))
                if q is not None:
                    lat, lon, alt = log.frame.to_geodetic(q)
                    s = dataclasses.replace(s, lat_deg=float(lat), lon_deg=float(lon), alt_m=float(alt))
        out.append(s)
    return Log(tuple(out), log.frame)


@dataclass(frozen=True)
class Run:
    t_s: np.ndarray  # estimate time, s after the log's first sample
    p_ned_m: np.ndarray  # (n, 3)
    beta: np.ndarray
    glitch: np.ndarray
    pos_valid: np.ndarray
    var_p_m2: np.ndarray  # (n, 3) position variances
    fix_t_s: np.ndarray  # validity times of the fixes pushed, s after the log's first sample
    counters: dict


def run(log: Log, method: str, cfg: EstimatorConfig | None = None, every_imu: int = 0) -> Run:
    """Replay ``log``; one row per GNSS fix arrival (the estimate right after it), or with
    ``every_imu`` one row per ``every_imu``-th IMU sample."""
    nav = Navigator(cfg or EstimatorConfig(), method, log.frame)
    rows: list[NavEstimate] = []
    k = 0
    for s in log.samples:
        nav.push(s)
        if every_imu and type(s) is ImuSample:
            k += 1
            if k % every_imu:
                continue
        if (type(s) is ImuSample) if every_imu else (type(s) is GnssFix):
            est = nav.estimate()
            if est is not None:
                rows.append(est)
    t_first = _t_us(log.samples[0])
    fix_t_s = np.array([(s.t_validity_us - t_first) * 1e-6 for s in log.samples if type(s) is GnssFix])
    return Run(np.array([(e.t_us - t_first) * 1e-6 for e in rows]), np.array([e.p_ned_m for e in rows]),
               np.array([e.beta for e in rows]), np.array([e.gnss_glitch for e in rows]),
               np.array([e.pos_valid for e in rows]), np.array([e.cov_diag[0:3] for e in rows]), fix_t_s,
               nav.counters())
