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

With the canyon receiver (scenario ``canyon``) the flight also records its raw epochs: the tightly
coupled rows (``tight-<weighting>``, ``companion.tight``) are run on exactly those epochs (pushed
at their release, fused at their measurement time, on the same IMU stream) with the flown mission's
map as the per-satellite belief's line-of-sight prior (the city the receiver flew in), and row ``spp``
is the receiver's own fix as it arrived (what the autopilot's EKF was sent).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from companion.domain.samples import AttitudeSample, ImuSample
from companion.estimator import EstimatorConfig
from companion.gnss.ephemeris import EphemerisStore
from companion.mission import Mission
from companion.tight import RawGnss, TightConfig
from companion.wiring import mission_city, navigator_for, tight_navigator_for
from simvehicle.harness.foreign.gnss_source import SentFix
from simvehicle.harness.foreign.recording import Recording
from simvehicle.receiver import RawObservation

LIVE_ROW = "companion-live"  # closed loop: what the companion process sent the autopilot (its tlog)
SPP_ROW = "spp"  # the canyon receiver's own single-point fixes, as they arrived (what the autopilot got)
PushImu = Callable[[int, np.ndarray, np.ndarray], None]  # (t_us, acc_frd_m_s2, q_ned_frd)
TIGHT_PREFIX = "tight-"  # the tightly coupled rows on the canyon receiver's raw epochs: tight-<weighting>


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
    push = nav.push
    gyro = np.zeros(3)  # unused by the filter (attitude comes with each sample)

    def push_imu(t_us: int, acc_frd_m_s2: np.ndarray, q_ned_frd: np.ndarray) -> None:
        # one sample: what Navigator.push_imu_batch does with it (below its BATCH_MIN), without the
        # batch's array checks (a third of the scoring's time)
        push(AttitudeSample(t_us, q_ned_frd))
        push(ImuSample(t_us, acc_frd_m_s2, gyro))

    def push_fix(sf: SentFix) -> None:  # with the accuracies and Doppler velocity the autopilot's EKF got
        nav.push_fix_ned(sf.fix.t_validity_us, sf.p_ned_m, sf.fix.h_acc_m, sf.fix.v_acc_m, sf.v_ned_m_s,
                         sf.speed_accuracy_m_s)

    return _replayed(rec, [(sf.arrival_us, sf) for sf in sent], push_imu, push_fix, nav, times_us)


def tight_track(rec: Recording, raws: list[RawObservation], weighting: str, store: EphemerisStore,
                mission: Mission, times_us: np.ndarray, map_prior: bool = True) -> Track:
    """The tightly coupled filter (``companion.tight``, ``weighting``, ``TightConfig()``) over the
    recording: the IMU and attitude the autopilot streamed, the receiver's raw epochs pushed at their
    release and fused at their measurement time, satellite states from the sky's broadcast ephemerides
    (``store``), in the mission's frame with its map's line of sight as the belief's prior (the flight
    was flown in that city; ``map_prior=False``: no map)."""
    nav = tight_navigator_for(mission, weighting, config=TightConfig(), ephemerides=store,
                              city=mission_city(mission) if map_prior else None)
    gyro = np.zeros(3)  # unused by the filter (attitude comes with each sample)

    def push_imu(t_us: int, acc_frd_m_s2: np.ndarray, q_ned_frd: np.ndarray) -> None:
        nav.push(AttitudeSample(t_us, q_ned_frd))
        nav.push(ImuSample(t_us, acc_frd_m_s2, gyro))

    def push_raw(raw: RawObservation) -> None:
        nav.push(RawGnss(raw.t_us, raw.epoch))

    return _replayed(rec, [(raw.arrival_us, raw) for raw in raws], push_imu, push_raw, nav, times_us)


def _replayed(rec: Recording, arrivals: list[tuple[int, Any]], push_imu: PushImu, push: Callable[[Any], None],
              nav: Any, times_us: np.ndarray) -> Track:
    """As the session pushes them: each IMU sample, then the GNSS items (``(arrival µs, item)``, in
    arrival order) released with it; ``nav``'s estimate right after the IMU sample at each time."""
    n = len(times_us)
    p, b = np.full((n, 3), np.nan), np.full((n, 3), np.nan)
    beta, nis = np.full(n, np.nan), np.full(n, np.nan)
    k = j = 0
    for i, t in enumerate(rec.imu_t_us):
        push_imu(t, rec.imu_acc_frd_m_s2[i], rec.imu_q_ned_frd[i])
        while k < len(arrivals) and arrivals[k][0] <= t:
            push(arrivals[k][1])
            k += 1
        while j < n and times_us[j] < t:
            j += 1  # an evaluation time without its IMU sample (dropped): skipped, stays NaN
        if j < n and times_us[j] == t:
            est = nav.estimate()
            if est is not None:
                p[j], b[j], beta[j], nis[j] = est.p_ned_m, est.b_ned_m, est.beta, est.nis
            j += 1
    return Track(p, b, beta, nis, nav.counters())


def held_track(arrival_us: np.ndarray, p_ned_m: np.ndarray, times_us: np.ndarray) -> Track:
    """The latest position that had arrived by each time (a consumer of the fixes: the receiver's own
    single-point solution as it arrived); NaN before the first."""
    n = len(times_us)
    p = np.full((n, 3), np.nan)
    idx = np.searchsorted(np.asarray(arrival_us, dtype=np.int64), times_us, side="right") - 1
    ok = idx >= 0
    p[ok] = np.asarray(p_ned_m, dtype=float).reshape(-1, 3)[idx[ok]]
    nan = np.full(n, np.nan)
    return Track(p, np.full((n, 3), np.nan), nan, nan, {})


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
