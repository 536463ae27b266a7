"""Zenoh edge: telemetry sessions, a publisher that never blocks its caller, and a decoding subscriber.

Topology (no router needed): every process is a Zenoh *peer* with multicast scouting off. The
first process on the host binds the hub endpoint (``tcp/127.0.0.1:7447`` by default) and the
others connect to it; gossip then tells each peer the others' (loopback, random-port) listeners
and they link directly, so the mesh survives the hub's exit and a later process becomes the new
hub. ``TelemetryConfig.connect`` adds a router or mesh peers (multi-host), and a full Zenoh JSON5
file (``zenoh_config_file``) replaces all of this.

Environment (read by ``TelemetryConfig.from_env``, so child processes inherit it):
``BELIEFNAV_ZENOH_HUB`` (endpoint), ``BELIEFNAV_ZENOH_CONNECT`` (comma-separated endpoints),
``BELIEFNAV_ZENOH_CONFIG`` (file), ``BELIEFNAV_TELEMETRY=off`` (publish nothing).
"""

from __future__ import annotations

import argparse
import atexit
import json
import os
import threading
import time
import weakref
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import zenoh

from companion.errors import UserError
from companion.telemetry import codec as zc

DEFAULT_HUB = "tcp/127.0.0.1:7447"


@dataclass(frozen=True)
class TelemetryConfig:
    """How a process joins the telemetry network."""

    hub_endpoint: str = DEFAULT_HUB  # first process on the host listens here, the others connect
    connect: tuple[str, ...] = ()  # extra endpoints to connect to (a router, peers on other hosts)
    mode: str = "peer"  # "peer" (default) or "client" (needs a router in `connect`)
    zenoh_config_file: str = ""  # a Zenoh JSON5 config that replaces everything above
    enabled: bool = True  # False: publishers do nothing (no session is opened)

    @classmethod
    def from_env(cls, env: dict[str, str] | None = None) -> TelemetryConfig:
        env = dict(os.environ if env is None else env)
        return cls(
            hub_endpoint=env.get("BELIEFNAV_ZENOH_HUB", DEFAULT_HUB),
            connect=tuple(e for e in env.get("BELIEFNAV_ZENOH_CONNECT", "").split(",") if e),
            zenoh_config_file=env.get("BELIEFNAV_ZENOH_CONFIG", ""),
            enabled=env.get("BELIEFNAV_TELEMETRY", "on").lower() not in ("off", "0", "false", "no"),
        )


DEFAULT_VEHICLE_ID = "uav1"


def add_arguments(parser: argparse.ArgumentParser, publisher: bool = False) -> None:
    """``--zenoh-hub``, ``--zenoh-connect``, ``--zenoh-config``: defaults come from the environment.

    ``publisher``: also ``--vehicle-id`` (the ``<vehicle>`` key part) and ``--no-telemetry``."""
    g = parser.add_argument_group("telemetry (Zenoh)")
    if publisher:
        g.add_argument("--vehicle-id", default=DEFAULT_VEHICLE_ID,
                       help="vehicle id in the telemetry keys beliefnav/<id>/... (default %(default)s)")
        g.add_argument("--no-telemetry", action="store_true", help="publish no Zenoh telemetry")
    g.add_argument("--zenoh-hub", metavar="ENDPOINT", help=f"local hub endpoint (default {DEFAULT_HUB})")
    g.add_argument("--zenoh-connect", metavar="ENDPOINT", action="append", default=[],
                   help="also connect to this router/peer (repeatable), e.g. tcp/10.0.0.2:7447")
    g.add_argument("--zenoh-config", metavar="FILE", help="Zenoh JSON5 config file (replaces the defaults)")


def config_from_args(args: argparse.Namespace) -> TelemetryConfig:
    cfg = TelemetryConfig.from_env()
    if getattr(args, "zenoh_hub", None):
        cfg = replace(cfg, hub_endpoint=args.zenoh_hub)
    if getattr(args, "zenoh_connect", None):
        cfg = replace(cfg, connect=cfg.connect + tuple(args.zenoh_connect))
    if getattr(args, "zenoh_config", None):
        cfg = replace(cfg, zenoh_config_file=args.zenoh_config)
    if getattr(args, "no_telemetry", False):
        cfg = replace(cfg, enabled=False)
    return cfg


def forward_arguments(args: argparse.Namespace) -> list[str]:
    """The telemetry flags of ``args`` again, for a child process (``beliefnav sitl`` -> its nodes)."""
    out = []
    if getattr(args, "vehicle_id", None):
        out += ["--vehicle-id", args.vehicle_id]
    if getattr(args, "no_telemetry", False):
        out.append("--no-telemetry")
    if getattr(args, "zenoh_hub", None):
        out += ["--zenoh-hub", args.zenoh_hub]
    for endpoint in getattr(args, "zenoh_connect", None) or ():
        out += ["--zenoh-connect", endpoint]
    if getattr(args, "zenoh_config", None):
        out += ["--zenoh-config", args.zenoh_config]
    return out


def publisher_from_args(args: argparse.Namespace, process: str) -> TelemetryPublisher:
    """The one publisher of a process, from its ``add_arguments(parser, publisher=True)`` flags."""
    return TelemetryPublisher(args.vehicle_id, process, config_from_args(args))


def _zenoh_config(cfg: TelemetryConfig, listen: list[str], connect: list[str]) -> zenoh.Config:
    c = zenoh.Config()
    c.insert_json5("mode", json.dumps(cfg.mode))
    c.insert_json5("scouting/multicast/enabled", "false")
    c.insert_json5("listen/endpoints", json.dumps(listen))
    c.insert_json5("connect/endpoints", json.dumps(connect))
    return c


def open_session(cfg: TelemetryConfig) -> zenoh.Session:
    """Open a session per ``cfg``; a broken config or endpoint raises a one-line UserError."""
    if cfg.zenoh_config_file:
        path = Path(cfg.zenoh_config_file)
        try:
            return zenoh.open(zenoh.Config.from_file(str(path)))
        except (zenoh.ZError, OSError, ValueError) as exc:
            raise UserError(f"{path}: cannot open a Zenoh session: {_first_line(exc)}") from None
    extra = list(cfg.connect)
    try:
        if cfg.mode == "client":
            return zenoh.open(_zenoh_config(cfg, [], extra or [cfg.hub_endpoint]))
        try:  # be the hub ...
            return zenoh.open(_zenoh_config(cfg, [cfg.hub_endpoint], extra))
        except zenoh.ZError as exc:
            if "in use" not in str(exc):
                raise
        # ... or join it, listening on a random loopback port that gossip advertises to the others
        host = cfg.hub_endpoint.split("/", 1)[-1].rsplit(":", 1)[0]
        proto = cfg.hub_endpoint.split("/", 1)[0]
        return zenoh.open(_zenoh_config(cfg, [f"{proto}/{host}:0"], [cfg.hub_endpoint, *extra]))
    except (zenoh.ZError, ValueError) as exc:
        raise UserError(f"Zenoh hub {cfg.hub_endpoint}: cannot open a session: {_first_line(exc)}") from None


def _first_line(exc: BaseException) -> str:
    return str(exc).splitlines()[0][:200] if str(exc) else exc.__class__.__name__


_OPEN: weakref.WeakSet[Any] = weakref.WeakSet()


def _close_all() -> None:
    """Close every session still open: one left open with a live peer hangs the interpreter at exit.

    Zenoh runs Python callbacks on its own non-daemon threads, which the interpreter joins BEFORE
    ``atexit`` handlers run, so this is registered with ``threading``'s (earlier) exit hook.
    """
    for obj in list(_OPEN):
        obj.close()


_register = getattr(threading, "_register_atexit", atexit.register)
_register(_close_all)


class TelemetryPublisher:
    """Publishes domain objects on ``beliefnav/<vehicle>/<process>/<topic>``; never blocks the caller.

    ``publish`` encodes in the caller's thread (6-30 µs for the estimator's topics back to back;
    100-200 µs once per message with cold caches, as on a small VM) and puts with congestion control
    DROP, which never waits: a slow, stalled or crashed subscriber makes the transport drop samples,
    it never holds the caller (hence not Zenoh's ``lowlatency`` transport: it writes to every peer's
    socket in the caller's thread). There is no hand-off thread: a thread hop
    costs a wake-up per message (the dominant part of the latency on a busy host) and, under the
    GIL, saves the caller no CPU. While no subscriber matches a topic (Zenoh's matching listener)
    nothing is encoded at all, so telemetry nobody watches costs a dictionary look-up.
    Counters: ``published``, ``unmatched`` (skipped: no subscriber), ``encode_errors``,
    ``put_errors``. Use from one thread, as a context manager or with ``close()``.
    """

    def __init__(self, vehicle_id: str, process: str, config: TelemetryConfig | None = None):
        self.config = config or TelemetryConfig.from_env()
        self.vehicle_id, self.process = vehicle_id, process
        zc.key_for(vehicle_id, process, "x")  # validates the parts
        self._counts = {"published": 0, "unmatched": 0, "encode_errors": 0, "put_errors": 0}
        self._session: zenoh.Session | None = None
        self._publishers: dict[str, zenoh.Publisher] = {}
        self._listeners: list[zenoh.MatchingListener] = []
        self._matching: dict[str, bool] = {}  # topic -> a subscriber matches (set by Zenoh's listener)
        if not self.config.enabled:
            return
        self._session = open_session(self.config)
        _OPEN.add(self)

    @classmethod
    def disabled(cls) -> TelemetryPublisher:
        """A publisher that publishes nothing (no session): the default of nodes built in tests."""
        return cls("none", "none", TelemetryConfig(enabled=False))

    def publish(self, topic: str, obj: Any) -> None:
        """Encode ``obj`` for ``topic`` (see ``zenoh_codec.TOPICS``) and put it; never raises."""
        if self._session is None:
            return
        if not self.has_subscribers(topic):
            if topic in self._matching:  # else: not declarable, counted as a put error
                self._counts["unmatched"] += 1
            return
        try:
            payload = zc.encode(topic, obj, time.time_ns())
        except (TypeError, ValueError, KeyError, AttributeError):
            self._counts["encode_errors"] += 1
            return
        if self.put_raw(topic, payload):
            self._counts["published"] += 1

    def put_raw(self, topic: str, payload: bytes) -> bool:
        """Put an already-encoded payload (re-publishing a recording; tests of malformed input).

        Not counted as ``published``; False if it could not be put (disabled, session closed)."""
        if self._session is None:
            return False
        try:
            self._publisher(topic).put(payload)
        except zenoh.ZError:  # session closed underneath us
            self._counts["put_errors"] += 1
            return False
        return True

    def counters(self) -> dict[str, int]:
        return dict(self._counts)

    def wait_for_subscribers(self, topic: str, timeout_s: float = 10.0) -> bool:
        """True once a subscriber matches ``topic`` (tests and benchmarks; nodes never wait).

        Zenoh's matching status says that SOME subscriber matches, nothing about the others: with
        several subscriber processes, one that joined late may not be linked yet (see the bench's
        ``await_receiving``). Tools that must miss nothing (the recorder) are started first.
        """
        if self._session is None:
            return False
        deadline = time.monotonic() + timeout_s
        while not self.has_subscribers(topic):
            if time.monotonic() > deadline:
                return False
            time.sleep(0.01)
        return True

    def has_subscribers(self, topic: str) -> bool:
        """Whether a subscriber matches ``topic`` now (False when disabled)."""
        if self._session is None:
            return False
        if topic not in self._matching:
            try:
                self._publisher(topic)
            except (ValueError, zenoh.ZError):  # not a valid key part, or the session is closing
                self._counts["put_errors"] += 1
                return False
        return self._matching[topic]

    def peer_count(self) -> int:
        """Zenoh peers this process is linked to directly (0 when disabled)."""
        return 0 if self._session is None else len(list(self._session.info.peers_zid()))

    def _publisher(self, topic: str) -> zenoh.Publisher:
        pub = self._publishers.get(topic)
        if pub is None:
            assert self._session is not None
            pub = self._session.declare_publisher(
                zc.key_for(self.vehicle_id, self.process, topic),
                encoding=zenoh.Encoding.APPLICATION_JSON,
                congestion_control=zenoh.CongestionControl.DROP,
            )
            self._publishers[topic] = pub

            def on_matching(status: zenoh.MatchingStatus) -> None:
                self._matching[topic] = status.matching

            self._listeners.append(pub.declare_matching_listener(on_matching))
            # zenoh 1.10's stub types matching_status as bool; at run time it is a MatchingStatus
        self._matching[topic] = pub.matching_status.matching  # type: ignore[attr-defined]
        return pub

    def close(self) -> None:
        """Undeclare the publishers and close the session; idempotent."""
        session, self._session = self._session, None
        if session is not None:
            for listener in self._listeners:
                listener.undeclare()
            self._listeners.clear()
            for pub in self._publishers.values():
                pub.undeclare()
            self._publishers.clear()
            session.close()
        _OPEN.discard(self)

    def __enter__(self) -> TelemetryPublisher:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class DeferredPublisher:
    """Queues ``publish(topic, obj)`` until ``drain()``: a lockstep SITL node publishes after it
    has answered its step, so telemetry is off the step's critical path (same messages, same order)."""

    def __init__(self, publisher: TelemetryPublisher) -> None:
        self.publisher = publisher
        self._queue: list[tuple[str, Any]] = []

    def publish(self, topic: str, obj: Any) -> None:
        self._queue.append((topic, obj))

    def drain(self) -> None:
        queue, self._queue = self._queue, []
        for topic, obj in queue:
            self.publisher.publish(topic, obj)


@dataclass(frozen=True)
class EstimatorRates:
    """Publishing periods of the estimator's topics, on the estimate's clock (boot time)."""

    estimate_period_us: int = 20_000  # companion/estimate, 50 Hz
    belief_period_us: int = 50_000  # companion/belief, 20 Hz
    health_period_us: int = 200_000  # companion/health, 5 Hz


class EstimatorTelemetry:
    """Publishes a navigator's ``estimate``, ``belief`` and ``health`` at ``EstimatorRates``.

    Call ``update(t_us, nav)`` after each IMU sample (the estimator node, ``replay``, the bench):
    each topic is due at the next multiple of its period, so a run publishes the same messages
    whether it goes at real time, in lockstep or as fast as possible.
    """

    def __init__(self, publisher: TelemetryPublisher | DeferredPublisher,
                 rates: EstimatorRates | None = None) -> None:
        self.publisher = publisher
        r = rates or EstimatorRates()
        self._periods = {"estimate": r.estimate_period_us, "belief": r.belief_period_us,
                         "health": r.health_period_us}
        self._due = dict.fromkeys(self._periods, 0)

    def update(self, t_us: int, nav: Any) -> None:
        """``nav``: anything with ``estimate() -> NavEstimate | None`` and ``counters()``."""
        due = [topic for topic, d in self._due.items() if t_us >= d]
        if not due:
            return
        est = nav.estimate()
        if est is None:
            return
        for topic in due:
            self._due[topic] = (t_us // self._periods[topic] + 1) * self._periods[topic]
            obj = est if topic == "estimate" else zc.Belief.of(est) if topic == "belief" else (
                zc.Health(est.t_us, nav.counters()))
            self.publisher.publish(topic, obj)

    def finish(self, nav: Any) -> None:
        """A last ``health`` with status ``ended``: the run is over and this process stops cleanly
        (a viewer then says "ended" instead of "stale"). Nothing without an estimate yet."""
        est = None if nav is None else nav.estimate()
        if est is not None:
            self.publisher.publish("health", zc.Health(est.t_us, nav.counters(), status="ended"))


@dataclass(frozen=True)
class Received:
    """One decoded telemetry message."""

    vehicle: str
    process: str
    topic: str
    obj: Any
    sent_unix_ns: int | None
    recv_unix_ns: int
    payload: bytes


class TelemetrySubscriber:
    """Subscribes to ``key_expr`` (all beliefnav telemetry by default) and decodes every sample.

    ``on_message(Received)`` runs on a Zenoh thread; a payload that does not decode is counted in
    ``malformed`` (by key) and passed to ``on_malformed(key, payload, error_text)`` — never raised.
    """

    def __init__(self, on_message: Callable[[Received], None], config: TelemetryConfig | None = None,
                 key_expr: str = f"{zc.KEY_PREFIX}/**",
                 on_malformed: Callable[[str, bytes, str], None] | None = None):
        self.config = config or TelemetryConfig.from_env()
        self.on_message, self.on_malformed = on_message, on_malformed
        self.malformed: dict[str, int] = {}
        self.received = 0
        self._lock = threading.Lock()
        self._session: zenoh.Session | None = open_session(self.config)
        _OPEN.add(self)
        self._sub = self._session.declare_subscriber(key_expr, self._on_sample)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        now = time.time_ns()
        key = str(sample.key_expr)
        payload = sample.payload.to_bytes()
        try:
            vehicle, process, topic = zc.split_key(key)
            obj, sent = zc.decode(topic, payload)
        except zc.MalformedPayloadError as exc:
            with self._lock:
                self.malformed[key] = self.malformed.get(key, 0) + 1
            if self.on_malformed is not None:
                self.on_malformed(key, payload, str(exc))
            return
        with self._lock:
            self.received += 1
        self.on_message(Received(vehicle, process, topic, obj, sent, now, payload))

    @property
    def malformed_total(self) -> int:
        return sum(self.malformed.values())

    def close(self) -> None:
        session, self._session = self._session, None
        if session is not None:
            self._sub.undeclare()
            session.close()
        _OPEN.discard(self)

    def __enter__(self) -> TelemetrySubscriber:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
