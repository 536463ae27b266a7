"""Connection strings as MAVProxy and MAVSDK users write them, parsed in one place, and the
MAVLink connection the companion uses beside a real autopilot.

Grammar (``HOST`` may be empty = 127.0.0.1; the ``scheme://`` forms are MAVSDK's):

- ``tcp:HOST:PORT`` / ``tcp://HOST:PORT`` — connect to a TCP server (ArduPilot SITL SERIAL0..2).
- ``udpin:HOST:PORT`` / ``udp://HOST:PORT`` / ``udpin://HOST:PORT`` — listen on UDP.
- ``udpout:HOST:PORT`` / ``udpout://HOST:PORT`` — send to HOST:PORT (it answers to our port).
- ``serial:DEVICE:BAUD`` / ``serial://DEVICE:BAUD`` — e.g. ``serial:/dev/ttyACM0:921600``.

What one hostile sender cannot do here (the transport is our own, not pymavlink's):

- **poison the parser**: each UDP datagram is scanned on its own
  (:func:`companion.mavlink.frames.parse_datagram`); a TCP or serial byte stream goes through
  :class:`companion.mavlink.frames.StreamScanner`, which resynchronises on junk without losing the
  genuine frames that follow. Garbage, bad CRCs and unknown message ids are counted.
- **forge frames when signing is on** (``signing_key``): every frame we send is signed, every
  frame received must be signed with the key (:class:`companion.mavlink.signing.Signer`):
  ``unsigned``, ``bad_signature`` and ``replayed`` frames are counted and dropped.
- **grow our state or our work**: a UDP listener (``udpin``) sends only to the addresses its
  autopilot's frames come from (:meth:`MavConnection.note_peer`, called for the frames the
  node has accepted as the autopilot's): at most ``max_peers`` of them, each forgotten after
  ``peer_timeout_s`` without a frame. Datagrams from any number of other addresses cost their
  parse and nothing else. A receive call handles at most :data:`MAX_DATAGRAMS` datagrams.
- **steal the port**: the UDP port is bound without ``SO_REUSEADDR``: a port in use is a one-line
  error, never shared.

Each UDP datagram carries the kernel's receive time (``SO_TIMESTAMPNS``, on our monotonic clock:
:meth:`MavConnection.arrival_us`): when we fall behind, the frames of the backlog still have
their true arrival times (the clock rule's forward envelope needs them). A byte stream has no
such times (TCP keeps only its newest segment's): ``exact_arrivals`` is False there.

A TCP peer that closes (a SITL restarting) is reconnected (``disconnects``, ``reconnects``); the
first connection is tried ``connect_retries`` times, 1 s apart, then a one-line error. Writes
never block: a TCP or serial link that cannot take more queues at most :data:`MAX_OUT_BYTES`
(whole frames beyond it are dropped and counted). A message that cannot be packed (a field
beyond its type's range) is counted as ``unsendable_<TYPE>``, never raised. Every frame received
(from any system, once it passed the checks above) and every frame sent is appended to a tlog
(standard layout, arrival stamp = local wall clock in µs).
"""

from __future__ import annotations

import contextlib
import errno
import ipaddress
import os
import select
import socket
import struct
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from companion.errors import UserError
from companion.mavlink.frames import StreamScanner, pack_frame, parse_datagram
from companion.mavlink.signing import Signer
from companion.mavlink.tlog import TlogWriter

KINDS = ("tcp", "udpin", "udpout", "serial")
_ALIASES = {"tcp": "tcp", "udpin": "udpin", "udp": "udpin", "udpout": "udpout", "serial": "serial"}
LOOPBACK = "127.0.0.1"
DIALECT = "ardupilotmega"  # common + ArduPilot's own messages (recorded, CRC-checked)
MAX_DATAGRAMS = 256  # datagrams (or stream chunks) handled per recv() call at most
MAX_DATAGRAM_BYTES = 65_535
STREAM_CHUNK_BYTES = 65_536
MAX_OUT_BYTES = 262_144  # TCP/serial bytes queued while the peer does not read
TCP_CONNECT_RETRIES = 3  # first connection: attempts 1 s apart
RECONNECT_PERIOD_S = 0.5  # a lost TCP peer is tried again this often
SO_RCVBUF_BYTES = 4 * 1024 * 1024
SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)  # Linux: receive times on each datagram
_TIMESPEC = struct.Struct("qq")
_PACK_ERRORS = (struct.error, OverflowError, ValueError, TypeError)
_LINK_REASONS = {"unknown_msgid": "unknown_message", "bad_crc": "bad_crc"}  # the rest is garbage


@dataclass(frozen=True, slots=True)
class Endpoint:
    kind: str  # one of KINDS
    host: str = ""
    port: int = 0
    device: str = ""
    baud: int = 0

    @property
    def loopback(self) -> bool:
        """Only this machine can reach it (a serial line, a radio even, is not loopback)."""
        if self.kind == "serial":
            return False
        if self.host == "localhost":
            return True
        try:
            return ipaddress.ip_address(self.host).is_loopback
        except ValueError:
            return False

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


@dataclass(frozen=True, slots=True)
class PeerPolicy:
    """Whom a UDP listener answers: the addresses its autopilot's frames come from."""

    max_peers: int = 4
    peer_timeout_s: float = 10.0  # wall time without an accepted frame from an address


class MavConnection:
    """A MAVLink connection to one autopilot, recorded both ways to ``tlog`` (if given).

    ``recv`` returns the accepted frames as light views (:mod:`companion.mavlink.frames`: field
    names as attributes, ``get_type()``, ``get_srcSystem()``, ``get_srcComponent()``,
    ``get_msgbuf()``). The source ids of what we send are set with :meth:`set_source`.
    """

    def __init__(self, endpoint: Endpoint, system_id: int, component_id: int,
                 tlog: TlogWriter | None = None, signing_key: bytes | None = None,
                 peers: PeerPolicy | None = None, connect_retries: int = TCP_CONNECT_RETRIES) -> None:
        self.endpoint = endpoint
        self.tlog = tlog
        self.counters: Counter[str] = Counter()
        self.signer = None if signing_key is None else Signer(signing_key)
        self.peers = peers or PeerPolicy()
        self._source = (system_id, component_id)
        self._seq = 0
        self._sock: socket.socket | None = None
        self._serial: Any = None
        self._fd = -1
        self._scanner = StreamScanner(DIALECT)
        self._buffer = bytearray(max(MAX_DATAGRAM_BYTES, STREAM_CHUNK_BYTES))  # reads land here: no 64 kB
        self._view = memoryview(self._buffer)  # allocation per datagram (it would fragment the heap)
        self._out = bytearray()
        self._lost = False
        self._next_reconnect_s = 0.0
        self._peer_addrs: dict[tuple[str, int], float] = {}  # udpin: address -> last accepted frame (s)
        self._origin: dict[int, tuple[str, int]] = {}  # udpin: id(view) -> its address, last batch only
        self._arrival: dict[int, int] = {}  # UDP: id(view) -> kernel receive time (monotonic µs), last batch
        self.exact_arrivals = False  # True when every datagram carries the kernel's receive time
        self._open(connect_retries)

    # -- opening ------------------------------------------------------------------------------
    def _open(self, retries: int) -> None:
        e = self.endpoint
        if e.kind == "serial":
            self._open_serial()
        elif e.kind == "tcp":
            self._connect_tcp(retries)
        else:
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            try:
                if e.kind == "udpin":
                    sock.bind((e.host, e.port))  # no SO_REUSEADDR: a port in use is refused, not shared
                else:
                    sock.connect((e.host, e.port))  # only that address's datagrams reach us
            except OSError as exc:
                sock.close()
                if exc.errno == errno.EADDRINUSE:
                    raise UserError(f"--master {e}: UDP port {e.port} is already in use "
                                    "(another companion or ground station?)") from None
                raise UserError(f"--master {e}: cannot open: {exc.strerror or exc}") from None
            sock.setblocking(False)
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, SO_RCVBUF_BYTES)
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
                self.exact_arrivals = True
            self._sock, self._fd = sock, sock.fileno()

    def _connect_tcp(self, attempts: int) -> None:
        e = self.endpoint
        for attempt in range(max(attempts, 1)):
            sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            sock.settimeout(2.0)
            try:
                sock.connect((e.host, e.port))
            except OSError as exc:
                sock.close()
                if attempt + 1 >= max(attempts, 1):
                    raise UserError(f"--master {e}: cannot connect: {exc.strerror or exc}") from None
                time.sleep(1.0)
                continue
            sock.setblocking(False)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._sock, self._fd = sock, sock.fileno()
            self._scanner.reset()
            self._out.clear()
            return

    def _open_serial(self) -> None:
        e = self.endpoint
        try:
            import serial  # pyserial: configures the port; reading and writing go through its fd
        except ImportError:
            raise UserError(f"--master {e}: serial links need pyserial (pip install pyserial)") from None
        try:
            self._serial = serial.Serial(e.device, e.baud, timeout=0, write_timeout=0, exclusive=True)
        except (OSError, ValueError, serial.SerialException) as exc:
            raise UserError(f"--master {e}: cannot open: {exc}") from None
        self._fd = self._serial.fileno()
        os.set_blocking(self._fd, False)

    # -- life cycle -----------------------------------------------------------------------------
    def _on_lost(self) -> None:
        if not self._lost:
            self.counters["disconnects"] += 1
        self._lost = True
        if self._sock is not None:
            self._sock.close()
            self._sock, self._fd = None, -1

    def _reconnect(self) -> bool:
        now = time.monotonic()
        if now < self._next_reconnect_s:
            return False
        self._next_reconnect_s = now + RECONNECT_PERIOD_S
        try:
            self._connect_tcp(1)
        except UserError:
            return False
        self._lost = False
        self.counters["reconnects"] += 1
        return True

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None
        if self._serial is not None:
            with contextlib.suppress(OSError):
                self._serial.close()
            self._serial = None
        self._fd = -1

    def set_source(self, system_id: int, component_id: int) -> None:
        self._source = (system_id, component_id)

    # -- receiving ------------------------------------------------------------------------------
    def recv(self, timeout_s: float) -> list[Any]:
        """The frames received, waiting up to ``timeout_s`` for the first datagram or bytes."""
        if self._lost and not self._reconnect():
            time.sleep(max(min(timeout_s, RECONNECT_PERIOD_S), 0.0))
            return []
        self._origin.clear()
        self._arrival.clear()
        self._flush_out()
        try:
            readable, _, _ = select.select([self._fd], [], [], max(timeout_s, 0.0))
        except (OSError, ValueError):
            readable = []
        if not readable:
            return []
        out: list[Any] = []
        if self.endpoint.kind in ("udpin", "udpout"):
            self._recv_datagrams(out)
        else:
            self._recv_stream(out)
        return out

    def _recv_datagrams(self, out: list[Any]) -> None:
        assert self._sock is not None
        udpin = self.endpoint.kind == "udpin"
        mono_minus_real_ns = time.monotonic_ns() - time.time_ns()
        for _ in range(MAX_DATAGRAMS):
            try:
                n, ancillary, _, addr = self._sock.recvmsg_into([self._view], 64)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:  # udpout: the peer's port is closed (ICMP refused)
                self.counters["peer_refused"] += 1
                return
            self.counters["datagrams"] += 1
            arrival_us = None
            for level, kind, value in ancillary:
                if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS and len(value) >= _TIMESPEC.size:
                    sec, ns = _TIMESPEC.unpack(value[: _TIMESPEC.size])
                    arrival_us = (sec * 1_000_000_000 + ns + mono_minus_real_ns) // 1000
            views, skipped = parse_datagram(bytes(self._view[:n]), DIALECT)
            first = len(out)
            self._take(views, skipped, out)
            for view in out[first:]:
                if udpin:
                    self._origin[id(view)] = addr
                if arrival_us is not None:
                    self._arrival[id(view)] = arrival_us

    def _recv_stream(self, out: list[Any]) -> None:
        for _ in range(MAX_DATAGRAMS):
            try:
                n = os.readv(self._fd, [self._view[:STREAM_CHUNK_BYTES]])
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                n = 0
            chunk = bytes(self._view[:n])
            if not chunk:  # the peer closed (EOF), or the device is gone
                if self.endpoint.kind == "tcp":
                    self._on_lost()
                return
            self.counters["bytes"] += len(chunk)
            views, skipped = self._scanner.feed(chunk)
            self._take(views, skipped, out)

    def _take(self, views: list[Any], skipped: list[str], out: list[Any]) -> None:
        c = self.counters
        for reason in skipped:
            c[_LINK_REASONS.get(reason, "garbage")] += 1
        signer = self.signer
        now_us = time.time_ns() // 1000
        for view in views:
            if signer is not None:
                verdict = signer.verdict(view.get_msgbuf(), view.get_srcSystem(), view.get_srcComponent())
                if verdict != "ok":
                    c[verdict] += 1
                    continue
            c["received"] += 1
            if self.tlog is not None:
                self.tlog.write_frame(now_us, view.get_msgbuf())
            out.append(view)

    def note_peer(self, msg: Any, now_s: float) -> None:
        """``msg`` (from the last :meth:`recv`) is the autopilot's: answer its address (udpin)."""
        addr = self._origin.get(id(msg))
        if addr is None:
            return
        peers = self._peer_addrs
        if addr not in peers:
            self._expire_peers(now_s)
            if len(peers) >= self.peers.max_peers:
                self.counters["peers_refused"] += 1  # the table is full: keep the ones we have
                return
            self.counters["peers_added"] += 1
        peers[addr] = now_s

    def _expire_peers(self, now_s: float) -> None:
        for addr, seen in list(self._peer_addrs.items()):
            if now_s - seen > self.peers.peer_timeout_s:
                del self._peer_addrs[addr]
                self.counters["peers_expired"] += 1

    def arrival_us(self, msg: Any) -> int | None:
        """When ``msg`` (from the last :meth:`recv`) arrived, by the kernel (monotonic µs); None on
        a byte stream, or when the kernel gave no time."""
        return self._arrival.get(id(msg))

    @property
    def peer_addresses(self) -> list[tuple[str, int]]:
        return list(self._peer_addrs)

    # -- sending --------------------------------------------------------------------------------
    def send(self, msg: Any) -> bool:
        """Pack (and sign) ``msg`` and send it; False (counted) if it cannot be packed or sent."""
        system_id, component_id = self._source
        try:
            frame = pack_frame(msg, self._seq, system_id, component_id, signed=self.signer is not None)
        except _PACK_ERRORS:
            self.counters[f"unsendable_{msg.get_type()}"] += 1
            return False
        if self.signer is not None:
            frame = self.signer.sign(frame)
        if not self._transmit(frame):
            return False
        self._seq = (self._seq + 1) & 0xFF
        self.counters["sent"] += 1
        if self.tlog is not None:
            self.tlog.write_frame(time.time_ns() // 1000, frame)
        return True

    def _transmit(self, frame: bytes) -> bool:
        kind = self.endpoint.kind
        if kind == "udpin":
            self._expire_peers(time.monotonic())
            if not self._peer_addrs:
                self.counters["send_no_peer"] += 1
                return False
            assert self._sock is not None
            for addr in self._peer_addrs:
                with contextlib.suppress(OSError):
                    self._sock.sendto(frame, addr)
            return True
        if kind == "udpout":
            assert self._sock is not None
            try:
                self._sock.send(frame)
            except OSError:
                self.counters["send_errors"] += 1
                return False
            return True
        if self._lost:
            self.counters["send_errors"] += 1
            return False
        if len(self._out) + len(frame) > MAX_OUT_BYTES:
            self.counters["send_dropped"] += 1  # the peer does not read: drop whole frames
            return False
        self._out += frame
        self._flush_out()
        return True

    def _flush_out(self) -> None:
        if not self._out or self._fd < 0:
            return
        try:
            n = os.write(self._fd, self._out)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            self._out.clear()
            if self.endpoint.kind == "tcp":
                self._on_lost()
            return
        del self._out[:n]


def open_connection(text: str, system_id: int, component_id: int, tlog_path: Path | None,
                    signing_key: bytes | None = None, peers: PeerPolicy | None = None) -> MavConnection:
    endpoint = parse_connection(text)
    tlog = TlogWriter(tlog_path) if tlog_path is not None else None
    try:
        return MavConnection(endpoint, system_id, component_id, tlog, signing_key, peers)
    except UserError:
        if tlog is not None:
            tlog.close()
        raise
