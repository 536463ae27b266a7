"""``beliefnav bench fly``: simulated seconds per wall second of an in-process flight.

``sim_realtime_factor``: the default mission, profile 0, second-order estimator, whole flight
(``--quick``: first 30 s), one process on one core; planning is timed separately. The vehicle
alone (truth fed back as the estimate, no estimator) is measured as ``vehicle_realtime_factor``
to show where the time goes. ``*_cpu`` factors divide by the process's CPU time instead of the
wall clock (what an idle core would give; on a shared machine the wall clock also counts time
spent waiting for a core), and ``load_avg_1m`` says how busy the machine was.

``fly_memory_rss_mb_by_sim_min`` (not with --quick): peak resident memory of a fresh process that
flies the same profile for 10 and for 60 simulated minutes (the goal test disabled, so the vehicle
hovers at the goal after the route), and ``fly_memory_growth_mb_10_to_60_min`` between them: the
flight keeps its record as plain floats (136 B per 50 ms step, 9.8 MB per hour).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from typing import Any

import numpy as np

from companion.domain.samples import NavEstimate
from companion.estimator.methods import DEFAULT_METHOD
from companion.mission import load_mission
from companion.planning import plan_route
from simvehicle import SimVehicle
from simvehicle.harness.backend import FlightRequest, backend

MISSION, PROFILE, METHOD, SEED = "default", 0, DEFAULT_METHOD, 0


def vehicle_only_s(mission: Any, sim_s: float) -> tuple[float, float]:
    """Wall and CPU seconds to fly ``sim_s`` of profile 0 with truth feedback (the vehicle's own cost)."""
    route = plan_route(mission, PROFILE, t_start_s=2.0)
    sim = SimVehicle(mission, PROFILE, SEED)
    est, zero9 = None, np.zeros(9)
    t0, cpu0 = time.perf_counter(), time.process_time()
    while sim.t_us < sim_s * 1e6:
        out = sim.advance(est, route.setpoint(sim.t_us))
        tr = out.final_truth
        est = NavEstimate(out.t_us, tr.p_ned_m, tr.v_ned_m_s, tr.gnss_bias_ned_m, zero9, 1.0, np.nan, "truth")
    return time.perf_counter() - t0, time.process_time() - cpu0


_MEMORY_CHILD = """
import json, resource, sys
from simvehicle.harness.fly import FlyConfig, fly
duration_s = float(sys.argv[1])
res = fly("{mission}", {profile}, "{method}", {seed}, max_duration_s=duration_s,
          config=FlyConfig(goal_radius_m=-1.0, timeout_margin_s=duration_s))
print(json.dumps({{"sim_s": res.summary["duration_s"],
                  "max_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}}))
"""


def fly_memory(minutes: tuple[int, ...] = (10, 60)) -> dict[str, Any]:
    """Peak RSS of a fresh process flying ``minutes`` of simulated time (one process per length)."""
    code = _MEMORY_CHILD.format(mission=MISSION, profile=PROFILE, method=METHOD, seed=SEED)
    marks: dict[str, float] = {}
    for m in minutes:
        done = subprocess.run([sys.executable, "-c", code, str(60.0 * m)], capture_output=True, text=True,
                              check=True)
        marks[str(m)] = round(json.loads(done.stdout.strip().splitlines()[-1])["max_rss_mb"], 1)
    return {"fly_memory_rss_mb_by_sim_min": marks,
            "fly_memory_growth_mb_10_to_60_min": round(marks[str(minutes[-1])] - marks[str(minutes[0])], 1)}


def measure(args: argparse.Namespace) -> dict[str, Any]:
    quick = bool(getattr(args, "quick", False))
    mission = load_mission(MISSION)
    t0, cpu0 = time.perf_counter(), time.process_time()
    plan_route(mission, PROFILE, t_start_s=2.0)
    plan_s, plan_cpu_s = time.perf_counter() - t0, time.process_time() - cpu0
    cpu0 = time.process_time()
    res = backend("inprocess").fly(FlightRequest(mission, PROFILE, METHOD, SEED,
                                                 max_duration_s=30.0 if quick else None))
    fly_cpu_s = time.process_time() - cpu0 - plan_cpu_s  # fly() plans the route again
    s = res.summary
    vehicle_s, vehicle_cpu_s = vehicle_only_s(mission, s["duration_s"])
    return {
        "sim_realtime_factor": s["duration_s"] / s["wall_s"],
        "sim_realtime_factor_cpu": s["duration_s"] / fly_cpu_s,
        "vehicle_realtime_factor_cpu": s["duration_s"] / vehicle_cpu_s,
        "load_avg_1m": os.getloadavg()[0],
        "fly_sim_s": s["duration_s"],
        "fly_wall_s": s["wall_s"],
        "plan_wall_s": plan_s,
        "vehicle_realtime_factor": s["duration_s"] / vehicle_s,
        "fly_mission": f"{MISSION} profile {PROFILE} seed {SEED}",
        "fly_method": METHOD,
        "fly_reached_goal": s["reached_goal"],
        **({} if quick else fly_memory()),
    }
