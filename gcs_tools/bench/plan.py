"""Planner speed on the default city: ``beliefnav bench plan --json``.

Wall time of ``plan_route`` (A* + line-of-sight pruning + min-jerk timing) for each of the
10 evaluation profiles, best of a few repeats so a busy machine disturbs it less.
"""

from __future__ import annotations

import argparse
import statistics
import time
from typing import Any

from companion.mission import load_mission
from companion.planning import plan_route


def measure(args: argparse.Namespace) -> dict[str, Any]:
    mission = load_mission("default")
    repeats = 1 if getattr(args, "quick", False) else 3
    wall_s, expanded, length_m = [], [], []
    for k in range(len(mission.profiles)):
        best = float("inf")
        for _ in range(repeats):
            t0 = time.perf_counter()
            route = plan_route(mission, k)
            best = min(best, time.perf_counter() - t0)
        wall_s.append(best)
        expanded.append(route.grid_path.expanded)
        length_m.append(route.length_m)
    return {
        "plan_wall_s_median": statistics.median(wall_s),
        "plan_wall_s_max": max(wall_s),
        "plan_expanded_states_median": statistics.median(expanded),
        "route_length_m": [round(x, 1) for x in length_m],
        "grid_cells": mission.world.shape[0] * mission.world.shape[1],
    }
