"""The route phase every foreign-autopilot flight shares: setpoints of the planned route, goal, time-out.

Pure state machine, no I/O. A vehicle's driver (``ardupilot.driver.FlightDriver``: GUIDED, arm,
take-off; ``px4.driver.OffboardDriver``: OFFBOARD, arm, climb) subclasses :class:`RouteDriver`,
brings the vehicle to the route's start at the mission altitude and calls :meth:`start_route`;
from then on :meth:`RouteDriver.follow` sends SET_POSITION_TARGET_LOCAL_NED of the minimum-jerk
reference at ``setpoint_rate_hz`` in the autopilot's local frame (mission NED minus
``DriverInputs.origin_ned_m``, the local frame's origin in the mission frame) and ends the flight:

``done``     reached (TRUE position within ``goal_radius_m`` of the goal, slower than
             ``goal_speed_m_s``, after the reference arrived: as ``fly``) or timed out
             (``route duration + max(timeout_margin_s, 50 %)``).

``step(now)`` takes what the session knows at the autopilot's time ``now.t_us`` and returns the
commands to send (``Command`` tuples the session encodes).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from companion.planning import Route
from simvehicle.harness.foreign.config import ForeignFlightConfig
from simvehicle.recording import Goal

RETRY_US = 1_000_000
MAV_CMD_DO_SET_MODE = 176
MAV_CMD_COMPONENT_ARM_DISARM = 400


@dataclass(frozen=True, slots=True)
class Command:
    kind: str  # "command_long" or "setpoint"
    args: tuple[Any, ...]


@dataclass
class DriverInputs:
    """What the session knows now (the autopilot's boot time)."""

    t_us: int
    mode: int | None = None  # HEARTBEAT custom_mode
    armed: bool = False
    takeoff_accepted: bool = False  # MAV_CMD_NAV_TAKEOFF ACCEPTED since the last arming (ArduPilot)
    ekf_position_ok: bool = False  # the autopilot's EKF has a position it can fly on
    origin_ned_m: np.ndarray | None = None  # the autopilot's local frame origin in the mission frame
    ekf_ned_m: np.ndarray | None = None  # the EKF's position in the mission frame
    # the EKF's height above home (GLOBAL_POSITION_INT.relative_alt): the take-off check. Its AMSL
    # height carries the vertical error of the fix that set the EKF origin, which in a canyon can
    # exceed the take-off tolerance for the whole flight.
    ekf_height_m: float | None = None
    truth_ned_m: np.ndarray | None = None
    truth_v_ned_m_s: np.ndarray | None = None


@dataclass
class RouteDriver:
    cfg: ForeignFlightConfig
    route: Route  # planned with t_start_s = 0: its clock starts when the route phase does
    altitude_m: float
    phase: str = ""
    outcome: str = ""
    route_t0_us: int | None = None
    phase_times_us: dict[str, int] = field(default_factory=dict)
    _last_try_us: int = -RETRY_US
    _hover_from_us: int | None = None
    _next_setpoint_us: int = 0

    def step(self, now: DriverInputs) -> list[Command]:  # pragma: no cover - each vehicle's
        raise NotImplementedError

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

    def hovered_at_altitude(self, now: DriverInputs) -> bool:
        """At the mission altitude (EKF height within the tolerance) for ``hover_before_route_s``;
        False (the hover clock restarted) while outside."""
        if now.ekf_height_m is None or abs(now.ekf_height_m - self.altitude_m) > self.cfg.takeoff_tolerance_m:
            self._hover_from_us = None
            return False
        if self._hover_from_us is None:
            self._hover_from_us = now.t_us
        return now.t_us - self._hover_from_us >= self.cfg.hover_before_route_s * 1e6

    def start_route(self, now: DriverInputs) -> list[Command]:
        self._set("route", now.t_us)
        self.route_t0_us = now.t_us
        return self.follow(now)

    def follow(self, now: DriverInputs) -> list[Command]:
        """The route phase: the reference as setpoints until the goal is reached or time is up."""
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
        p, v, a = self.route.reference(rt)
        return self.setpoint(now, np.asarray(p), np.asarray(v), np.asarray(a))

    def setpoint(self, now: DriverInputs, p_ned_m: np.ndarray, v_ned_m_s: np.ndarray | None = None,
                 a_ned_m_s2: np.ndarray | None = None) -> list[Command]:
        """A mission-frame setpoint in the autopilot's local frame, at most at ``setpoint_rate_hz``."""
        t = now.t_us
        if t < self._next_setpoint_us or now.origin_ned_m is None:
            return []
        self._next_setpoint_us = t + round(1e6 / self.cfg.setpoint_rate_hz)
        zero = np.zeros(3)
        v = zero if v_ned_m_s is None else v_ned_m_s
        a = zero if a_ned_m_s2 is None else a_ned_m_s2
        return [Command("setpoint", (t // 1000, *(p_ned_m - now.origin_ned_m).tolist(), *v.tolist(),
                                     *a.tolist()))]
