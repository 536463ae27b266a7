"""``SimVehicle``: truth, autopilot and sensors of one quadrotor, advanced one control period at a time.

Wire-agnostic: ``advance(estimate, setpoint)`` takes and returns domain types only, so the
same object runs in-process (``beliefnav fly``) and inside the vehicle process (SITL).
Time starts at ``t_us = 0`` (vehicle boot) hovering at the mission's flight altitude over the
profile's start point, yaw 0 (facing north).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

from companion.domain.samples import AttitudeSample, GnssFix, ImuSample, NavEstimate, Setpoint, TruthState
from companion.errors import UserError
from simvehicle.ahrs import Ahrs
from simvehicle.autopilot import Autopilot
from simvehicle.baro import Barometer
from simvehicle.config import SimConfig, sim_config_for
from simvehicle.dynamics import RigidBody
from simvehicle.gnss import GnssModel, NedFix
from simvehicle.imu import Imu, specific_force_frd
from simvehicle.nlos import UnmodelledGnss
from simvehicle.rawgnss import RawGnssModel
from simvehicle.receiver import RawObservation

# columns of the per-period block: specific force (0-2), then the RigidBody state (3-15)
_BLOCK_COLUMNS = 16


@dataclass(frozen=True, eq=False)
class StepOutput:
    """What one control period produced, in time order.

    The period is held as arrays (one row per physics tick); the sample objects ``imu``,
    ``attitude``, ``truth`` and the geodetic ``gnss`` fixes are built on first access, so an
    in-process consumer that reads the arrays (and ``gnss_ned``) pays for none of them.
    """

    t_us: int  # end of the period
    tick_us: range  # the physics ticks of the period (last = t_us)
    acc_frd_m_s2: np.ndarray  # (n, 3) IMU specific force, noisy
    gyro_frd_rad_s: np.ndarray  # (n, 3) IMU rates, noisy
    q_ned_frd: np.ndarray  # (n, 4) true attitude
    p_ned_m: np.ndarray  # (n, 3) true position
    v_ned_m_s: np.ndarray  # (n, 3) true velocity
    # (gnss bias, latency, clearance) of the latest valid fix: before the period's fix, at the last tick
    gnss_truth: tuple[tuple[np.ndarray, float, float], tuple[np.ndarray, float, float]]
    gnss_ned: list[NedFix]  # released this period (latency elapsed), stamped with validity time
    gnss_arrival_us: list[int]  # arrival tick of each ``gnss_ned`` / ``gnss`` entry
    collided: bool  # within radius_m of a building, or at/below the ground, at the end of the period
    to_fix: Callable[[NedFix], GnssFix]  # the wire form of a released fix (geodetic)
    q_sent_ned_frd: np.ndarray | None = None  # (n, 4) the onboard AHRS estimate; None = the truth is sent
    # the raw receiver's epochs released this period (``receiver.enabled``; each with its arrival tick)
    gnss_raw: tuple[RawObservation, ...] = ()
    # the barometer's (pressure altitude (m), absolute pressure (hPa), temperature (°C)), each (n,), with the
    # IMU samples (``imu.baro``; simvehicle.baro); None: none
    baro: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    @property
    def q_att_ned_frd(self) -> np.ndarray:
        """The attitude the attitude samples carry (AHRS estimate, or the truth without one)."""
        return self.q_ned_frd if self.q_sent_ned_frd is None else self.q_sent_ned_frd

    @cached_property
    def imu(self) -> list[ImuSample]:
        acc, gyro = self.acc_frd_m_s2, self.gyro_frd_rad_s
        if self.baro is not None:
            alt = self.baro[0].tolist()
            return [ImuSample(t, acc[i], gyro[i], alt[i]) for i, t in enumerate(self.tick_us)]
        return [ImuSample(t, acc[i], gyro[i]) for i, t in enumerate(self.tick_us)]

    @cached_property
    def attitude(self) -> list[AttitudeSample]:
        q = self.q_att_ned_frd
        return [AttitudeSample(t, q[i]) for i, t in enumerate(self.tick_us)]

    @cached_property
    def truth(self) -> list[TruthState]:
        """One per IMU sample; each carries the bias/latency/clearance of the latest fix valid at it."""
        return [self.truth_at(i) for i in range(len(self.tick_us))]

    @property
    def final_truth(self) -> TruthState:
        """``truth[-1]`` without building the others."""
        return self.truth_at(len(self.tick_us) - 1)

    def truth_at(self, i: int) -> TruthState:
        bias, latency_s, clearance_m = self.gnss_truth[i == len(self.tick_us) - 1]
        return TruthState(self.tick_us[i], self.p_ned_m[i], self.v_ned_m_s[i], self.q_ned_frd[i],
                          gnss_bias_ned_m=bias, gnss_latency_s=latency_s, clearance_m=clearance_m)

    @cached_property
    def gnss(self) -> list[GnssFix]:
        return [self.to_fix(f) for f in self.gnss_ned]


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
        # children 0 and 1 are the paper's streams (spawning more leaves them as they were)
        # child 4 is the eq. 22-27 receiver velocity's, 5 the raw receiver's, 6 the barometer's
        seqs = np.random.SeedSequence(seed).spawn(7)
        imu_seq, gnss_seq, ahrs_seq, nlos_seq, velocity_seq, raw_seq = seqs[:6]
        self.body = RigidBody(cfg.vehicle, self.start_ned_m)
        self.autopilot = Autopilot(cfg.autopilot, cfg.vehicle, self.start_ned_m)
        self.imu = Imu(cfg.imu, np.random.default_rng(imu_seq), cfg.vehicle.physics_rate_hz)
        self.baro = (Barometer(cfg.imu, np.random.default_rng(seqs[6]), cfg.vehicle.physics_rate_hz,
                               float(mission.frame.home_alt_m)) if cfg.imu.baro else None)
        self.ahrs = (Ahrs(cfg.ahrs, cfg.vehicle.physics_rate_hz, np.array(self.body.x[6:10]),
                          np.random.default_rng(ahrs_seq)) if cfg.ahrs.enabled else None)
        self._clearance_m = self._clearance(self.start_ned_m)
        period_s = 1.0 / cfg.vehicle.control_rate_hz
        gnss_rng = np.random.default_rng(gnss_seq)
        unmodelled = None
        if cfg.gnss.unmodelled:
            heights = np.array([b.height_m for b in mission.world.config.buildings], dtype=float)
            nlos_rng = np.random.default_rng(nlos_seq)
            unmodelled = UnmodelledGnss(cfg.gnss, mission.world.rects_m, heights, nlos_rng)
        self.gnss: GnssModel | RawGnssModel
        if cfg.receiver.enabled:
            heights = np.array([b.height_m for b in mission.world.config.buildings], dtype=float)
            self.gnss = RawGnssModel(cfg.receiver, mission.world.rects_m, heights, mission.frame,
                                     np.random.default_rng(raw_seq), round(period_s * 1e6))
        else:
            self.gnss = GnssModel(cfg.gnss, period_s, mission.frame, gnss_rng, self._clearance_m, unmodelled,
                                  np.random.default_rng(velocity_seq))
        self._raw = self.gnss if isinstance(self.gnss, RawGnssModel) else None
        self.t_us = 0
        self._dt_us = cfg.vehicle.physics_dt_us
        self._dt_s = self._dt_us * 1e-6
        self._steps = cfg.vehicle.steps_per_control

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
        t0, dt_s, dt_us, veh = self.t_us, self._dt_s, self._dt_us, self.config.vehicle
        inner, step = ap.inner, body.step
        flat: list[float] = []
        fixes: list[NedFix] = []
        arrivals: list[int] = []
        next_release_us = gnss.next_release_us
        t = t0
        for _ in range(self._steps):
            thrust, tx, ty, tz = inner(body.x)
            step(dt_s, thrust, tx, ty, tz)
            t += dt_us
            x = body.x
            flat += specific_force_frd(veh, thrust, x)
            flat += x
            if t >= next_release_us:
                for fix in gnss.release(t):
                    fixes.append(fix)
                    arrivals.append(t)
                next_release_us = gnss.next_release_us
        self.t_us = t

        block = np.array(flat).reshape(self._steps, _BLOCK_COLUMNS)
        p, v, q, omega = block[:, 3:6], block[:, 6:9], block[:, 9:13], block[:, 13:16]
        acc, gyro = self.imu.measure(block[:, 0:3], omega)
        ap.imu_period(q, acc)
        baro = None if self.baro is None else self.baro.measure(
            np.arange(t0 + dt_us, t + 1, dt_us) * 1e-6, -p[:, 2])

        # one GNSS fix per period, valid at its end; truth carries the bias of the latest valid fix
        before = (gnss.bias_ned_m, gnss.latency_s, self._clearance_m)
        self._clearance_m = self._clearance(p[-1])
        gnss.sample(t, p[-1], self._clearance_m, v[-1])
        for fix in gnss.release(t):
            fixes.append(fix)
            arrivals.append(t)
        after = (gnss.bias_ned_m, gnss.latency_s, self._clearance_m)
        q_sent = None
        if self.ahrs is not None:  # the autopilot's attitude: its receiver's fixes as they arrived
            received = [((a - t0) // dt_us - 1, f.v_ned_m_s, f.satellites)
                        for f, a in zip(fixes, arrivals, strict=True)]
            q_sent = self.ahrs.update(acc, gyro, q, received)
        collided = self._clearance_m < veh.radius_m or p[-1, 2] >= 0.0
        raw = () if self._raw is None else tuple(self._raw.drain_raw())
        return StepOutput(
            t, range(t0 + dt_us, t + 1, dt_us), acc, gyro, q, p, v, (before, after),
            fixes, arrivals, bool(collided), gnss.to_fix, q_sent, raw, baro,
        )
