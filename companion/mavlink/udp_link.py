"""A MAVLink 2 endpoint over UDP on 127.0.0.1: one socket, one peer, counted rejections.

Every datagram is parsed on its own (a broken datagram never poisons the next). What cannot be
used is counted and dropped, never raised: garbage bytes, bad CRCs, message ids outside the
common dialect, frames from a system id the link does not accept, and — when a signing key is
set — unsigned frames or frames signed with another key. The peer is either fixed
(``peer_port``) or learned from the last accepted HEARTBEAT, so a restarted client on a new
ephemeral port is picked up again (and no other kind of frame can redirect the link).
Frames are accepted by system id and, where configured, component id.

A closed peer port (its process is gone) is reported: the socket asks for ICMP errors
(``IP_RECVERR``, Linux), so the next operation after a send to it fails with ECONNREFUSED; that
is counted as ``peer_refused`` and the error queue is drained (its entries would otherwise
take up the receive buffer).

Test-only loss injection drops datagrams per direction with a seeded generator. An optional
``tee`` callback sees the bytes of every frame sent and every accepted frame received (the
node stamps them and writes the tlog).
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import select
import socket
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from companion.errors import UserError
from companion.mavlink.frames import pack_frame, parse_datagram
from companion.mavlink.signing import (  # noqa: F401 - re-exported: the SITL's users import them here
    SIGNING_EPOCH_UNIX_S,
    SIGNING_KEY_BYTES,
    Signer,
    read_signing_key,
)

MAX_DATAGRAM_BYTES = 65_535
BATCH_DATAGRAM_BYTES = 32_768  # a batch is split into datagrams of at most this size
VEHICLE_SYSTEM_ID = 1  # the vehicle and its companions share one MAVLink system id
VEHICLE_COMPONENT_ID = 1  # MAV_COMP_ID_AUTOPILOT1: the vehicle process
ESTIMATOR_COMPONENT_ID = 197  # MAV_COMP_ID_VISUAL_INERTIAL_ODOMETRY
BRIDGE_COMPONENT_ID = 191  # MAV_COMP_ID_ONBOARD_COMPUTER
IP_RECVERR = getattr(socket, "IP_RECVERR", 11)  # Linux: report ICMP errors on unconnected sockets
MSG_ERRQUEUE = getattr(socket, "MSG_ERRQUEUE", 0x2000)

Tee = Callable[[bytes, bool], None]  # (frame, sent) -> None


@dataclass(frozen=True, slots=True)
class LinkConfig:
    """Where a link listens and whom it talks to (loopback only by default)."""

    bind_port: int = 0  # 0: an ephemeral port chosen by the OS
    peer_port: int | None = None  # None: reply to whoever last sent an accepted frame
    host: str = "127.0.0.1"
    system_id: int = 1  # our MAVLink system id
    component_id: int = 1  # our MAVLink component id
    accept_system_ids: frozenset[int] | None = None  # None: frames from any system id
    accept_component_ids: frozenset[int] | None = None  # None: frames from any component id
    signing_key: bytes | None = None  # 32-byte MAVLink 2 signing secret; None: no signing
    link_id: int = 0  # MAVLink 2 signing link id of this endpoint
    drop_probability_tx: float = 0.0  # test-only loss injection on sends, in [0, 1]
    drop_probability_rx: float = 0.0  # test-only loss injection on receives, in [0, 1]


@dataclass(slots=True)
class LinkCounters:
    """What the link saw; names are stable (they appear in summaries and tests)."""

    datagrams_rx: int = 0
    datagrams_tx: int = 0
    messages_rx: int = 0
    messages_tx: int = 0
    garbage: int = 0  # bytes that are not a MAVLink frame (bad prefix, truncated, bad length)
    bad_crc: int = 0
    unknown_message: int = 0  # valid frame, message id not in the common dialect
    wrong_system_id: int = 0
    wrong_component_id: int = 0  # right system id, but not a component this link talks to
    bad_signature: int = 0  # unsigned, wrong key or replayed timestamp while signing is on
    dropped_rx: int = 0  # loss injector
    dropped_tx: int = 0  # loss injector
    send_errors: int = 0  # e.g. a full send buffer
    peer_refused: int = 0  # the peer's port is closed (ECONNREFUSED): its process is gone

    def as_dict(self) -> dict[str, int]:
        return asdict(self)


class _DatagramSink:
    """File-like target for pymavlink's packer: each ``write`` is one datagram."""

    def __init__(self, link: UdpLink) -> None:
        self._link = link

    def write(self, buf: bytes) -> None:
        self._link._send_datagram(bytes(buf))


class UdpLink:
    """One MAVLink endpoint. ``send`` never blocks; ``recv`` returns the accepted messages of
    one datagram (empty on timeout or rejection)."""

    def __init__(
        self,
        config: LinkConfig,
        rng: np.random.Generator | None = None,
        tee: Tee | None = None,
    ) -> None:
        if (config.drop_probability_tx or config.drop_probability_rx) and rng is None:
            raise ValueError("loss injection needs a seeded numpy Generator")
        self.config = config
        self.counters = LinkCounters()
        self.tee = tee
        self._rng = rng
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.bind((config.host, config.bind_port))
        except OSError as exc:
            self._sock.close()
            if exc.errno == errno.EADDRINUSE:
                raise UserError(f"UDP port {config.bind_port} on {config.host} is already in use") from None
            raise UserError(f"cannot bind UDP {config.host}:{config.bind_port}: {exc.strerror}") from None
        self._sock.setblocking(False)
        self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 * 1024 * 1024)
        with contextlib.suppress(OSError):  # not on every platform: then a dead peer is only silent
            self._sock.setsockopt(socket.IPPROTO_IP, IP_RECVERR, 1)
        self._batch: list[bytes] | None = None
        self.last_rx_ns = 0  # perf_counter_ns() when the last datagram was read from the socket
        self.peer: tuple[str, int] | None = (
            (config.host, config.peer_port) if config.peer_port is not None else None
        )
        self._mav = mavlink.MAVLink(_DatagramSink(self), config.system_id, config.component_id)
        self._mav.robust_parsing = True
        self.signer = None if config.signing_key is None else Signer(config.signing_key, config.link_id)

    # -- plumbing -------------------------------------------------------------------------
    @property
    def port(self) -> int:
        return int(self._sock.getsockname()[1])

    @property
    def mav(self) -> mavlink.MAVLink:
        """pymavlink's encoder (``link.mav.heartbeat_encode(...)`` builds messages)."""
        return self._mav

    def fileno(self) -> int:
        return self._sock.fileno()

    def close(self) -> None:
        self._sock.close()

    def __enter__(self) -> UdpLink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- sending --------------------------------------------------------------------------
    def send(self, msg: mavlink.MAVLink_message) -> None:
        """Pack (and sign) ``msg`` and send it to the peer; without a peer yet it is skipped."""
        if self.peer is None:
            return
        self._send_datagram(self.pack(msg))
        self.counters.messages_tx += 1

    def pack(self, msg: mavlink.MAVLink_message) -> bytes:
        """``msg`` as this link's next frame: signed when the link has a key; advances the sequence."""
        mav = self._mav
        if self.signer is None:  # the fast packer, byte-equal to pymavlink's (signed too, below)
            frame = pack_frame(msg, mav.seq, mav.srcSystem, mav.srcComponent)
        else:
            frame = self.signer.sign(pack_frame(msg, mav.seq, mav.srcSystem, mav.srcComponent, signed=True))
        mav.seq = (mav.seq + 1) & 0xFF
        return frame

    def begin_batch(self) -> None:
        """Collect the frames sent from now on into one datagram, sent by :meth:`flush` (lockstep
        uses one datagram per step and per answer: far fewer wake-ups than one per frame)."""
        if self._batch is None:
            self._batch = []

    def flush(self) -> None:
        """Send the collected frames (split below the datagram size limit) and stop batching."""
        frames, self._batch = self._batch, None
        chunk: list[bytes] = []
        size = 0
        for frame in frames or ():
            if size + len(frame) > BATCH_DATAGRAM_BYTES and chunk:
                self._transmit(chunk)
                chunk, size = [], 0
            chunk.append(frame)
            size += len(frame)
        if chunk:
            self._transmit(chunk)

    def send_frame(self, frame: bytes) -> None:
        """Forward an already packed frame unchanged (routing: its source ids and signature stay)."""
        if self.peer is not None:
            self._send_datagram(frame)
            self.counters.messages_tx += 1

    def _send_datagram(self, frame: bytes) -> None:
        if self._batch is not None:
            self._batch.append(frame)
        else:
            self._transmit([frame])

    def _transmit(self, frames: list[bytes]) -> None:
        if self.config.drop_probability_tx and self._drop(self.config.drop_probability_tx):
            self.counters.dropped_tx += 1
            return
        assert self.peer is not None
        try:
            self._sock.sendto(frames[0] if len(frames) == 1 else b"".join(frames), self.peer)
        except OSError as exc:  # ECONNREFUSED from an earlier send, full buffer: a lost datagram
            self._socket_error(exc)
            return
        self.counters.datagrams_tx += 1
        if self.tee is not None:
            for frame in frames:
                self.tee(frame, True)

    def _socket_error(self, exc: OSError) -> None:
        if not isinstance(exc, ConnectionRefusedError):
            self.counters.send_errors += 1
            return
        self.counters.peer_refused += 1
        while True:  # drain the ICMP error queue
            try:
                self._sock.recvmsg(1, 512, MSG_ERRQUEUE)
            except OSError:
                return

    def _drop(self, probability: float) -> bool:
        assert self._rng is not None
        return bool(self._rng.random() < probability)

    # -- receiving ------------------------------------------------------------------------
    def wait_readable(self, timeout_s: float) -> bool:
        readable, _, _ = select.select([self._sock], [], [], max(timeout_s, 0.0))
        return bool(readable)

    def recv(self, timeout_s: float = 0.0) -> list[mavlink.MAVLink_message]:
        """Accepted messages of the next datagram; [] if none arrives within ``timeout_s``."""
        if timeout_s > 0 and not self.wait_readable(timeout_s):
            return []
        while True:
            try:
                data, addr = self._sock.recvfrom(MAX_DATAGRAM_BYTES)
            except (BlockingIOError, InterruptedError):
                return []
            except OSError as exc:  # ICMP port unreachable reported on a later call
                self._socket_error(exc)
                continue
            self.last_rx_ns = time.perf_counter_ns()
            return self.accept_datagram(data, addr)

    def recv_all(self) -> list[mavlink.MAVLink_message]:
        """Every message already waiting in the socket buffer, in arrival order."""
        out: list[mavlink.MAVLink_message] = []
        while True:
            try:
                data, addr = self._sock.recvfrom(MAX_DATAGRAM_BYTES)
            except (BlockingIOError, InterruptedError):
                return out
            except OSError as exc:
                self._socket_error(exc)
                continue
            self.last_rx_ns = time.perf_counter_ns()
            out.extend(self.accept_datagram(data, addr))

    def accept_datagram(self, data: bytes, addr: tuple[str, int]) -> list[Any]:
        """Parse one datagram with the fast scanner of :mod:`companion.mavlink.frames` (messages
        are its light views); count and drop what cannot be used (never raises). With signing,
        a frame is kept only if it is MAVLink 2, signed, and its signature checks
        (:class:`companion.mavlink.signing.Signer`: unsigned, wrong key or replayed frames count as
        bad_signature)."""
        c = self.counters
        c.datagrams_rx += 1
        if self.config.drop_probability_rx and self._drop(self.config.drop_probability_rx):
            c.dropped_rx += 1
            return []
        views, skipped = parse_datagram(data)
        for reason in skipped:
            if reason == "bad_crc":
                c.bad_crc += 1
            elif reason == "unknown_msgid":
                c.unknown_message += 1
            else:
                c.garbage += 1
        signer = self.signer
        if signer is not None:
            signed = [v for v in views
                      if signer.check(v.get_msgbuf(), v.get_srcSystem(), v.get_srcComponent())]
            c.bad_signature += len(views) - len(signed)
            views = signed
        return self._accept(views, addr)

    def _accept(self, msgs: list[Any], addr: tuple[str, int]) -> list[Any]:
        """Keep the messages from accepted system ids; learn the peer; tee what is kept."""
        c = self.counters
        accept_ids = self.config.accept_system_ids
        accepted = msgs
        if accept_ids is not None:
            accepted = [m for m in msgs if m.get_srcSystem() in accept_ids]
            c.wrong_system_id += len(msgs) - len(accepted)
        components = self.config.accept_component_ids
        if components is not None:
            n = len(accepted)
            accepted = [m for m in accepted if m.get_srcComponent() in components]
            c.wrong_component_id += n - len(accepted)
        if accepted:
            c.messages_rx += len(accepted)
            if self.config.peer_port is None and any(m.get_type() == "HEARTBEAT" for m in accepted):
                self.peer = addr
            if self.tee is not None:
                for msg in accepted:
                    self.tee(bytes(msg.get_msgbuf()), False)
        return accepted


# -- command-line options shared by the vehicle and companion processes --------------------------
def add_link_arguments(parser: argparse.ArgumentParser) -> None:
    """Signing and (test-only) loss options; parsing itself stays in each ``__main__``."""
    parser.add_argument("--signing-key-file", help="MAVLink 2 signing key (64 hex chars or a passphrase)")
    parser.add_argument(
        "--drop-probability", type=float, default=0.0,
        help="TEST ONLY: drop this fraction of datagrams in each direction",
    )
    parser.add_argument("--loss-seed", type=int, default=0, help="seed of the loss injector")


def link_settings(args: argparse.Namespace) -> tuple[dict[str, object], np.random.Generator | None]:
    """LinkConfig fields and the loss generator chosen by :func:`add_link_arguments` options."""
    p = float(args.drop_probability)
    if not 0.0 <= p <= 1.0:
        raise UserError(f"--drop-probability must be in [0, 1], got {p}")
    key = read_signing_key(args.signing_key_file) if args.signing_key_file else None
    fields: dict[str, object] = {"signing_key": key, "drop_probability_tx": p, "drop_probability_rx": p}
    return fields, (np.random.default_rng(args.loss_seed) if p > 0 else None)
