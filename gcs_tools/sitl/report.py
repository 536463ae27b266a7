"""Summary of a SITL run from what the processes recorded (keys as ``gcs_tools.fly``'s summary)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from gcs_tools.sitl.launcher import SitlRun


def error_stats(errors_m: np.ndarray) -> dict[str, float]:
    e = errors_m[np.isfinite(errors_m)]
    if e.size == 0:
        return {"median": math.nan, "p95": math.nan, "rmse": math.nan}
    return {"median": float(np.median(e)), "p95": float(np.percentile(e, 95)),
            "rmse": float(np.sqrt(np.mean(e * e)))}


def load_series(out_dir: Path) -> dict[str, np.ndarray]:
    try:
        with np.load(out_dir / "vehicle_series.npz") as data:
            return {k: data[k] for k in data.files}
    except (OSError, ValueError):
        return {}


def summarize(run: SitlRun, series: dict[str, np.ndarray], method: str, seed: int) -> dict[str, Any]:
    v, e = run.vehicle, run.estimator
    nav = e.get("navigator", {})
    t_s = series.get("t_s", np.zeros(0))
    clearance = series.get("clearance_m", np.zeros(0))
    vehicle_links = v.get("links", {})
    gnss_sent = int(v.get("gnss_sent", 0))
    return {
        "method": method,
        "seed": seed,
        "ended_by": run.ended_by,
        "outcome": v.get("outcome", "unknown"),
        "reached_goal": v.get("outcome") == "reached_goal",
        "collisions": int(v.get("collisions", 0)),
        "duration_s": float(t_s[-1]) if t_s.size else 0.0,
        "wall_s": float(v.get("wall_s", math.nan)),
        "estimation_error_m": error_stats(series.get("est_error_m", np.zeros(0))),
        "tracking_error_m": error_stats(series.get("track_error_m", np.zeros(0))),
        "min_clearance_m": float(np.min(clearance)) if clearance.size else math.nan,
        "gnss": {
            "sent": gnss_sent,
            "fused": int(nav.get("gnss_fused", 0)),
            "rejected": int(sum(n for k, n in nav.items() if k.startswith("gnss_rejected"))),
        },
        "links": {"vehicle": vehicle_links, "ground": v.get("ground", {}), "estimator": e.get("link", {}),
                  "bridge": run.bridge.get("link", {})},
        "lockstep": v.get("lockstep", {}),
        "return_codes": run.return_codes,
    }
