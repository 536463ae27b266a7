"""The companion planner-bridge process: plans the route once, then streams its setpoints.

The vehicle's step marker (TIMESYNC request, 20 Hz of boot time) drives the output: the bridge
answers with SET_POSITION_TARGET_LOCAL_NED for that time, then the TIMESYNC response. The same
code serves lockstep and real time; only the vehicle decides whether to wait for the answer.
Markers are clock-guarded (:mod:`companion.domain.clock_guard`): a lone marker far from the
vehicle's time base is not answered (``rejected_clock_marker``); a consensus of several is a
vehicle reboot (``clock_resets``). A setpoint that cannot be sent is counted, never raised.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from companion.domain.clock_guard import ClockWindow, StreamClock, Verdict
from companion.mavlink import codec as codec
from companion.mavlink.lockstep import marker_time_us, step_response
from companion.mavlink.udp_link import UdpLink
from companion.mission import Mission
from companion.planning import Route
from companion.runtime import count_handler_error, write_json
from companion.telemetry.codec import RouteInfo
from companion.telemetry.pubsub import TelemetryPublisher

HEARTBEAT_PERIOD_S = 1.0
ROUTE_PERIOD_US = 1_000_000  # bridge/route telemetry, 1 Hz of boot time
MARKER_WINDOW = ClockWindow(max_back_us=5_000_000, max_forward_us=2_000_000)  # around the last marker


def route_info(mission: Mission, profile: int, route: Route) -> RouteInfo:
    """The ``bridge/route`` telemetry message of a planned route (stamped when published)."""
    wp = route.waypoints_ned_m
    f = mission.frame
    return RouteInfo(0, mission.name, profile, wp, route.duration_s, mission.world.rects_m, wp[-1],
                     np.array([f.home_lat_deg, f.home_lon_deg, f.home_alt_m]))


@dataclass(slots=True)
class BridgeNode:
    link: UdpLink
    route: Route
    telemetry: TelemetryPublisher = field(default_factory=TelemetryPublisher.disabled)
    route_msg: RouteInfo | None = None  # published every ROUTE_PERIOD_US of boot time
    counters: dict[str, int] = field(default_factory=dict)
    clock: StreamClock = field(default_factory=lambda: StreamClock(MARKER_WINDOW))
    _next_route_us: int = 0

    def _count(self, name: str) -> None:
        self.counters[name] = self.counters.get(name, 0) + 1

    def handle(self, msg: Any) -> None:
        """Answer a step marker; whatever a message holds, count it and never raise."""
        try:
            self._handle(msg)
        except Exception as exc:  # noqa: BLE001 - a frame must never end the process
            count_handler_error(self.counters, "bridge", msg, exc)

    def _handle(self, msg: Any) -> None:
        t_us = marker_time_us(msg)
        if t_us is None:
            return
        verdict = self.clock.check(t_us)
        if verdict is Verdict.REJECT:
            self._count("rejected_clock_marker")
            return
        if verdict is Verdict.RESET:
            self._count("clock_resets")
            self._next_route_us = 0
        setpoint = self.route.setpoint(t_us)
        try:
            self.link.send(codec.encode_setpoint(setpoint))
            self._count("setpoints")
        except codec.CodecError as exc:  # answered without one: the vehicle keeps its last setpoint
            self._count(f"unsendable_{exc.reason}")
        self.link.send(step_response(t_us, time.monotonic_ns()))
        self.telemetry.publish("setpoint", setpoint)
        if self.route_msg is not None and t_us >= self._next_route_us:
            self._next_route_us = t_us + ROUTE_PERIOD_US
            self.telemetry.publish("route", replace(self.route_msg, t_us=t_us))

    def stats(self) -> dict[str, Any]:
        return {"link": self.link.counters.as_dict(), "node": dict(self.counters),
                "route_duration_s": self.route.duration_s, "telemetry": self.telemetry.counters()}


def serve(node: BridgeNode, stats_path: Path | None = None) -> None:
    """Run until interrupted (SIGTERM/SIGINT end the process through SystemExit/KeyboardInterrupt).
    With ``stats_path`` the counters are written there with every heartbeat (1 s)."""
    next_heartbeat = 0.0
    while True:
        now = time.monotonic()
        if now >= next_heartbeat:
            node.link.send(codec.encode_heartbeat("companion"))
            if stats_path is not None:
                write_json(stats_path, node.stats())
            next_heartbeat = now + HEARTBEAT_PERIOD_S
        msgs = node.link.recv(timeout_s=max(next_heartbeat - time.monotonic(), 0.001))
        node.link.begin_batch()  # everything answering one datagram leaves in one datagram
        for msg in msgs:
            node.handle(msg)
        node.link.flush()
