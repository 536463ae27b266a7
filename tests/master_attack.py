"""Attackers for the ``--master`` hostile-input tests, each counting exactly what it sent.

- :class:`UdpAttacker`: datagrams to the companion's udpin port from many source addresses:
  junk, frames of other systems, frames forged with the autopilot's ids (unsigned, or signed with
  the wrong key).
- :class:`InjectingProxy`: a TCP man in the middle between the companion and an autopilot's TCP
  port (a noisy or hostile serial line): the autopilot's stream is forwarded frame by frame
  (parsed with pymavlink, independently of our scanner) with junk and forged frames injected
  BETWEEN genuine frames; ``forwarded`` counts the genuine frames, ``injected_frames`` the valid
  frames it added, so a receiver's count can be checked exactly.
- ``junk(rng)``: seeded junk of the kinds that poison byte-wise parsers: random bytes, a false
  magic byte announcing a 255-byte frame, a frame cut short, a frame with a flipped byte, a
  frame of an unknown message id.
"""

from __future__ import annotations

import contextlib
import select
import socket
import threading
import time
from collections import Counter
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega, common

from companion.mavlink.frames import pack_frame
from companion.mavlink.signing import Signer

mavlink = common


def frame(msg: Any, system_id: int, component_id: int = 1, seq: int = 0,
          signer: Signer | None = None) -> bytes:
    data = pack_frame(msg, seq & 0xFF, system_id, component_id, signed=signer is not None)
    return data if signer is None else signer.sign(data)


def junk(rng: np.random.Generator, sample: bytes) -> bytes:
    """One piece of junk (no valid frame in it); ``sample``: a genuine frame to mangle."""
    kind = int(rng.integers(5))
    if kind == 0:
        return rng.integers(0, 256, int(rng.integers(1, 80)), dtype=np.uint8).tobytes()
    if kind == 1:
        tail = rng.integers(0, 256, int(rng.integers(4, 40)), dtype=np.uint8).tobytes()
        return bytes((0xFD, 0xFF, 0, 0)) + tail  # "255 bytes follow"
    if kind == 2:
        return sample[: int(rng.integers(2, max(3, len(sample) - 1)))]
    if kind == 3:
        bad = bytearray(sample)
        bad[int(rng.integers(10, len(bad) - 2))] ^= 0x5A  # the CRC no longer checks
        return bytes(bad)
    unknown = bytearray(sample)
    unknown[7:10] = bytes((0x21, 0x43, 0x0E))  # an id no dialect has
    return bytes(unknown)


class UdpAttacker:
    """Sends to 127.0.0.1:``port`` from ``addresses`` sockets (distinct source ports)."""

    def __init__(self, port: int, addresses: int) -> None:
        self.target = ("127.0.0.1", port)
        self.socks = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(addresses)]
        self.sent: Counter[str] = Counter()
        self._k = 0

    def send(self, data: bytes, kind: str) -> None:
        s = self.socks[self._k % len(self.socks)]
        self._k += 1
        with contextlib.suppress(OSError):
            s.sendto(data, self.target)
            self.sent[kind] += 1

    def close(self) -> None:
        for s in self.socks:
            s.close()


class InjectingProxy:
    """127.0.0.1:``port`` -> ``upstream``: one client; see the module doc."""

    def __init__(self, upstream: tuple[str, int]) -> None:
        self.upstream = upstream
        self.server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.server.bind(("127.0.0.1", 0))
        self.server.listen(1)
        self.port = self.server.getsockname()[1]
        self.forwarded: Counter[str] = Counter()  # genuine frames, by type
        self.injected_frames = 0  # valid frames we added
        self.injected_junk = 0
        self._queue: list[tuple[bytes, int]] = []  # (bytes, how many valid frames in them)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self.paused = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    @property
    def url(self) -> str:
        return f"tcp:127.0.0.1:{self.port}"

    def inject(self, data: bytes, frames: int = 0) -> None:
        """Put ``data`` (junk, or ``frames`` valid frames) into the stream at the next frame boundary."""
        with self._lock:
            self._queue.append((data, frames))

    def _run(self) -> None:
        self.server.settimeout(0.2)
        client = None
        while client is None and not self._stop.is_set():
            with contextlib.suppress(TimeoutError):
                client, _ = self.server.accept()
        if client is None:
            return
        up = socket.create_connection(self.upstream)
        parser = ardupilotmega.MAVLink(None)
        parser.robust_parsing = True
        with client, up:
            while not self._stop.is_set():
                readable, _, _ = select.select([client, up], [], [], 0.05)
                if client in readable:
                    data = client.recv(65536)
                    if not data:
                        return
                    up.sendall(data)
                if up in readable and not self.paused.is_set():
                    data = up.recv(65536)
                    if not data:
                        return
                    out = bytearray()
                    for msg in parser.parse_buffer(data) or []:
                        if msg.get_type() == "BAD_DATA":
                            continue  # ArduPilot's boot text on SERIAL0: not a frame
                        out += self._take_queue()
                        out += msg.get_msgbuf()
                        self.forwarded[msg.get_type()] += 1
                    client.sendall(bytes(out))

    def _take_queue(self) -> bytes:
        with self._lock:
            queue, self._queue = self._queue, []
        for _, frames in queue:
            self.injected_frames += frames
            self.injected_junk += not frames
        return b"".join(data for data, _ in queue)

    def pending(self) -> int:
        with self._lock:
            return len(self._queue)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        self.server.close()


def wait_for(predicate: Any, timeout_s: float, step_s: float = 0.1) -> Any:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(step_s)
    raise AssertionError(f"not within {timeout_s} s")
