"""Flight driver for PX4: OFFBOARD, arm, climb, then the planned route as setpoints.

Pure state machine, no I/O (``foreign.driver.RouteDriver`` does the route phase). Phases:

``wait``      until EKF2 has a position it can fly on (ESTIMATOR_STATUS: absolute horizontal
              position) and the local frame is placed in the mission frame (``origin_ned_m``);
``offboard``  stream the climb setpoint (the route's start at the mission altitude) for
              ``offboard_warmup_s`` (PX4 enters OFFBOARD only while setpoints arrive), then
              MAV_CMD_DO_SET_MODE (custom, main mode 6) once a second until the HEARTBEAT shows it;
``arm``       MAV_CMD_COMPONENT_ARM_DISARM once a second until armed: PX4 climbs straight to
              the setpoint (no separate take-off command in OFFBOARD); back here if it disarms
              or leaves OFFBOARD;
``climb``     until EKF2's height above the take-off point is within ``takeoff_tolerance_m`` of
              the mission altitude, then hover ``hover_before_route_s``;
``route``     the minimum-jerk reference at ``setpoint_rate_hz`` in PX4's local frame;
``done``      reached (true position within ``goal_radius_m`` of the goal, slower than
              ``goal_speed_m_s``, after the reference arrived) or timed out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from simvehicle.harness.foreign import driver as base
from simvehicle.harness.foreign.driver import Command, DriverInputs, RouteDriver
from simvehicle.harness.px4.config import PX4_MODE_OFFBOARD

MAV_MODE_FLAG_CUSTOM_MODE_ENABLED = 1
SET_OFFBOARD = (base.MAV_CMD_DO_SET_MODE, MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, PX4_MODE_OFFBOARD, 0, 0, 0, 0, 0)
ARM = (base.MAV_CMD_COMPONENT_ARM_DISARM, 1, 0, 0, 0, 0, 0, 0)


def main_mode(custom_mode: int | None) -> int | None:
    """PX4's main mode from HEARTBEAT ``custom_mode`` (``main << 16 | sub << 24``)."""
    return None if custom_mode is None else (int(custom_mode) >> 16) & 0xFF


@dataclass
class OffboardDriver(RouteDriver):
    phase: str = "wait"
    warmup_s: float = 1.0
    _warmup_from_us: int | None = None

    def _climb_point(self) -> np.ndarray:
        p0 = np.array(self.route.reference(0.0)[0], dtype=float)
        p0[2] = -self.altitude_m
        return p0

    def step(self, now: DriverInputs) -> list[Command]:
        t = now.t_us
        if self.phase == "wait":
            if not (now.ekf_position_ok and now.origin_ned_m is not None):
                return []
            self._set("offboard", t)
            self._warmup_from_us, self._last_try_us = t, -base.RETRY_US
        if self.phase == "route":
            return self.follow(now)
        if self.phase == "done":
            return []
        out = self.setpoint(now, self._climb_point())
        offboard = main_mode(now.mode) == PX4_MODE_OFFBOARD
        if self.phase in ("arm", "climb") and not (now.armed and offboard):
            self._set("offboard" if not offboard else "arm", t)  # disarmed, or a failsafe left OFFBOARD
            self._hover_from_us = None
        if self.phase == "offboard":
            if offboard:
                self._set("arm", t)
                self._last_try_us = -base.RETRY_US
            elif t - (self._warmup_from_us or t) >= self.warmup_s * 1e6 and self._retry(t):
                out.append(Command("command_long", SET_OFFBOARD))
        if self.phase == "arm":
            if now.armed:
                self._set("climb", t)
            elif self._retry(t):
                out.append(Command("command_long", ARM))
        if self.phase == "climb" and self.hovered_at_altitude(now):
            self._next_setpoint_us = 0  # the route's first setpoint now
            return self.start_route(now)
        return out
