"""Zenoh telemetry codec: domain types <-> JSON payloads (Zenoh encoding ``application/json``).

Key expressions are ``beliefnav/<vehicle>/<process>/<topic>``; the topic (last segment) fixes the
payload's schema (``TOPICS``). Every payload is one flat JSON object with the topic's fields plus
``sent_unix_ns`` (the publisher's wall clock, ns since the Unix epoch, taken when the caller
published: receivers on the same host get the end-to-end latency from it). Vectors are JSON lists;
non-finite floats are ``null`` (JSON has no NaN). The README's "Telemetry topics" section is the
human-readable form of ``TOPICS``.

Decoding validates everything and raises ``MalformedPayloadError`` (one line, naming the field) on
anything else: tools count those, they never crash on them.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from companion.domain.samples import GnssFix, NavEstimate, Setpoint, TruthState

KEY_PREFIX = "beliefnav"


class MalformedPayloadError(ValueError):
    """A payload that is not valid JSON for its topic; the message names the field."""


# --- telemetry-only types (no MAVLink counterpart) ------------------------------------------------


@dataclass(frozen=True, slots=True)
class Belief:
    """GNSS trust belief of the estimator: beta in [0, 1] and the last fix's NIS."""

    t_us: int
    beta: float
    nis: float  # NaN before the first fused fix
    method: str

    @classmethod
    def of(cls, est: NavEstimate) -> Belief:
        return cls(t_us=est.t_us, beta=est.beta, nis=est.nis, method=est.method)


@dataclass(frozen=True, slots=True)
class Health:
    """Counters of a process (samples used, fused, rejected by reason, ...) and its status text."""

    t_us: int
    counters: Mapping[str, int]
    status: str = "ok"


@dataclass(frozen=True, slots=True)
class GnssReport:
    """A GNSS fix as the vehicle released it at ``t_us`` (its validity time is in the fix)."""

    t_us: int
    fix: GnssFix

    @property
    def latency_s(self) -> float:
        return (self.t_us - self.fix.t_validity_us) * 1e-6


@dataclass(frozen=True, slots=True)
class RouteInfo:
    """The planned route and the map it was planned on (published by the bridge, about 1 Hz)."""

    t_us: int
    mission: str
    profile: int
    waypoints_ned_m: np.ndarray  # (N, 3)
    duration_s: float
    buildings_ne_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))  # (K, 4) n0, e0, n1, e1
    goal_ned_m: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    # the origin of the NED frame (lat, lon [deg], alt [m] AMSL): NaN when not sent
    home_lla: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))


@dataclass(frozen=True, slots=True)
class FlightStatus:
    """What an autopilot's HEARTBEAT says: its flight mode and whether it is armed (1 Hz and on
    every change)."""

    t_us: int
    mode: str  # e.g. OFFBOARD, HOLD
    armed: bool


# --- field kinds: (encode, decode) ----------------------------------------------------------------

_Enc = Callable[[Any], Any]
_Dec = Callable[[Any, str], Any]


def _enc_float(x: Any) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def _shown(v: Any) -> str:
    """``repr`` of an offending value, cut short (a hostile value may be megabytes long)."""
    text = repr(v) if not isinstance(v, int) or abs(v) < 10**30 else f"<{v.bit_length()}-bit integer>"
    return text if len(text) <= 60 else text[:57] + "..."


def _dec_float(optional: bool) -> _Dec:
    def dec(v: Any, where: str) -> float:
        if v is None and optional:
            return math.nan
        try:
            ok = not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v)
        except OverflowError:  # an integer no float can hold
            ok = False
        if not ok:
            raise MalformedPayloadError(f"{where}: expected a finite number, got {_shown(v)}")
        return float(v)

    return dec


def _dec_int(v: Any, where: str) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or not -(2**63) <= v < 2**63:
        raise MalformedPayloadError(f"{where}: expected a 64-bit integer, got {_shown(v)}")
    return v


def _dec_str(v: Any, where: str) -> str:
    if not isinstance(v, str):
        raise MalformedPayloadError(f"{where}: expected a string, got {_shown(v)}")
    return v


def _enc_array(x: Any) -> list:
    values = np.asarray(x, dtype=float).tolist()
    if values and isinstance(values[0], list):
        return [_enc_array(r) for r in values]
    return values if all(map(math.isfinite, values)) else [_enc_float(v) for v in values]


def _dec_array(shape: tuple[int | None, ...], optional: bool = False) -> _Dec:
    n_fixed = shape[0] if len(shape) == 1 else None

    def dec(v: Any, where: str) -> np.ndarray:
        # fast path, the common case: a list of n finite JSON floats -> one numpy call. A subscriber
        # runs this cold (once per message, its caches evicted in between), where every numpy call
        # costs 10-25 µs; anything else takes the general path below, which names the fault
        if (type(v) is list and len(v) == n_fixed and all(type(x) is float for x in v)
                and all(map(math.isfinite, v))):
            return np.array(v, dtype=float)
        if not isinstance(v, list):
            raise MalformedPayloadError(f"{where}: expected a list, got {type(v).__name__}")
        try:
            a = np.array(v, dtype=float)  # null -> NaN
        except (TypeError, ValueError, OverflowError):
            raise MalformedPayloadError(f"{where}: expected numbers") from None
        if len(v) == 0 and len(shape) == 2:
            a = a.reshape(0, shape[1] or 0)
        if a.ndim != len(shape) or any(n is not None and n != m for n, m in zip(shape, a.shape, strict=True)):
            want = "x".join("N" if n is None else str(n) for n in shape)
            raise MalformedPayloadError(f"{where}: expected shape {want}, got {'x'.join(map(str, a.shape))}")
        if not optional and not np.isfinite(a).all():
            raise MalformedPayloadError(f"{where}: expected finite numbers")
        return a

    return dec


def _dec_bool(v: Any, where: str) -> bool:
    if not isinstance(v, bool):
        raise MalformedPayloadError(f"{where}: expected true or false, got {_shown(v)}")
    return v


def _dec_counters(v: Any, where: str) -> dict[str, int]:
    if not isinstance(v, dict):
        raise MalformedPayloadError(f"{where}: expected an object, got {type(v).__name__}")
    return {str(k): _dec_int(c, f"{where}.{k}") for k, c in v.items()}


INT = (int, _dec_int)
STR = (str, _dec_str)
BOOL = (bool, _dec_bool)
FLOAT = (_enc_float, _dec_float(False))
FLOAT_OPT = (_enc_float, _dec_float(True))  # null <-> NaN (not available)
VEC3 = (_enc_array, _dec_array((3,)))
COUNTERS = (lambda c: {str(k): int(n) for k, n in c.items()}, _dec_counters)


@dataclass(frozen=True)
class TopicSpec:
    """Schema of one topic: the domain type, its JSON fields in order, and derived extra fields."""

    cls: type
    fields: dict[str, tuple[_Enc, _Dec]]
    extras: Callable[[Any], dict[str, Any]] = lambda obj: {}
    # fields added after the first release: a payload without them (an older publisher, an older
    # recording) decodes with the type's default
    added: frozenset[str] = frozenset()


_GNSS_FIELDS: dict[str, tuple[_Enc, _Dec]] = {
    "t_validity_us": INT, "lat_deg": FLOAT, "lon_deg": FLOAT, "alt_m": FLOAT, "fix_type": INT,
    "satellites_visible": INT, "h_acc_m": FLOAT_OPT, "v_acc_m": FLOAT_OPT, "hdop": FLOAT_OPT,
}

TOPICS: dict[str, TopicSpec] = {
    "estimate": TopicSpec(NavEstimate, {
        "t_us": INT, "p_ned_m": VEC3, "v_ned_m_s": VEC3, "b_ned_m": VEC3,
        "cov_diag": (_enc_array, _dec_array((9,))), "beta": FLOAT, "nis": FLOAT_OPT, "method": STR,
        "pos_horiz_test_ratio": FLOAT_OPT, "gnss_rejected_innovation": INT},
        added=frozenset({"pos_horiz_test_ratio", "gnss_rejected_innovation"})),
    "belief": TopicSpec(Belief, {"t_us": INT, "beta": FLOAT, "nis": FLOAT_OPT, "method": STR}),
    "health": TopicSpec(Health, {"t_us": INT, "counters": COUNTERS, "status": STR}),
    "truth": TopicSpec(TruthState, {
        "t_us": INT, "p_ned_m": VEC3, "v_ned_m_s": VEC3, "q_ned_frd": (_enc_array, _dec_array((4,))),
        "gnss_bias_ned_m": VEC3, "gnss_latency_s": FLOAT, "clearance_m": FLOAT_OPT}),
    "gnss": TopicSpec(GnssReport, {"t_us": INT, **_GNSS_FIELDS},
                      extras=lambda r: {"latency_s": r.latency_s}),
    "setpoint": TopicSpec(Setpoint, {"t_us": INT, "p_ned_m": VEC3, "v_ned_m_s": VEC3, "a_ned_m_s2": VEC3}),
    "route": TopicSpec(RouteInfo, {
        "t_us": INT, "mission": STR, "profile": INT, "waypoints_ned_m": (_enc_array, _dec_array((None, 3))),
        "duration_s": FLOAT, "buildings_ne_m": (_enc_array, _dec_array((None, 4))),
        "goal_ned_m": (_enc_array, _dec_array((3,), optional=True)),
        "home_lla": (_enc_array, _dec_array((3,), optional=True))}, added=frozenset({"home_lla"})),
    "status": TopicSpec(FlightStatus, {"t_us": INT, "mode": STR, "armed": BOOL}),
}


# --- keys -------------------------------------------------------------------------------------------


def key_for(vehicle: str, process: str, topic: str) -> str:
    """``beliefnav/<vehicle>/<process>/<topic>``; each part must be a plain key chunk."""
    for part in (vehicle, process, topic):
        if not part or any(c in part for c in "/*$?#"):
            raise ValueError(f"invalid key part {part!r}")
    return f"{KEY_PREFIX}/{vehicle}/{process}/{topic}"


def split_key(key: str) -> tuple[str, str, str]:
    """Inverse of ``key_for``: (vehicle, process, topic); MalformedPayloadError for a foreign key."""
    parts = str(key).split("/")
    if len(parts) != 4 or parts[0] != KEY_PREFIX or not all(parts):
        raise MalformedPayloadError(f"{key}: not a beliefnav/<vehicle>/<process>/<topic> key")
    return parts[1], parts[2], parts[3]


# --- payloads ---------------------------------------------------------------------------------------


def to_dict(topic: str, obj: Any) -> dict[str, Any]:
    """The JSON object (before serialisation) of ``obj`` on ``topic``."""
    spec = TOPICS[topic]
    if not isinstance(obj, spec.cls):
        raise TypeError(f"topic {topic!r} carries {spec.cls.__name__}, got {type(obj).__name__}")
    source: Any = obj.fix if isinstance(obj, GnssReport) else obj
    out: dict[str, Any] = {}
    for name, (enc, _dec) in spec.fields.items():
        value = getattr(obj if name == "t_us" else source, name)  # a GNSS report's t_us is its own
        out[name] = enc(value)
    out.update(spec.extras(obj))
    return out


# ``json.dumps`` with options builds a new encoder per call: its Python set-up costs more than the
# C serialisation of an estimate when it runs cold (once per message, as a publisher does)
_JSON_ENCODER = json.JSONEncoder(separators=(",", ":"), allow_nan=False)


def encode(topic: str, obj: Any, sent_unix_ns: int) -> bytes:
    """UTF-8 JSON payload of ``obj`` on ``topic`` (``TypeError`` if the type does not match)."""
    d = to_dict(topic, obj)
    d["sent_unix_ns"] = int(sent_unix_ns)
    return _JSON_ENCODER.encode(d).encode()


def from_dict(topic: str, d: Any) -> Any:
    """Domain object from a parsed JSON object; MalformedPayloadError on any deviation."""
    spec = TOPICS.get(topic)
    if spec is None:
        raise MalformedPayloadError(f"unknown topic {topic!r}")
    if not isinstance(d, dict):
        raise MalformedPayloadError(f"{topic}: expected a JSON object")
    values = {}
    for name, (_enc, dec) in spec.fields.items():
        if name not in d and name in spec.added:
            continue  # the type's default
        if name not in d:
            raise MalformedPayloadError(f"{topic}.{name}: missing")
        values[name] = dec(d[name], f"{topic}.{name}")
    if spec.cls is GnssReport:
        t_us = values.pop("t_us")
        return GnssReport(t_us=t_us, fix=GnssFix(**values))
    return spec.cls(**values)


MAX_PAYLOAD_BYTES = 256 * 1024  # the largest real payload (a route) is a few kB
MAX_JSON_DEPTH = 8  # payloads are flat: object -> list -> list at most


def _nested_deeper_than(obj: Any, limit: int) -> bool:
    """True if the parsed JSON ``obj`` nests containers deeper than ``limit`` (the top level is 1).
    Walked after parsing (json strings need no special care) and only through containers, with an
    early exit: a flat payload costs one pass over its lists."""
    stack = [(obj, 1)] if isinstance(obj, (dict, list)) else []
    while stack:
        item, depth = stack.pop()
        if depth > limit:
            return True
        children = item.values() if isinstance(item, dict) else item
        stack.extend((c, depth + 1) for c in children if isinstance(c, (dict, list)))
    return False


def decode(topic: str, payload: bytes | str) -> tuple[Any, int | None]:
    """(domain object, sent_unix_ns or None) from a payload; MalformedPayloadError if it is not valid
    (including a payload over ``MAX_PAYLOAD_BYTES`` or nested deeper than ``MAX_JSON_DEPTH``)."""
    if len(payload) > MAX_PAYLOAD_BYTES:
        raise MalformedPayloadError(f"{topic}: payload of {len(payload):,} bytes over the limit of "
                                    f"{MAX_PAYLOAD_BYTES:,}")
    too_deep = f"{topic}: JSON nested deeper than the limit of {MAX_JSON_DEPTH}"
    try:
        d = json.loads(payload)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise MalformedPayloadError(f"{topic}: not JSON ({exc.__class__.__name__})") from None
    except RecursionError:  # nested past the parser's own limit
        raise MalformedPayloadError(too_deep) from None
    if _nested_deeper_than(d, MAX_JSON_DEPTH):
        raise MalformedPayloadError(too_deep)
    obj = from_dict(topic, d)
    sent = d.get("sent_unix_ns")
    return obj, (sent if isinstance(sent, int) and not isinstance(sent, bool) else None)

