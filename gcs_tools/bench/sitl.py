"""``beliefnav bench sitl``: the three-process SITL over MAVLink/UDP on loopback.

- ``lockstep_realtime_factor``: simulated / wall seconds of a lockstep flight (default mission,
  profile 0, second-order; ``--quick``: first 30 s), counted from the vehicle's first step (process
  start-up excluded).
- Real-time mode (20 s simulated; ``--quick``: 10 s): ``gnss_to_odometry_latency_p99_ms`` from a
  GPS_RAW_INT datagram read by the companion to the ODOMETRY that includes it leaving it, and
  ``imu_period_jitter_p99_ms``, |period − 5 ms| between consecutive HIGHRES_IMU sends.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from typing import Any

from companion.estimator.methods import DEFAULT_METHOD
from simvehicle.harness.sitl.launcher import SitlOptions, launch

MISSION, PROFILE, METHOD, SEED = "default", 0, DEFAULT_METHOD, 0


def measure(args: argparse.Namespace) -> dict[str, Any]:
    quick = bool(getattr(args, "quick", False))
    with tempfile.TemporaryDirectory(prefix="beliefnav-bench-sitl-") as tmp:
        lock = launch(SitlOptions(MISSION, PROFILE, METHOD, SEED, Path(tmp) / "lockstep",
                                  max_duration_s=30.0 if quick else None, wall_timeout_s=600))
        real = launch(SitlOptions(MISSION, PROFILE, METHOD, SEED, Path(tmp) / "realtime",
                                  max_duration_s=10.0 if quick else 20.0, realtime=True, wall_timeout_s=120))
    v = lock.vehicle
    latency = real.estimator.get("gnss_to_odometry_latency_ms", {})
    jitter = real.vehicle.get("imu_period_jitter_ms", {})
    return {
        "mission": MISSION, "profile": PROFILE, "method": METHOD, "seed": SEED,
        "lockstep_sim_s": v.get("t_s"),
        "lockstep_wall_s": v.get("wall_s"),
        "lockstep_realtime_factor": v["t_s"] / v["wall_s"] if v.get("wall_s") else None,
        "lockstep_outcome": v.get("outcome"),
        "realtime_sim_s": real.vehicle.get("t_s"),
        "gnss_to_odometry_latency_p50_ms": latency.get("median"),
        "gnss_to_odometry_latency_p99_ms": latency.get("p99"),
        "gnss_fixes_timed": latency.get("n"),
        "imu_period_jitter_p50_ms": jitter.get("median"),
        "imu_period_jitter_p99_ms": jitter.get("p99"),
        "targets": {"lockstep_realtime_factor": ">= 20", "gnss_to_odometry_latency_p99_ms": "< 1"},
    }
