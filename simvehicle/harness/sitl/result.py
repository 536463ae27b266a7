"""Turn what the SITL processes recorded into ``fly``'s result: same summary keys, same files."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from companion.domain.statistics import describe
from companion.planning import Route
from simvehicle.harness.backend import FlightResult
from simvehicle.harness.sitl.launcher import SitlOptions, SitlRun
from simvehicle.harness.sitl.outcome import process_exits
from simvehicle.recording import SPOOL_NAME, series_from_spool


def load_series(out_dir: Path, route: Route) -> dict[str, np.ndarray]:
    """The vehicle's 20 Hz record, with the reference taken from the route exactly as ``fly`` does
    (from the raw spool file when the vehicle was killed before it could write the ``.npz``)."""
    try:
        with np.load(out_dir / "vehicle_series.npz") as data:
            series = {k: data[k] for k in data.files}
    except (OSError, ValueError):
        try:
            series = series_from_spool(out_dir / SPOOL_NAME)
        except OSError:
            return {}
    if series["t_s"].size:
        series["p_ref_ned_m"] = route.reference(series["t_s"])[0]
        series["track_error_m"] = np.linalg.norm(series["p_true_ned_m"] - series["p_ref_ned_m"], axis=1)
    return series


def flight_result(opts: SitlOptions, run: SitlRun, route: Route, mission_name: str) -> FlightResult:
    series = load_series(opts.out_dir, route)
    v, e = run.vehicle, run.estimator
    nav = e.get("navigator", {})
    t_s = series.get("t_s", np.zeros(0))
    empty = np.zeros(0)
    clearance = series.get("clearance_m", empty)
    summary: dict[str, Any] = {
        "mission": mission_name,
        "profile": opts.profile,
        "method": opts.method,
        "seed": opts.seed,
        "reached_goal": v.get("outcome") == "reached_goal" and int(v.get("collisions", 0)) == 0,
        "collisions": int(v.get("collisions", 0)),
        "duration_s": float(t_s[-1]) if t_s.size else 0.0,
        "route_duration_s": route.duration_s,
        "wall_s": float(v.get("wall_s", math.nan)),
        "estimation_error_m": describe(series.get("est_error_m", empty)),
        "tracking_error_m": describe(series.get("track_error_m", empty)),
        "min_clearance_m": float(np.min(clearance)) if clearance.size else math.nan,
        "gnss": {
            "sent": int(v.get("gnss_sent", 0)),
            "fused": int(nav.get("gnss_fused", 0)),
            "rejected": int(sum(n for k, n in nav.items() if k.startswith("gnss_rejected"))),
        },
        "estimator_counters": nav,
        "sitl": {
            "mode": "realtime" if opts.realtime else "lockstep",
            "ended_by": run.ended_by,
            "outcome": v.get("outcome", "unknown"),
            "processes": process_exits(run.return_codes, run.ended_by),
            "lockstep": v.get("lockstep", {}),
            "links": {"vehicle": v.get("links", {}), "ground": v.get("ground", {}),
                      "estimator": e.get("link", {}), "bridge": run.bridge.get("link", {})},
            "vehicle_node": v.get("node", {}),
            "estimator_node": e.get("node", {}),
            "gnss_to_odometry_latency_ms": e.get("gnss_to_odometry_latency_ms", {}),
            "imu_period_jitter_ms": v.get("imu_period_jitter_ms", {}),
        },
    }
    if not t_s.size:
        series = {}
    return FlightResult(summary, series, route)
