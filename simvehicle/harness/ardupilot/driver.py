"""Flight driver for ArduCopter: GUIDED, arm, take off, then the planned route as setpoints.

Pure state machine, no I/O: ``step(now)`` takes what the session knows at ArduPilot time
``now.t_us`` and returns the commands to send (``Command`` tuples the session encodes). Phases:

``guided``   once EKF_STATUS_REPORT shows an absolute horizontal position (EKF3 uses the GNSS),
             ask for GUIDED (custom mode 4) once a second until the HEARTBEAT shows it (GUIDED
             entered before that, at boot, accepts the mode but then refuses every take-off);
``arm``      MAV_CMD_COMPONENT_ARM_DISARM once a second until armed (back here if it disarms);
``takeoff``  MAV_CMD_NAV_TAKEOFF to the mission altitude, until EKF3's height is within
             ``takeoff_tolerance_m`` of it, then hover ``hover_before_route_s``;
``route``    SET_POSITION_TARGET_LOCAL_NED of the minimum-jerk reference at ``setpoint_rate_hz``,
             in ArduPilot's local frame (EKF origin): mission NED minus the origin's mission NED;
``done``     reached (TRUE position within ``goal_radius_m`` of the goal, slower than
             ``goal_speed_m_s``, after the reference arrived: as ``fly``) or timed out.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from companion.planning import Route
from simvehicle.harness.ardupilot.config import ArduPilotConfig
from simvehicle.recording import Goal

COPTER_MODE_GUIDED = 4
MAV_CMD_NAV_TAKEOFF = 22
MAV_CMD_DO_SET_MODE = 176
MAV_CMD_COMPONENT_ARM_DISARM = 400
RETRY_US = 1_000_000


@dataclass(frozen=True, slots=True)
class Command:
    kind: str  # "command_long" or "setpoint"
    args: tuple[Any, ...]


@dataclass
class DriverInputs:
    """What the session knows now (ArduPilot boot time)."""

    t_us: int
    mode: int | None = None  # HEARTBEAT custom_mode
    armed: bool = False
    takeoff_accepted: bool = False  # MAV_CMD_NAV_TAKEOFF ACCEPTED since the last arming
    ekf_position_ok: bool = False  # EKF_STATUS_REPORT: absolute horizontal position, not const-pos mode
    origin_ned_m: np.ndarray | None = None  # EKF origin in the mission frame (GPS_GLOBAL_ORIGIN)
    ekf_ned_m: np.ndarray | None = None  # EKF3's position in the mission frame
    # EKF3's height above home (GLOBAL_POSITION_INT.relative_alt): the take-off check. Its AMSL
    # height carries the vertical error of the fix that set the EKF origin, which in a canyon can
    # exceed the take-off tolerance for the whole flight.
    ekf_height_m: float | None = None
    truth_ned_m: np.ndarray | None = None
    truth_v_ned_m_s: np.ndarray | None = None


@dataclass
class FlightDriver:
    cfg: ArduPilotConfig
    route: Route  # planned with t_start_s = 0: its clock starts when the route phase does
    altitude_m: float
    phase: str = "guided"
    outcome: str = ""
    route_t0_us: int | None = None
    phase_times_us: dict[str, int] = field(default_factory=dict)
    _last_try_us: int = -RETRY_US
    _hover_from_us: int | None = None
    _next_setpoint_us: int = 0

    def _set(self, phase: str, t_us: int) -> None:
        self.phase = phase
        self.phase_times_us[phase] = t_us

    def _retry(self, t_us: int) -> bool:
        if t_us - self._last_try_us >= RETRY_US:
            self._last_try_us = t_us
            return True
        return False

    @property
    def route_end_us(self) -> float:
        if self.route_t0_us is None:
            return float("inf")
        d = self.route.duration_s
        return self.route_t0_us + 1e6 * (d + max(self.cfg.timeout_margin_s, 0.5 * d))

    def route_time_s(self, t_us: int) -> float:
        return (t_us - (self.route_t0_us or 0)) * 1e-6

    def step(self, now: DriverInputs) -> list[Command]:
        t = now.t_us
        if self.phase == "guided":
            if now.mode == COPTER_MODE_GUIDED:
                self._set("arm", t)
                self._last_try_us = -RETRY_US
            elif now.ekf_position_ok and self._retry(t):
                return [Command("command_long", (MAV_CMD_DO_SET_MODE, 1, COPTER_MODE_GUIDED, 0, 0, 0, 0, 0))]
        if self.phase == "arm":
            if now.armed:
                self._set("takeoff", t)
                self._last_try_us = -RETRY_US
            elif now.ekf_position_ok and self._retry(t):
                return [Command("command_long", (MAV_CMD_COMPONENT_ARM_DISARM, 1, 0, 0, 0, 0, 0, 0))]
        if self.phase == "takeoff":
            return self._takeoff(now)
        if self.phase == "route":
            return self._route(now)
        return []

    def _takeoff(self, now: DriverInputs) -> list[Command]:
        t = now.t_us
        if not now.armed:  # refused take-off: ArduPilot disarms after a while on the ground
            self._set("arm", t)
            self._hover_from_us = None
            return []
        tol_m, hover_us = self.cfg.takeoff_tolerance_m, self.cfg.hover_before_route_s * 1e6
        if now.ekf_height_m is not None and abs(now.ekf_height_m - self.altitude_m) <= tol_m:
            if self._hover_from_us is None:
                self._hover_from_us = t
            if t - self._hover_from_us >= hover_us and now.origin_ned_m is not None:
                self._set("route", t)
                self.route_t0_us = t
                return self._route(now)
            return []
        if not now.takeoff_accepted and self._retry(t):
            return [Command("command_long", (MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, self.altitude_m))]
        return []

    def _route(self, now: DriverInputs) -> list[Command]:
        t = now.t_us
        rt = self.route_time_s(t)
        goal = Goal(self.route.waypoints_ned_m[-1], self.cfg.goal_radius_m, self.cfg.goal_speed_m_s,
                    arrive_after_s=self.route.duration_s)  # on the route's clock
        if (now.truth_ned_m is not None and now.truth_v_ned_m_s is not None
                and goal.reached(rt, now.truth_ned_m, now.truth_v_ned_m_s)):
            self._set("done", t)
            self.outcome = "reached_goal"
            return []
        if t >= self.route_end_us:
            self._set("done", t)
            self.outcome = "timeout"
            return []
        if t < self._next_setpoint_us or now.origin_ned_m is None:
            return []
        self._next_setpoint_us = t + round(1e6 / self.cfg.setpoint_rate_hz)
        p, v, a = self.route.reference(rt)
        o = now.origin_ned_m
        return [Command("setpoint", (t // 1000, *(np.asarray(p) - o).tolist(), *np.asarray(v).tolist(),
                                     *np.asarray(a).tolist()))]
