"""The companion estimator process: MAVLink samples in, ODOMETRY and belief out.

Samples are pushed into the :class:`Navigator` in arrival order. Outputs are scheduled on the
estimate's own clock (boot time of the last IMU sample), so they are the same in lockstep and
in real time: ODOMETRY at 50 Hz and right after every GNSS fix, ESTIMATOR_STATUS at 5 Hz,
NAMED_VALUE_FLOAT ``GNSS_BETA``/``GNSS_NIS`` at 20 Hz. With ``step_markers`` (set only by
``beliefnav sitl``, whose vehicle ends each step with a TIMESYNC request) a request is a step
marker, answered with ODOMETRY for that time, then the TIMESYNC response; without it a TIMESYNC
request is answered as the MAVLink spec says and nothing else happens. ODOMETRY goes out once per
estimate time: a trigger that finds the estimate already sent (e.g. a marker right after the 50 Hz
one) sends nothing new, as the one sent is already ahead of the response on the same socket. A
restarted process starts a fresh Navigator, which initialises again from the next good GNSS fix.

Time cannot be poisoned (:mod:`companion.domain.clock_guard`): the IMU stream is the time base;
a lone IMU stamp outside its window is rejected (``rejected_clock_imu``), a consensus of several
is a real jump (the vehicle rebooted): the Navigator starts afresh (``clock_resets``). Attitude,
fixes and step markers are checked against that base, never adopted. An estimate that is not
finite and plausible is never sent (``unsendable_<reason>``), and a message that still makes the
handler raise is counted (``handler_error_<type>``), never fatal.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from companion.autopilot.timesync import answer as timesync_answer
from companion.domain.clock_guard import ClockWindow, StreamClock, Verdict, within
from companion.domain.geodesy import LocalNedFrame
from companion.domain.samples import AttitudeSample, GnssFix, ImuSample, NavEstimate
from companion.domain.statistics import LATENCY_STATISTICS, describe
from companion.estimator import Navigator
from companion.mavlink import codec as codec
from companion.mavlink.lockstep import marker_time_us, step_response
from companion.mavlink.udp_link import UdpLink
from companion.mission import Mission
from companion.runtime import count_handler_error, write_json
from companion.telemetry.pubsub import (
    DeferredPublisher,
    EstimatorRates,
    EstimatorTelemetry,
    TelemetryPublisher,
)

IGNORED_TYPES = frozenset({"HEARTBEAT", "SIM_STATE", "SYSTEM_TIME", "TIMESYNC"})
MAX_LATENCY_SAMPLES = 200_000



@dataclass(frozen=True, slots=True)
class OutputRates:
    """MAVLink output periods: those of the estimator's Zenoh topics (``EstimatorRates``, written once)."""

    odometry_period_us: int = EstimatorRates.estimate_period_us  # ODOMETRY, 50 Hz
    belief_period_us: int = EstimatorRates.belief_period_us  # NAMED_VALUE_FLOAT GNSS_BETA / GNSS_NIS, 20 Hz
    status_period_us: int = EstimatorRates.health_period_us  # ESTIMATOR_STATUS, 5 Hz
    bias_period_us: int = EstimatorRates.health_period_us  # DEBUG_VECT GNSS_BIAS (vehicle's record), 5 Hz
    heartbeat_period_s: float = 1.0  # HEARTBEAT, wall clock


@dataclass(frozen=True, slots=True)
class ClockWindows:
    """How far each input may stray from the IMU time base (µs of the vehicle's boot clock)."""

    imu: ClockWindow = ClockWindow(max_back_us=200_000, max_forward_us=2_000_000)
    attitude: ClockWindow = ClockWindow(max_back_us=1_000_000, max_forward_us=1_000_000)
    gnss: ClockWindow = ClockWindow(max_back_us=5_000_000, max_forward_us=500_000)  # latency <= 1.2 s
    marker: ClockWindow = ClockWindow(max_back_us=5_000_000, max_forward_us=1_000_000)


@dataclass(slots=True)
class _Due:
    """Next boot time at which each periodic output is due."""

    odometry_us: int = 0
    belief_us: int = 0
    status_us: int = 0
    bias_us: int = 0


@dataclass(slots=True)
class EstimatorNode:
    link: UdpLink
    navigator: Navigator
    nis_gate: float
    telemetry: TelemetryPublisher = field(default_factory=TelemetryPublisher.disabled)
    rates: OutputRates = field(default_factory=OutputRates)
    new_navigator: Callable[[], Navigator] | None = None  # a fresh Navigator after a clock reset
    home: LocalNedFrame | None = None  # fixes farther than codec.LIMITS allow from it are rejected
    windows: ClockWindows = field(default_factory=ClockWindows)
    counters: dict[str, int] = field(default_factory=dict)
    gnss_to_odometry_ns: list[int] = field(default_factory=list)
    step_markers: bool = False  # TIMESYNC requests are beliefnav sitl's step markers
    _due: _Due = field(default_factory=_Due)
    _odometry_sent_t_us: int = -1  # estimate time of the last ODOMETRY sent (one per estimate time)
    _topics: EstimatorTelemetry = field(init=False)
    _deferred: DeferredPublisher = field(init=False)
    _clock: StreamClock = field(init=False)
    _retired: dict[str, int] = field(default_factory=dict)  # counters of Navigators reset away

    def __post_init__(self) -> None:
        self._clock = StreamClock(self.windows.imu)
        self._deferred = DeferredPublisher(self.telemetry)  # published once a datagram is answered
        self._topics = EstimatorTelemetry(self._deferred)  # Zenoh: estimate, belief, health

    def telemetry_ended(self) -> None:
        """On a clean stop: what is queued, then the last ``health`` (status ``ended``)."""
        self._topics.finish(self.navigator)
        self._deferred.drain()

    def publish_telemetry(self) -> None:
        """Publish the telemetry queued while handling (call after the answer has left)."""
        self._deferred.drain()

    def _count(self, name: str) -> None:
        self.counters[name] = self.counters.get(name, 0) + 1

    def handle(self, msg: Any) -> None:
        """Handle one message; whatever it holds, count it and never raise."""
        try:
            self._handle(msg)
        except Exception as exc:  # noqa: BLE001 - a frame must never end the process
            count_handler_error(self.counters, "estimator", msg, exc)

    def _in_window(self, t_us: int, window: ClockWindow) -> bool:
        base = self._clock.base_us
        return base is not None and within(t_us, base, window)

    def _handle(self, msg: Any) -> None:
        kind = msg.get_type()
        if kind == "TIMESYNC":
            t_marker = marker_time_us(msg)
            if t_marker is not None and self.step_markers:
                if self._clock.base_us is not None and not self._in_window(t_marker, self.windows.marker):
                    self._count("rejected_clock_marker")
                    return
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
            sample = codec.decode_sample(msg, self.home)
        except codec.CodecError as exc:
            self._count(f"rejected_{exc.reason}")
            return
        if sample is None:
            self._count("ignored_messages")
            return
        if not self._clock_ok(sample):
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

    def _clock_ok(self, sample: ImuSample | AttitudeSample | GnssFix) -> bool:
        """The clock guard: IMU sets the time base (consensus resets), the rest must fit it."""
        if isinstance(sample, ImuSample):
            verdict = self._clock.check(sample.t_us)
            if verdict is Verdict.REJECT:
                self._count("rejected_clock_imu")
                return False
            if verdict is Verdict.RESET:
                self._restart_navigator()
            return True
        if isinstance(sample, GnssFix):
            ok, name = self._in_window(sample.t_validity_us, self.windows.gnss), "rejected_clock_gnss"
        else:  # the attitude that precedes the first IMU sample is taken (it rotates that sample)
            ok = self._clock.base_us is None or self._in_window(sample.t_us, self.windows.attitude)
            name = "rejected_clock_attitude"
        if not ok:
            self._count(name)
        return ok

    def _restart_navigator(self) -> None:
        """The vehicle's clock jumped (a reboot): start again as a restarted process would."""
        self._count("clock_resets")
        if self.new_navigator is not None:
            for name, n in self.navigator.counters().items():
                self._retired[name] = self._retired.get(name, 0) + n
            self.navigator = self.new_navigator()
        self._due = _Due()
        self._odometry_sent_t_us = -1

    def _sendable(self) -> NavEstimate | None:
        """The current estimate if it may be sent (finite, plausible), else None (counted)."""
        estimate = self.navigator.estimate()
        if estimate is None:
            return None
        try:
            codec.check_sendable(estimate)
        except codec.CodecError as exc:
            self._count(f"unsendable_{exc.reason}")
            return None
        return estimate

    def _periodic(self, t_us: int) -> None:
        due = self._due
        if t_us >= due.odometry_us:
            due.odometry_us = _next_multiple(t_us, self.rates.odometry_period_us)
            self._send_odometry()
        if t_us >= due.belief_us:
            due.belief_us = _next_multiple(t_us, self.rates.belief_period_us)
            estimate = self._sendable()
            if estimate is not None:
                for msg in codec.encode_belief(estimate):
                    self.link.send(msg)
        if t_us >= due.status_us:
            due.status_us = _next_multiple(t_us, self.rates.status_period_us)
            estimate = self._sendable()
            if estimate is not None:
                self.link.send(codec.encode_estimator_status(estimate))
        if t_us >= due.bias_us:
            due.bias_us = _next_multiple(t_us, self.rates.bias_period_us)
            estimate = self._sendable()
            if estimate is not None and np.isfinite(estimate.b_ned_m).all():
                self.link.send(codec.encode_bias(estimate))

    def _send_odometry(self) -> NavEstimate | None:
        estimate = self._sendable()
        if estimate is not None and estimate.t_us != self._odometry_sent_t_us:
            self._odometry_sent_t_us = estimate.t_us
            self.link.send(codec.encode_odometry(estimate))
        return estimate

    def heartbeat(self) -> None:
        self.link.send(codec.encode_heartbeat("companion"))

    def navigator_counters(self) -> dict[str, int]:
        """The Navigator's counters over the whole run (those of Navigators reset away included)."""
        total = dict(self._retired)
        for name, n in self.navigator.counters().items():
            total[name] = total.get(name, 0) + n
        return total

    def stats(self) -> dict[str, Any]:
        lat_ms = np.asarray(self.gnss_to_odometry_ns, dtype=float) / 1e6
        return {
            "link": self.link.counters.as_dict(),
            "node": dict(self.counters),
            "navigator": self.navigator_counters(),
            "telemetry": self.telemetry.counters(),
            "gnss_to_odometry_latency_ms": describe(lat_ms, LATENCY_STATISTICS),
        }


def _next_multiple(t_us: int, period_us: int) -> int:
    return (t_us // period_us + 1) * period_us


def make_navigator(mission: Mission, method: str) -> tuple[Navigator, float]:
    """The mission's Navigator (home = the mission's home point) and its χ² NIS gate."""
    from companion.wiring import navigator_for

    nav = navigator_for(mission, method)
    return nav, nav.cfg.chi2_095


def serve(node: EstimatorNode, stop_after_s: float | None = None, stats_path: Path | None = None) -> None:
    """Run until interrupted (SIGTERM/SIGINT end the process through SystemExit/KeyboardInterrupt).
    With ``stats_path`` the counters are written there with every heartbeat (a ``kill -9`` loses
    at most one heartbeat period of them)."""
    next_heartbeat = 0.0
    start = time.monotonic()
    while stop_after_s is None or time.monotonic() - start < stop_after_s:
        now = time.monotonic()
        if now >= next_heartbeat:
            node.heartbeat()
            if stats_path is not None:
                write_json(stats_path, node.stats())
            next_heartbeat = now + node.rates.heartbeat_period_s
        msgs = node.link.recv(timeout_s=max(next_heartbeat - time.monotonic(), 0.001))
        node.link.begin_batch()  # everything answering one datagram leaves in one datagram
        for msg in msgs:
            node.handle(msg)
        node.link.flush()
        node.publish_telemetry()
