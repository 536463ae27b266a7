"""Flight driver for ArduCopter: GUIDED, arm, take off, then the planned route as setpoints.

Pure state machine, no I/O (``foreign.driver.RouteDriver`` does the route phase). Phases:

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

from dataclasses import dataclass

from simvehicle.harness.foreign.driver import (
    MAV_CMD_COMPONENT_ARM_DISARM,
    MAV_CMD_DO_SET_MODE,
    RETRY_US,
    Command,
    DriverInputs,
    RouteDriver,
)

COPTER_MODE_GUIDED = 4
MAV_CMD_NAV_TAKEOFF = 22
__all__ = ["COPTER_MODE_GUIDED", "MAV_CMD_COMPONENT_ARM_DISARM", "MAV_CMD_DO_SET_MODE", "MAV_CMD_NAV_TAKEOFF",
           "Command", "DriverInputs", "FlightDriver"]


@dataclass
class FlightDriver(RouteDriver):
    phase: str = "guided"

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
            return self.follow(now)
        return []

    def _takeoff(self, now: DriverInputs) -> list[Command]:
        t = now.t_us
        if not now.armed:  # refused take-off: ArduPilot disarms after a while on the ground
            self._set("arm", t)
            self._hover_from_us = None
            return []
        if self.hovered_at_altitude(now):
            return self.start_route(now) if now.origin_ned_m is not None else []
        at_altitude = self._hover_from_us is not None
        if not at_altitude and not now.takeoff_accepted and self._retry(t):
            return [Command("command_long", (MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, self.altitude_m))]
        return []
