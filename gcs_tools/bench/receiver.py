"""``beliefnav bench receiver``: what the raw receiver (scenario ``canyon``) costs.

* ``fly_realtime_factor[_cpu]``: simulated seconds per wall (CPU) second of an in-process flight
  (``fly``: default mission, profile 0, second-order, seed 0; ``--quick``: the first 30 s) under
  ``canyon``, and the same flight under ``realistic`` (the same vehicle without the receiver) beside
  it; ``receiver_ms_per_sim_s_cpu`` is the difference, per simulated second.
* per 5 Hz epoch, CPU ms (best of 5 runs of 100 epochs along profile 4's canyon): the observation model
  (``Receiver.observe``: sky, ray tracing, signals), the receiver's single-point solution, and the
  UBX frames of an epoch (``UbxEncoder``, what the SITL vehicle process adds).

CPU time divides by the process's own CPU time (what an idle core would give); the wall-clock factors
and ``load_avg_1m`` say how busy the machine was.
"""

from __future__ import annotations

import argparse
import os
import time
from typing import Any

import numpy as np

from companion.gnss.constants import C_M_S
from companion.gnss.spp import solve_position
from companion.mission import load_mission
from simvehicle import SimVehicle
from simvehicle.harness.backend import FlightRequest, backend
from simvehicle.rawgnss import RawGnssModel
from simvehicle.receiver import RawObservation
from simvehicle.ubx import UbxEncoder

MISSION, PROFILE, METHOD, SEED = "default", 0, "second-order", 0
CANYON_PROFILE = 4


def _fly(scenario: str, max_s: float | None) -> tuple[float, float, float]:
    m = load_mission(MISSION, scenario)
    cpu0 = time.process_time()
    res = backend("inprocess").fly(FlightRequest(m, PROFILE, METHOD, SEED, max_duration_s=max_s))
    cpu = time.process_time() - cpu0
    s = res.summary
    return s["duration_s"], s["wall_s"], cpu


def per_epoch_ms(repeats: int = 5, n: int = 100) -> dict[str, float]:
    """Best-of CPU ms per epoch: observation, solution, UBX frames (a hovering-then-moving antenna)."""
    sim = SimVehicle(load_mission(MISSION, "canyon"), CANYON_PROFILE, SEED)
    gnss = sim.gnss
    assert isinstance(gnss, RawGnssModel)
    rx = gnss.receiver
    p0, v = sim.start_ned_m.copy(), np.array([3.0, 0.0, 0.0])
    rx.observe(0, p0, v)
    best = {"observe": np.inf, "solve": np.inf, "ubx": np.inf}
    t_us = 0
    for _ in range(repeats):
        epochs = []
        c0 = time.process_time()
        for _ in range(n):
            t_us += 200_000
            epochs.append(rx.observe(t_us, p0 + v * t_us * 1e-6 % 200.0, v))
        best["observe"] = min(best["observe"], (time.process_time() - c0) / n * 1e3)
        prev = None
        c0 = time.process_time()
        for ep, tr in epochs:
            cor = ep.replace(
                pseudorange_m=ep.pseudorange_m + C_M_S * ep.sat_clock_s - tr.model_atmosphere_m,
                corrected=True,
            )
            prev = solve_position(cor, gnss.spp, p0_ecef_m=prev).p_ecef_m
        best["solve"] = min(best["solve"], (time.process_time() - c0) / n * 1e3)
    enc = UbxEncoder(gnss.store)
    raws: list[RawObservation] = []
    while len(raws) < 50:
        raws += list(sim.advance(None, None).gnss_raw)
    c0 = time.process_time()
    for raw in raws:
        enc.epoch_frames(raw)
    best["ubx"] = (time.process_time() - c0) / len(raws) * 1e3
    return {f"{k}_ms_per_epoch_cpu": float(v) for k, v in best.items()}


def measure(args: argparse.Namespace) -> dict[str, Any]:
    max_s = 30.0 if getattr(args, "quick", False) else None
    sim_c, wall_c, cpu_c = _fly("canyon", max_s)
    sim_r, wall_r, cpu_r = _fly("realistic", sim_c)
    return {
        "fly_realtime_factor": sim_c / wall_c,
        "fly_realtime_factor_cpu": sim_c / cpu_c,
        "fly_realistic_realtime_factor_cpu": sim_r / cpu_r,
        "receiver_ms_per_sim_s_cpu": 1e3 * (cpu_c / sim_c - cpu_r / sim_r),
        "fly_sim_s": sim_c,
        "fly_mission": f"{MISSION} profile {PROFILE} seed {SEED} {METHOD}",
        **per_epoch_ms(),
        "load_avg_1m": os.getloadavg()[0],
    }
