"""The companion planner-bridge process: plans the route once, then streams its setpoints.

The vehicle's step marker (TIMESYNC request, 20 Hz of boot time) drives the output: the bridge
answers with SET_POSITION_TARGET_LOCAL_NED for that time, then the TIMESYNC response. The same
code serves lockstep and real time; only the vehicle decides whether to wait for the answer.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Any

from companion.mavlink import codec as codec
from companion.mavlink.lockstep import marker_time_us, step_response
from companion.mavlink.udp_link import UdpLink
from companion.mission import Mission
from companion.planning import Route
from companion.telemetry.codec import RouteInfo
from companion.telemetry.pubsub import TelemetryPublisher

BRIDGE_COMPONENT_ID = 191  # MAV_COMP_ID_ONBOARD_COMPUTER
HEARTBEAT_PERIOD_S = 1.0
ROUTE_PERIOD_US = 1_000_000  # bridge/route telemetry, 1 Hz of boot time


def route_info(mission: Mission, profile: int, route: Route) -> RouteInfo:
    """The ``bridge/route`` telemetry message of a planned route (stamped when published)."""
    wp = route.waypoints_ned_m
    return RouteInfo(0, mission.name, profile, wp, route.duration_s, mission.world.rects_m, wp[-1])


@dataclass(slots=True)
class BridgeNode:
    link: UdpLink
    route: Route
    telemetry: TelemetryPublisher = field(default_factory=TelemetryPublisher.disabled)
    route_msg: RouteInfo | None = None  # published every ROUTE_PERIOD_US of boot time
    counters: dict[str, int] = field(default_factory=dict)
    _next_route_us: int = 0

    def handle(self, msg: Any) -> None:
        t_us = marker_time_us(msg)
        if t_us is None:
            return
        self.counters["setpoints"] = self.counters.get("setpoints", 0) + 1
        setpoint = self.route.setpoint(t_us)
        self.link.send(codec.encode_setpoint(setpoint))
        self.link.send(step_response(t_us, time.monotonic_ns()))
        self.telemetry.publish("setpoint", setpoint)
        if self.route_msg is not None and t_us >= self._next_route_us:
            self._next_route_us = t_us + ROUTE_PERIOD_US
            self.telemetry.publish("route", replace(self.route_msg, t_us=t_us))

    def stats(self) -> dict[str, Any]:
        return {"link": self.link.counters.as_dict(), "node": dict(self.counters),
                "route_duration_s": self.route.duration_s, "telemetry": self.telemetry.counters()}


def serve(node: BridgeNode) -> None:
    """Run until interrupted (SIGTERM/SIGINT end the process through SystemExit/KeyboardInterrupt)."""
    next_heartbeat = 0.0
    while True:
        now = time.monotonic()
        if now >= next_heartbeat:
            node.link.send(codec.encode_heartbeat("companion"))
            next_heartbeat = now + HEARTBEAT_PERIOD_S
        msgs = node.link.recv(timeout_s=max(next_heartbeat - time.monotonic(), 0.001))
        node.link.begin_batch()  # everything answering one datagram leaves in one datagram
        for msg in msgs:
            node.handle(msg)
        node.link.flush()
