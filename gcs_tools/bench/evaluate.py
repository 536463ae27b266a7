"""``beliefnav bench evaluate``: wall time of the 10-profile × 4-method campaign (seed 0).

Runs the same grid with 2 workers (the target: ≤ 60 s) and with 1 worker, and reports the
speed-up. ``--quick`` flies 4 profiles with a 20 s cap instead (a smoke check).
"""

from __future__ import annotations

import argparse
import time
from typing import Any

from gcs_tools.evaluate import campaign

METHODS = ("naive", "adaptive", "first-order", "second-order")
TARGET_WALL_S = 60.0


def timed(jobs: list[campaign.Job], workers: int) -> tuple[float, list[campaign.JobResult]]:
    t0 = time.perf_counter()
    results = campaign.run(jobs, workers, progress=False)
    return time.perf_counter() - t0, results


def measure(args: argparse.Namespace) -> dict[str, Any]:
    quick = bool(getattr(args, "quick", False))
    profiles = range(4) if quick else range(10)
    jobs = campaign.grid("default", profiles, METHODS, [0], 20.0 if quick else None)
    wall_2, results = timed(jobs, 2)
    wall_1, _ = timed(jobs, 1)
    flown_s = sum(float(r.summary.get("duration_s", 0.0)) for r in results)
    return {
        "evaluate": {
            "flights": len(jobs),
            "profiles": len(profiles),
            "methods": list(METHODS),
            "quick": quick,
            "simulated_s": round(flown_s, 1),
            "wall_2_workers_s": round(wall_2, 2),
            "wall_1_worker_s": round(wall_1, 2),
            "speedup_1_to_2": round(wall_1 / wall_2, 2),
            "target_wall_2_workers_s": TARGET_WALL_S,
            "meets_target": wall_2 <= TARGET_WALL_S,
        }
    }
