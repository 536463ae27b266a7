"""After a flight beside a foreign autopilot: every companion method on the recorded samples, the
autopilot's EKF, truth.

Pure code, no I/O. The companion's inputs are exactly what the autopilot streamed (HIGHRES_IMU
with the latest ATTITUDE_QUATERNION, in its boot time) and exactly the fixes it was sent (fused
at their validity time, pushed at their release time, with the accuracies and the Doppler
velocity the autopilot's EKF is given), so each method is what a companion reading this
autopilot would have estimated in open loop, and all methods and the autopilot's
EKF (EKF3, EKF2) are compared on identical GNSS. Errors are taken at the truth samples
(ArduPilot's SIM_STATE, PX4 SIH's HIL_STATE_QUATERNION) of the route phase; the EKF's
GLOBAL_POSITION_INT is interpolated linearly to those times.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from companion.estimator import EstimatorConfig
from companion.mission import Mission
from companion.wiring import navigator_for
from simvehicle.harness.foreign.gnss_source import SentFix
from simvehicle.harness.foreign.recording import Recording

LIVE_ROW = "companion-live"  # closed loop: what the companion process sent the autopilot (its tlog)


@dataclass(frozen=True)
class Track:
    """One estimator's output at the evaluation times (N,)."""

    p_ned_m: np.ndarray  # (N, 3), NaN before its first estimate
    b_ned_m: np.ndarray  # (N, 3) estimated multipath bias (NaN for the autopilot's EKF)
    beta: np.ndarray
    nis: np.ndarray
    counters: dict[str, int]


def companion_track(rec: Recording, sent: list[SentFix], method: str, cfg: EstimatorConfig,
                    mission: Mission, times_us: np.ndarray) -> Track:
    """Run ``method`` (``cfg``, the mission's plugin parameters, map and frame) over the recording; its
    estimate right after the IMU sample (and the fixes released with it) at each time: exactly what
    the closed loop's live companion computes."""
    nav = navigator_for(mission, method, config=cfg)
    n = len(times_us)
    p, b = np.full((n, 3), np.nan), np.full((n, 3), np.nan)
    beta, nis = np.full(n, np.nan), np.full(n, np.nan)
    imu_t = rec.imu_t_us
    k = j = 0
    for i, t in enumerate(imu_t):  # as the session pushes them: the IMU sample, then the fixes released
        nav.push_imu_batch(np.array([t]), rec.imu_acc_frd_m_s2[i][None, :], rec.imu_q_ned_frd[i][None, :])
        while k < len(sent) and sent[k].arrival_us <= t:
            sf = sent[k]  # with the accuracies and the Doppler velocity the autopilot's EKF is sent
            nav.push_fix_ned(sf.fix.t_validity_us, sf.p_ned_m, sf.fix.h_acc_m, sf.fix.v_acc_m, sf.v_ned_m_s,
                             sf.speed_accuracy_m_s)
            k += 1
        while j < n and times_us[j] < t:
            j += 1  # an evaluation time without its IMU sample (dropped): skipped, stays NaN
        if j < n and times_us[j] == t:
            est = nav.estimate()
            if est is not None:
                p[j], b[j], beta[j], nis[j] = est.p_ned_m, est.b_ned_m, est.beta, est.nis
            j += 1
    return Track(p, b, beta, nis, nav.counters())


def autopilot_track(rec: Recording, times_us: np.ndarray) -> Track:
    """The autopilot EKF's GLOBAL_POSITION_INT, interpolated to ``times_us`` (NaN outside its span)."""
    return interpolated_track(np.asarray(rec.ekf_t_us, dtype=float), np.asarray(rec.ekf_p_ned_m), times_us)


def interpolated_track(t_us: np.ndarray, p_ned_m: np.ndarray, times_us: np.ndarray) -> Track:
    """A position series (any order) interpolated linearly to ``times_us`` (NaN outside its span)."""
    n = len(times_us)
    p = np.full((n, 3), np.nan)
    if len(t_us) >= 2:
        t_e = np.asarray(t_us, dtype=float)
        order = np.argsort(t_e, kind="stable")
        t_e, p_e = t_e[order], np.asarray(p_ned_m, dtype=float).reshape(-1, 3)[order]
        inside = (times_us >= t_e[0]) & (times_us <= t_e[-1])
        for axis in range(3):
            p[inside, axis] = np.interp(times_us[inside], t_e, p_e[:, axis])
    nan = np.full(n, np.nan)
    return Track(p, np.full((n, 3), np.nan), nan, nan, {})


def errors(p_est_ned_m: np.ndarray, p_true_ned_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(3-D error, horizontal error) per sample."""
    d = p_est_ned_m - p_true_ned_m
    return np.linalg.norm(d, axis=1), np.linalg.norm(d[:, :2], axis=1)


def count_collisions(clearance_m: np.ndarray, radius_m: float) -> int:
    """Contacts: entries into ``clearance < radius`` (as the simulated vehicle counts them)."""
    inside = clearance_m < radius_m
    return int(np.count_nonzero(inside[1:] & ~inside[:-1]) + (1 if inside.size and inside[0] else 0))
