"""Connection strings as MAVProxy and MAVSDK users write them, parsed in one place, and the
generic MAVLink connection the companion uses beside a foreign autopilot.

Grammar (``HOST`` may be empty = 127.0.0.1; the ``scheme://`` forms are MAVSDK's):

- ``tcp:HOST:PORT`` / ``tcp://HOST:PORT`` — connect to a TCP server (ArduPilot SITL SERIAL0..2).
- ``udpin:HOST:PORT`` / ``udp://HOST:PORT`` / ``udpin://HOST:PORT`` — listen on UDP; replies go to
  the address the last datagram came from.
- ``udpout:HOST:PORT`` / ``udpout://HOST:PORT`` — send to HOST:PORT (it answers to our port).
- ``serial:DEVICE:BAUD`` / ``serial://DEVICE:BAUD`` — e.g. ``serial:/dev/ttyACM0:921600``.

The generic path is pymavlink's ``mavutil`` (one parser for every transport); our own
simulated vehicle keeps its faster :class:`companion.mavlink.udp_link.UdpLink`
(``--vehicle-port``). Every frame received and every frame sent is appended to a tlog
(standard layout, arrival stamp = local wall clock in µs).
"""

from __future__ import annotations

import contextlib
import os
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

os.environ.setdefault("MAVLINK20", "1")

from pymavlink import mavutil  # noqa: E402

from companion.errors import UserError  # noqa: E402
from companion.mavlink.tlog import TlogWriter  # noqa: E402

KINDS = ("tcp", "udpin", "udpout", "serial")
_ALIASES = {"tcp": "tcp", "udpin": "udpin", "udp": "udpin", "udpout": "udpout", "serial": "serial"}
LOOPBACK = "127.0.0.1"
MAX_DRAIN = 512  # messages taken per recv() call at most
TCP_CONNECT_RETRIES = 3  # first connection: attempts 1 s apart (pymavlink's)


@dataclass(frozen=True, slots=True)
class Endpoint:
    kind: str  # one of KINDS
    host: str = ""
    port: int = 0
    device: str = ""
    baud: int = 0

    def mavutil_device(self) -> str:
        """The same endpoint in pymavlink's spelling."""
        if self.kind == "serial":
            return self.device
        return f"{self.kind}:{self.host}:{self.port}"

    def __str__(self) -> str:
        if self.kind == "serial":
            return f"serial:{self.device}:{self.baud}"
        return f"{self.kind}:{self.host}:{self.port}"


def parse_connection(text: str) -> Endpoint:
    """``Endpoint`` from a connection string; a one-line UserError naming what is wrong."""
    scheme, sep, rest = text.partition(":")
    if not sep or scheme.lower() not in _ALIASES:
        raise UserError(f"--master {text!r}: expected tcp:HOST:PORT, udpin:HOST:PORT, "
                        "udpout:HOST:PORT or serial:DEVICE:BAUD")
    kind = _ALIASES[scheme.lower()]
    rest = rest[2:] if rest.startswith("//") else rest
    where, sep, number = rest.rpartition(":")
    if not sep:
        raise UserError(f"--master {text!r}: missing :{'BAUD' if kind == 'serial' else 'PORT'}")
    try:
        value = int(number)
    except ValueError:
        raise UserError(f"--master {text!r}: {number!r} is not a number") from None
    if kind == "serial":
        if not where:
            raise UserError(f"--master {text!r}: missing the serial device")
        if value <= 0:
            raise UserError(f"--master {text!r}: baud rate must be positive")
        return Endpoint(kind, device=where, baud=value)
    if not 0 < value < 65536:
        raise UserError(f"--master {text!r}: port {value} out of range 1..65535")
    if kind == "udpout" and not where:
        raise UserError(f"--master {text!r}: udpout needs the host to send to")
    return Endpoint(kind, host=where or LOOPBACK, port=value)


class MavConnection:
    """A MAVLink connection to one autopilot, recorded both ways to ``tlog`` (if given).

    ``recv`` returns parsed messages (pymavlink objects); frames that do not parse are counted
    in ``counters['bad_frames']`` and never passed on. The source ids of what we send are set
    with :meth:`set_source` (the companion takes the autopilot's system id once discovered).
    """

    def __init__(self, endpoint: Endpoint, system_id: int, component_id: int,
                 tlog: TlogWriter | None = None) -> None:
        self.endpoint = endpoint
        self.tlog = tlog
        self.counters: Counter[str] = Counter()
        self._source = (system_id, component_id)
        self._lost = False
        try:
            self._conn: Any = self._open(TCP_CONNECT_RETRIES)
        except (OSError, ValueError) as exc:
            raise UserError(f"--master {endpoint}: cannot open: {exc}") from None

    def _open(self, retries: int) -> Any:
        conn = mavutil.mavlink_connection(
            self.endpoint.mavutil_device(), baud=self.endpoint.baud or 115200, source_system=self._source[0],
            source_component=self._source[1], autoreconnect=False, robust_parsing=True, retries=retries,
            dialect="ardupilotmega")
        if self.endpoint.kind == "tcp":  # the peer closed (a SITL restart): reopen from recv()
            conn.handle_eof = conn.handle_disconnect = self._on_lost
        return conn

    def _on_lost(self) -> None:
        if not self._lost:
            self.counters["disconnects"] += 1
        self._lost = True

    def _reopen(self, timeout_s: float) -> bool:
        with contextlib.suppress(OSError):
            self._conn.close()
        try:
            self._conn = self._open(0)
        except (OSError, ValueError):
            time.sleep(max(timeout_s, 0.0))
            return False
        self._lost = False
        self.counters["reconnects"] += 1
        return True

    def set_source(self, system_id: int, component_id: int) -> None:
        self._source = (system_id, component_id)
        self._conn.mav.srcSystem = system_id
        self._conn.mav.srcComponent = component_id

    def recv(self, timeout_s: float) -> list[Any]:
        """Messages received, waiting up to ``timeout_s`` for the first; a closed TCP peer is
        reconnected (counted in ``disconnects`` / ``reconnects``)."""
        out: list[Any] = []
        if self._lost and not self._reopen(timeout_s):
            return out
        try:
            msg = self._conn.recv_match(blocking=True, timeout=max(timeout_s, 0.0))
            while msg is not None:
                self._take(msg, out)
                if len(out) >= MAX_DRAIN or self._lost:
                    break
                msg = self._conn.recv_msg()
        except OSError:
            self._on_lost()
        return out

    def _take(self, msg: Any, out: list[Any]) -> None:
        kind = msg.get_type()
        if kind in ("BAD_DATA", "UNKNOWN"):
            self.counters["bad_frames"] += 1
            return
        self.counters["received"] += 1
        if self.tlog is not None:
            self.tlog.write_frame(time.time_ns() // 1000, bytes(msg.get_msgbuf()))
        out.append(msg)

    def send(self, msg: Any) -> None:
        try:
            self._conn.mav.send(msg)
        except OSError:
            self.counters["send_errors"] += 1
            return
        self.counters["sent"] += 1
        if self.tlog is not None:
            self.tlog.write_frame(time.time_ns() // 1000, bytes(msg.get_msgbuf()))

    def close(self) -> None:
        self._conn.close()


def open_connection(text: str, system_id: int, component_id: int, tlog_path: Path | None) -> MavConnection:
    endpoint = parse_connection(text)
    tlog = TlogWriter(tlog_path) if tlog_path is not None else None
    try:
        return MavConnection(endpoint, system_id, component_id, tlog)
    except UserError:
        if tlog is not None:
            tlog.close()
        raise
