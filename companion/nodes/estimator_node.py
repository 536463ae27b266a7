"""The companion estimator process: MAVLink samples in, ODOMETRY and belief out.

Samples are pushed into the :class:`Navigator` in arrival order. Outputs are scheduled on the
estimate's own clock (boot time of the last IMU sample), so they are the same in lockstep and
in real time: ODOMETRY at 50 Hz and right after every GNSS fix, ESTIMATOR_STATUS at 5 Hz,
NAMED_VALUE_FLOAT ``GNSS_BETA``/``GNSS_NIS`` at 20 Hz. With ``step_markers`` (set only by
``beliefnav sitl``, whose vehicle ends each step with a TIMESYNC request) a request is a step
marker, answered with ODOMETRY for that time, then the TIMESYNC response; without it a TIMESYNC
request is answered as the MAVLink spec says and nothing else happens. A restarted process starts a fresh
Navigator, which initialises again from the next good GNSS fix.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from companion.autopilot.timesync import answer as timesync_answer
from companion.domain.samples import GnssFix, ImuSample, NavEstimate
from companion.estimator import Navigator, mission_estimator_config
from companion.mavlink import codec as codec
from companion.mavlink.lockstep import marker_time_us, step_response
from companion.mavlink.udp_link import UdpLink
from companion.mission import Mission
from companion.telemetry.pubsub import DeferredPublisher, EstimatorTelemetry, TelemetryPublisher

ESTIMATOR_COMPONENT_ID = 197  # MAV_COMP_ID_VISUAL_INERTIAL_ODOMETRY
IGNORED_TYPES = frozenset({"HEARTBEAT", "SIM_STATE", "SYSTEM_TIME", "TIMESYNC"})
MAX_LATENCY_SAMPLES = 200_000



@dataclass(frozen=True, slots=True)
class OutputRates:
    odometry_period_us: int = 20_000  # ODOMETRY, 50 Hz
    belief_period_us: int = 50_000  # NAMED_VALUE_FLOAT GNSS_BETA / GNSS_NIS, 20 Hz
    status_period_us: int = 200_000  # ESTIMATOR_STATUS, 5 Hz
    heartbeat_period_s: float = 1.0  # HEARTBEAT, wall clock


@dataclass(slots=True)
class _Due:
    """Next boot time at which each periodic output is due."""

    odometry_us: int = 0
    belief_us: int = 0
    status_us: int = 0


@dataclass(slots=True)
class EstimatorNode:
    link: UdpLink
    navigator: Navigator
    nis_gate: float
    telemetry: TelemetryPublisher = field(default_factory=TelemetryPublisher.disabled)
    rates: OutputRates = field(default_factory=OutputRates)
    counters: dict[str, int] = field(default_factory=dict)
    gnss_to_odometry_ns: list[int] = field(default_factory=list)
    step_markers: bool = False  # TIMESYNC requests are beliefnav sitl's step markers
    _due: _Due = field(default_factory=_Due)
    _topics: EstimatorTelemetry = field(init=False)
    _deferred: DeferredPublisher = field(init=False)

    def __post_init__(self) -> None:
        self._deferred = DeferredPublisher(self.telemetry)  # published once a datagram is answered
        self._topics = EstimatorTelemetry(self._deferred)  # Zenoh: estimate, belief, health

    def publish_telemetry(self) -> None:
        """Publish the telemetry queued while handling (call after the answer has left)."""
        self._deferred.drain()

    def _count(self, name: str) -> None:
        self.counters[name] = self.counters.get(name, 0) + 1

    def handle(self, msg: Any) -> None:
        kind = msg.get_type()
        if kind == "TIMESYNC":
            t_marker = marker_time_us(msg)
            if t_marker is not None and self.step_markers:
                self._count("step_markers")
                self._send_odometry()
                self.link.send(step_response(t_marker, time.monotonic_ns()))
            elif msg.tc1 == 0:
                self._count("timesync_answered")
                self.link.send(timesync_answer(msg, time.monotonic_ns()))
            return
        if kind in IGNORED_TYPES:
            return
        try:
            sample = codec.decode_sample(msg)
        except codec.CodecError as exc:
            self._count(f"rejected_{exc.reason}")
            return
        if sample is None:
            self._count("ignored_messages")
            return
        self.navigator.push(sample)
        if isinstance(sample, GnssFix):
            self._send_odometry()
            self.link.flush()  # the ODOMETRY that includes a fix leaves at once
            self.gnss_to_odometry_ns.append(time.perf_counter_ns() - self.link.last_rx_ns)
            self.link.begin_batch()
            if len(self.gnss_to_odometry_ns) > MAX_LATENCY_SAMPLES:
                del self.gnss_to_odometry_ns[: MAX_LATENCY_SAMPLES // 2]
        elif isinstance(sample, ImuSample):
            self._periodic(sample.t_us)
            self._topics.update(sample.t_us, self.navigator)

    def _periodic(self, t_us: int) -> None:
        due = self._due
        if t_us >= due.odometry_us:
            due.odometry_us = _next_multiple(t_us, self.rates.odometry_period_us)
            self._send_odometry()
        if t_us >= due.belief_us:
            due.belief_us = _next_multiple(t_us, self.rates.belief_period_us)
            estimate = self.navigator.estimate()
            if estimate is not None:
                for msg in codec.encode_belief(estimate):
                    self.link.send(msg)
        if t_us >= due.status_us:
            due.status_us = _next_multiple(t_us, self.rates.status_period_us)
            estimate = self.navigator.estimate()
            if estimate is not None:
                self.link.send(codec.encode_estimator_status(estimate, self.nis_gate))

    def _send_odometry(self) -> NavEstimate | None:
        estimate = self.navigator.estimate()
        if estimate is not None:
            self.link.send(codec.encode_odometry(estimate))
        return estimate

    def heartbeat(self) -> None:
        self.link.send(codec.encode_heartbeat("companion"))

    def stats(self) -> dict[str, Any]:
        lat_ms = np.asarray(self.gnss_to_odometry_ns, dtype=float) / 1e6
        latency = (
            {"count": int(lat_ms.size), "p50_ms": float(np.percentile(lat_ms, 50)),
             "p99_ms": float(np.percentile(lat_ms, 99)), "max_ms": float(lat_ms.max())}
            if lat_ms.size else {"count": 0}
        )
        return {
            "link": self.link.counters.as_dict(),
            "node": dict(self.counters),
            "navigator": self.navigator.counters(),
            "telemetry": self.telemetry.counters(),
            "gnss_to_odometry_latency": latency,
        }


def _next_multiple(t_us: int, period_us: int) -> int:
    return (t_us // period_us + 1) * period_us


def make_navigator(mission: Mission, method: str) -> tuple[Navigator, float]:
    """The mission's Navigator (home = the mission's home point) and its χ² NIS gate."""
    config = mission_estimator_config(mission)
    return Navigator(config, method=method, frame=mission.frame), config.chi2_095


def serve(node: EstimatorNode, stop_after_s: float | None = None) -> None:
    """Run until interrupted (SIGTERM/SIGINT end the process through SystemExit/KeyboardInterrupt)."""
    next_heartbeat = 0.0
    start = time.monotonic()
    while stop_after_s is None or time.monotonic() - start < stop_after_s:
        now = time.monotonic()
        if now >= next_heartbeat:
            node.heartbeat()
            next_heartbeat = now + node.rates.heartbeat_period_s
        msgs = node.link.recv(timeout_s=max(next_heartbeat - time.monotonic(), 0.001))
        node.link.begin_batch()  # everything answering one datagram leaves in one datagram
        for msg in msgs:
            node.handle(msg)
        node.link.flush()
        node.publish_telemetry()
