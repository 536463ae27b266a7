"""``beliefnav bench fly``: simulated seconds per wall second of an in-process flight.

``sim_realtime_factor``: the default mission, profile 0, second-order estimator, whole flight
(``--quick``: first 30 s), one process on one core; planning is timed separately. The vehicle
alone (truth fed back as the estimate, no estimator) is measured as ``vehicle_realtime_factor``
to show where the time goes. ``*_cpu`` factors divide by the process's CPU time instead of the
wall clock (what an idle core would give; on a shared machine the wall clock also counts time
spent waiting for a core), and ``load_avg_1m`` says how busy the machine was.
"""

from __future__ import annotations

import argparse
import os
import time
from typing import Any

import numpy as np

from companion.domain.samples import NavEstimate
from companion.mission import load_mission
from companion.planning import plan_route
from gcs_tools.fly import fly
from simvehicle import SimVehicle

MISSION, PROFILE, METHOD, SEED = "default", 0, "second-order", 0


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


def measure(args: argparse.Namespace) -> dict[str, Any]:
    quick = bool(getattr(args, "quick", False))
    mission = load_mission(MISSION)
    t0, cpu0 = time.perf_counter(), time.process_time()
    plan_route(mission, PROFILE, t_start_s=2.0)
    plan_s, plan_cpu_s = time.perf_counter() - t0, time.process_time() - cpu0
    cpu0 = time.process_time()
    res = fly(mission, PROFILE, METHOD, SEED, max_duration_s=30.0 if quick else None)
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
    }
