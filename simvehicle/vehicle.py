"""``SimVehicle``: truth, autopilot and sensors of one quadrotor, advanced one control period at a time.

Wire-agnostic: ``advance(estimate, setpoint)`` takes and returns domain types only, so the
same object runs in-process (``beliefnav fly``) and inside the vehicle process (SITL).
Time starts at ``t_us = 0`` (vehicle boot) hovering at the mission's flight altitude over the
profile's start point, yaw 0 (facing north).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from companion.errors import UserError
from companion.wire.samples import AttitudeSample, GnssFix, ImuSample, NavEstimate, Setpoint, TruthState
from simvehicle.autopilot import Autopilot
from simvehicle.config import SimConfig, sim_config_for
from simvehicle.dynamics import RigidBody
from simvehicle.gnss import GnssModel
from simvehicle.imu import Imu, rotations, specific_force_frd


@dataclass(frozen=True, slots=True)
class StepOutput:
    """What one control period produced, in time order within each list."""

    t_us: int  # end of the period
    imu: list[ImuSample]
    attitude: list[AttitudeSample]
    gnss: list[GnssFix]  # released this period (latency elapsed), stamped with validity time
    truth: list[TruthState]  # one per IMU sample
    collided: bool  # within radius_m of a building, or at/below the ground, at the end of the period
    gnss_arrival_us: list[int] = field(default_factory=list)  # arrival tick of each ``gnss`` entry


class SimVehicle:
    """One simulated quadrotor flying a mission profile; every random draw from ``seed``."""

    def __init__(self, mission: Any, profile_index: int, seed: int, config: SimConfig | None = None) -> None:
        profiles = mission.profiles
        if not 0 <= profile_index < len(profiles):
            last = len(profiles) - 1
            raise UserError(f"profile {profile_index}: mission {mission.name!r} has profiles 0..{last}")
        self.config = cfg = config or sim_config_for(mission)
        self.mission = mission
        self._world = mission.world
        n0, e0 = (float(c) for c in profiles[profile_index].start_ne_m)
        self.start_ned_m = np.array([n0, e0, -float(mission.altitude_m)])
        imu_seq, gnss_seq = np.random.SeedSequence(seed).spawn(2)
        self.body = RigidBody(cfg.vehicle, self.start_ned_m)
        self.autopilot = Autopilot(cfg.autopilot, cfg.vehicle, self.start_ned_m)
        self.imu = Imu(cfg.imu, np.random.default_rng(imu_seq))
        self._clearance_m = self._clearance(self.start_ned_m)
        period_s = 1.0 / cfg.vehicle.control_rate_hz
        gnss_rng = np.random.default_rng(gnss_seq)
        self.gnss = GnssModel(cfg.gnss, period_s, mission.frame, gnss_rng, self._clearance_m)
        self.t_us = 0
        self._dt_us = cfg.vehicle.physics_dt_us
        self._dt_s = self._dt_us * 1e-6
        self._steps = cfg.vehicle.steps_per_control
        self._g_ned = np.array([0.0, 0.0, cfg.vehicle.gravity_m_s2])

    def _clearance(self, p_ned_m: np.ndarray) -> float:
        return float(self._world.clearance_m(float(p_ned_m[0]), float(p_ned_m[1])))

    @property
    def p_ned_m(self) -> np.ndarray:
        return np.array(self.body.x[0:3])

    @property
    def clearance_m(self) -> float:
        """Exact clearance of the true position at ``t_us`` (eq. 22)."""
        return self._clearance_m

    def advance(self, estimate: NavEstimate | None, setpoint: Setpoint | None) -> StepOutput:
        """Fly one control period (outer loop once, inner loop and physics every step)."""
        ap, body, gnss = self.autopilot, self.body, self.gnss
        ap.outer(self.t_us, estimate, setpoint)
        t, dt_s, dt_us, veh = self.t_us, self._dt_s, self._dt_us, self.config.vehicle
        rows: list[list[float]] = []
        fixes: list[GnssFix] = []
        arrivals: list[int] = []
        for _ in range(self._steps):
            x = body.x
            thrust, tx, ty, tz = ap.inner((x[6], x[7], x[8], x[9]), x[10], x[11], x[12])
            body.step(dt_s, thrust, tx, ty, tz)
            t += dt_us
            rows.append([*specific_force_frd(veh, thrust, body.x), *body.x])
            if gnss.pending:
                for fix in gnss.release(t):
                    fixes.append(fix)
                    arrivals.append(t)
        self.t_us = t

        block = np.array(rows)  # (steps, 16): specific force, p, v, q, omega
        p, v, q, omega = block[:, 3:6], block[:, 6:9], block[:, 9:13], block[:, 13:16]
        acc, gyro = self.imu.measure(block[:, 0:3], omega)
        if ap.holding:
            ap.dead_reckon(np.einsum("nij,nj->ni", rotations(q), acc) + self._g_ned, dt_s)

        # one GNSS fix per period, valid at its end; truth carries the bias of the latest valid fix
        prev_bias, prev_latency_s, prev_clearance_m = gnss.bias_ned_m, gnss.latency_s, self._clearance_m
        self._clearance_m = self._clearance(p[-1])
        gnss.sample(t, p[-1], self._clearance_m)
        for fix in gnss.release(t):
            fixes.append(fix)
            arrivals.append(t)

        times = range(t - (self._steps - 1) * dt_us, t + 1, dt_us)
        last = self._steps - 1
        imu = [ImuSample(ti, acc[i], gyro[i]) for i, ti in enumerate(times)]
        attitude = [AttitudeSample(ti, q[i]) for i, ti in enumerate(times)]
        truth = [
            TruthState(ti, p[i], v[i], q[i], gnss_bias_ned_m=prev_bias, gnss_latency_s=prev_latency_s,
                       clearance_m=prev_clearance_m)
            if i < last else
            TruthState(ti, p[i], v[i], q[i], gnss_bias_ned_m=gnss.bias_ned_m, gnss_latency_s=gnss.latency_s,
                       clearance_m=self._clearance_m)
            for i, ti in enumerate(times)
        ]
        collided = self._clearance_m < self.config.vehicle.radius_m or p[-1, 2] >= 0.0
        return StepOutput(t, imu, attitude, fixes, truth, bool(collided), arrivals)
