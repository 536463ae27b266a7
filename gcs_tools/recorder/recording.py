"""Recording format (JSON Lines) and reader.

One line per received message: ``{"key": "beliefnav/<vehicle>/<process>/<topic>", "recv_unix_ns": int,
"payload": <the payload, verbatim>}``. A payload that failed validation is kept as
``{"key", "recv_unix_ns", "error": "<why>", "raw": "<payload text>"}`` so it can be inspected.

Why JSON Lines: payloads already are JSON, so recording is a byte copy with no re-encoding (cheapest
per message, nothing lost at full rate); a killed recorder leaves every complete line readable
(Parquet needs its footer written at close, MCAP a library we do not ship); and any language, ``jq``
or ``grep`` reads it. At ~300 messages/s per vehicle that is ~100 kB/s, which needs no columnar
compression.
"""

from __future__ import annotations

import json
import threading
from collections import defaultdict
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np

from companion.errors import UserError
from companion.telemetry import codec as zc
from companion.telemetry.pubsub import Received

MAX_RAW_BYTES = 1024  # of a malformed payload, kept in the recording for diagnosis


class RecordingWriter:
    """Appends messages to a JSON Lines file; thread-safe (Zenoh calls back from its own threads)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        try:
            self._f: IO[bytes] = self.path.open("wb")
        except OSError as exc:
            raise UserError(f"{self.path}: cannot write: {exc.strerror or exc}") from None
        self._lock = threading.Lock()
        self.count = 0
        self.malformed = 0

    def write(self, msg: Received) -> None:
        key = zc.key_for(msg.vehicle, msg.process, msg.topic)
        line = b'{"key":"%s","recv_unix_ns":%d,"payload":%s}\n' % (
            key.encode(), msg.recv_unix_ns, msg.payload)
        with self._lock:
            self._f.write(line)
            self.count += 1

    def write_malformed(self, key: str, payload: bytes, error: str, recv_unix_ns: int) -> None:
        """Record the error and the first ``MAX_RAW_BYTES`` of the payload (never all of a huge one)."""
        line = json.dumps({"key": key, "recv_unix_ns": recv_unix_ns, "error": error,
                           "raw_bytes": len(payload),
                           "raw": payload[:MAX_RAW_BYTES].decode("utf-8", "replace")}) + "\n"
        with self._lock:
            self._f.write(line.encode())
            self.malformed += 1

    def flush(self) -> None:
        with self._lock:
            self._f.flush()

    def close(self) -> None:
        with self._lock:
            self._f.close()


@dataclass
class Recording:
    """Decoded messages of a recording, per vehicle and topic, in file order."""

    messages: dict[str, dict[str, list[Any]]] = field(
        default_factory=lambda: defaultdict(lambda: defaultdict(list)))
    malformed: int = 0

    @property
    def vehicles(self) -> list[str]:
        return sorted(self.messages)


def iter_lines(path: str | Path) -> Iterator[tuple[int, dict[str, Any] | None]]:
    """(line number, parsed line or None if unreadable); a truncated last line is just unreadable."""
    p = Path(path)
    if p.is_dir():
        raise UserError(f"{p}: a directory; give a recording made by `beliefnav record` (.jsonl)")
    try:
        f = p.open("rb")
    except OSError as exc:
        raise UserError(f"{p}: cannot read: {exc.strerror or exc}") from None
    with f:
        for n, line in enumerate(f, 1):
            try:
                d = json.loads(line)
            except (UnicodeDecodeError, json.JSONDecodeError, RecursionError):
                yield n, None
                continue
            yield n, d if isinstance(d, dict) else None


def recorded_vehicle(rec: Recording, vehicle: str, path: str | Path) -> str:
    """``vehicle`` if the recording at ``path`` holds it, else a one-line error naming the ones it holds."""
    if vehicle not in rec.vehicles:
        raise UserError(f"{path}: no vehicle {vehicle!r} (valid: {', '.join(rec.vehicles)})")
    return vehicle


def read_recording(path: str | Path) -> Recording:
    """Read and decode a recording; malformed lines and payloads are counted, not raised."""
    rec = Recording()
    for _n, d in iter_lines(path):
        try:
            if d is None or "payload" not in d:
                raise zc.MalformedPayloadError("unreadable line")
            vehicle, _process, topic = zc.split_key(d.get("key", ""))
            obj = zc.from_dict(topic, d["payload"])
            rec.messages[vehicle][topic].append(obj)
        except zc.MalformedPayloadError:
            rec.malformed += 1
    if not rec.messages:
        raise UserError(f"{path}: no telemetry in this recording ({rec.malformed} malformed lines)")
    return rec


@dataclass(frozen=True)
class RecordedWorld:
    """The map as a recording carries it (``route.buildings_ne_m``): what ``figures.draw_world`` needs."""

    rects_m: np.ndarray  # (K, 4) n0, e0, n1, e1 [m]


def recorded_route(rec: Recording, vehicle: str) -> tuple[RecordedWorld, np.ndarray, str]:
    """(world, planned waypoints (N, 3), " (mission, profile)" or "") of the vehicle's last route message."""
    routes = rec.messages[vehicle].get("route", [])
    if not routes:
        return RecordedWorld(np.zeros((0, 4))), np.zeros((0, 3)), ""
    r = routes[-1]
    return RecordedWorld(r.buildings_ne_m), r.waypoints_ned_m, f" ({r.mission}, profile {r.profile})"


def _interp(t_s: np.ndarray, t_src_s: np.ndarray, values: np.ndarray) -> np.ndarray:
    if len(t_src_s) == 0:
        return np.full((len(t_s), values.shape[1] if values.ndim > 1 else 1), np.nan)
    return np.column_stack([np.interp(t_s, t_src_s, values[:, i], left=np.nan, right=np.nan)
                            for i in range(values.shape[1])])


def series(rec: Recording, vehicle: str) -> dict[str, np.ndarray]:
    """Flight series at the estimate's timestamps, with the keys of ``simvehicle.harness.fly`` results.

    Truth and setpoint are interpolated onto estimate times; ``latency_s`` is the latency of the
    most recent GNSS fix released at or before each time.
    """
    by = rec.messages[vehicle]
    est = sorted(by.get("estimate", []), key=lambda e: e.t_us)
    if not est:
        raise UserError(f"vehicle {vehicle!r}: the recording has no estimates")
    t_s = np.array([e.t_us for e in est]) * 1e-6

    def stacked(topic: str, attr: str, width: int = 3) -> tuple[np.ndarray, np.ndarray]:
        objs = sorted(by.get(topic, []), key=lambda o: o.t_us)
        t = np.array([o.t_us for o in objs], dtype=float) * 1e-6
        return t, np.array([getattr(o, attr) for o in objs], dtype=float).reshape(len(objs), width)

    t_tr, p_true = stacked("truth", "p_ned_m")
    _, b_true = stacked("truth", "gnss_bias_ned_m")
    _, clearance = stacked("truth", "clearance_m", 1)
    t_sp, p_ref = stacked("setpoint", "p_ned_m")
    out = {
        "t_s": t_s,
        "p_est_ned_m": np.array([e.p_ned_m for e in est]),
        "b_est_ned_m": np.array([e.b_ned_m for e in est]),
        "beta": np.array([e.beta for e in est]),
        "nis": np.array([e.nis for e in est]),
        "p_true_ned_m": _interp(t_s, t_tr, p_true),
        "b_true_ned_m": _interp(t_s, t_tr, b_true),
        "clearance_m": _interp(t_s, t_tr, clearance)[:, 0],
        "p_ref_ned_m": _interp(t_s, t_sp, p_ref),
    }
    gnss = sorted(by.get("gnss", []), key=lambda g: g.t_us)
    t_g = np.array([g.t_us for g in gnss], dtype=float) * 1e-6
    lat = np.array([g.latency_s for g in gnss])
    idx = np.searchsorted(t_g, t_s, side="right") - 1
    out["latency_s"] = np.where(idx >= 0, lat[np.clip(idx, 0, None)] if len(lat) else np.nan, np.nan)
    out["est_error_m"] = np.linalg.norm(out["p_est_ned_m"] - out["p_true_ned_m"], axis=1)
    out["track_error_m"] = np.linalg.norm(out["p_true_ned_m"] - out["p_ref_ned_m"], axis=1)
    return out
