"""The acceleration's change over held IMU time, on the simulated quadrotor's truth:
``python -m gcs_tools.evaluate.hold_probe``.

    python -m gcs_tools.evaluate.hold_probe --mission default-tuning --profiles 0-3 --seeds 1000-1001

Each profile is flown on the second-order filter's estimate (the planned route from a 1 s hover, to 1.5
times its duration; the attitude, IMU and fixes pushed as they arrive): its acceleration changes where
the control answers the estimate's corrections, as a vehicle flying on its estimator does (flown on
its true state: σ 0.005-0.006 horizontal, under 0.001 vertical at 40 ms). The true NED acceleration of
each physics tick (its velocity change over the tick) held over L = m ticks, as the filter holds a
sample when the next ones are lost, misses dv = Σᵢ (a_{k+i} − a_k) dt. An acceleration random walk of
density σ² gives dv the variance σ² L³ / 3; the probe prints, per hold length and NED axis, the σ that
matches the flights' E[dv²] (JSON): the estimator's ``imu_hold_acc_rw_m_s2_sqrt_s``
(companion/estimator/history.py, "Held time"), chosen on the tuning mission only.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence

import numpy as np

from gcs_tools import choices

HOLDS_MS = (20, 40, 45, 80)


def hold_density(v_ned_m_s: np.ndarray, dt_s: float, ticks: int) -> np.ndarray:
    """σ (3,) with σ² = 3 E[dv²] / L³ for the tick accelerations a_k = (v_{k+1} − v_k) / dt held over L =
    ``ticks`` dt: dv_k = Σ_{i<ticks} (a_{k+i} − a_k) dt, over every k."""
    a = np.diff(v_ned_m_s, axis=0) / dt_s
    c = np.vstack([np.zeros(3), np.cumsum(a * dt_s, axis=0)])
    n = len(a) - ticks + 1
    dv = c[ticks:ticks + n] - c[:n] - a[:n] * (ticks * dt_s)
    L = ticks * dt_s
    return np.sqrt(3.0 * np.mean(dv * dv, axis=0) / L**3)


def true_velocity(mission: str, profile: int, seed: int,
                  method: str = "second-order") -> tuple[np.ndarray, float]:
    """The true NED velocity at every physics tick of one flight flown on ``method``'s estimate
    (``attitude_check.flown_on_estimate``), and the tick (s)."""
    from companion.mission import load_mission
    from companion.wiring import navigator_for
    from gcs_tools.evaluate.attitude_check import flown_on_estimate
    from simvehicle.harness.fly import planned_route
    from simvehicle.vehicle import SimVehicle

    m = load_mission(mission)
    route = planned_route(m, profile, 1.0)
    sim = SimVehicle(m, profile, seed)
    end_us = round((1.0 + route.duration_s * 1.5) * 1e6)
    v = [out.v_ned_m_s for out in flown_on_estimate(sim, navigator_for(m, method), route, end_us)]
    return np.concatenate(v), sim.config.vehicle.physics_dt_us * 1e-6


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(allow_abbrev=False, prog="python -m gcs_tools.evaluate.hold_probe",
                                description=(__doc__ or "").splitlines()[0])
    p.add_argument("--mission", default="default-tuning")
    p.add_argument("--profiles", default="0-3")
    p.add_argument("--seeds", default="1000-1001")
    args = p.parse_args(argv)
    m = choices.mission(args.mission)
    profiles = choices.profiles(args.profiles, len(m.profiles))
    flights = [true_velocity(args.mission, pr, s) for pr in profiles for s in choices.seeds(args.seeds)]
    dt = flights[0][1]
    out = {"mission": args.mission, "profiles": list(profiles), "seeds": list(choices.seeds(args.seeds)),
           "sigma_m_s2_sqrt_s": {}}
    for ms in HOLDS_MS:
        ticks = round(ms * 1e-3 / dt)
        # E[dv²] over all flights' ticks together (each flight's mean weighted by its length)
        w = np.array([len(v) for v, _ in flights], dtype=float)
        var = np.array([hold_density(v, dt, ticks) ** 2 for v, _ in flights])
        sigma = np.sqrt((w[:, None] * var).sum(axis=0) / w.sum())
        out["sigma_m_s2_sqrt_s"][f"{ms} ms"] = {"north": round(float(sigma[0]), 3),
                                               "east": round(float(sigma[1]), 3),
                                               "down": round(float(sigma[2]), 3)}
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
