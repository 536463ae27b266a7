"""MAVLink 2 message signing, done once for every link of the project (our SITL's UDP links and
the ``--master`` connection beside a real autopilot).

A signed frame ends with 13 bytes: link id, a 48-bit timestamp (10 µs ticks since 2015-01-01)
and the first 6 bytes of SHA-256(key + frame + link id + timestamp). :class:`Signer` signs what
we send (our timestamp advances by one per frame and never goes back) and checks what we receive:

- the signature is verified BEFORE the stream's timestamp is trusted: pymavlink's own check
  records a stream's timestamp first, so one forged frame (no key needed) with a far-future
  timestamp would make every later genuine frame of that stream look replayed;
- a stream (link id, system, component) must move its timestamp forward (a replay is refused);
- a NEW stream more than a minute older than our clock is a replay of an old recording.

The stream table only grows with frames whose signature checks (an attacker without the key
cannot add entries); it is bounded all the same (:data:`MAX_STREAMS`, oldest forgotten).
"""

from __future__ import annotations

import hashlib
import os
import struct
import time
from dataclasses import dataclass, field
from pathlib import Path

from companion.errors import UserError
from companion.mavlink.frames import IFLAG_SIGNED, MAGIC_V2, SIGNATURE_BYTES

SIGNING_EPOCH_UNIX_S = 1_420_070_400  # MAVLink 2 signing timestamps count 10 µs since 2015-01-01
SIGNING_KEY_BYTES = 32
NEW_STREAM_MAX_AGE = 6_000_000  # 60 s in signing ticks (10 µs): an older new stream is a replay
MAX_STREAMS = 1024  # signed streams remembered (each needs the key to create)
_LINK_TIMESTAMP = struct.Struct("<BQ")
_TIMESTAMP = struct.Struct("<Q")


def signing_timestamp_now() -> int:
    """Now, in signing ticks (10 µs since 2015-01-01 UTC)."""
    return int((max(time.time(), SIGNING_EPOCH_UNIX_S) - SIGNING_EPOCH_UNIX_S) * 100_000)


def signature_block(frame: bytes, secret_key: bytes, link_id: int, timestamp: int) -> bytes:
    """The 13 bytes that sign ``frame`` (packed with the signed flag set, ending at its CRC): link id,
    48-bit timestamp and the first 6 bytes of SHA-256(key + frame + link id + timestamp), as
    pymavlink's ``sign_packet``."""
    tail = _LINK_TIMESTAMP.pack(link_id, timestamp)[:7]
    return tail + hashlib.sha256(secret_key + frame + tail).digest()[:6]


def read_signing_key(path: str | os.PathLike[str]) -> bytes:
    """A signing key file holds 64 hex characters (the raw key, for pymavlink-style clients) or a
    passphrase: one word of printable ASCII, whose SHA-256 is the key exactly as MAVProxy's
    ``signing key WORD`` computes it (MAVProxy keeps only the first word of a longer phrase and
    encodes it as ASCII, so anything else could not be typed there)."""
    try:
        text = Path(path).read_text(encoding="utf-8").strip()
    except (OSError, UnicodeDecodeError) as exc:
        raise UserError(f"cannot read signing key file {path}: {exc}") from None
    if not text:
        raise UserError(f"signing key file {path} is empty")
    if len(text) == 2 * SIGNING_KEY_BYTES:
        try:
            return bytes.fromhex(text)
        except ValueError:
            pass
    if not (text.isascii() and text.isprintable()) or any(c.isspace() for c in text):
        raise UserError(f"signing key file {path}: a passphrase must be one word of printable ASCII "
                        "(what MAVProxy's 'signing key' accepts), or give 64 hex characters")
    return hashlib.sha256(text.encode("ascii")).digest()


@dataclass(slots=True)
class Signer:
    """One endpoint's signing state: our outgoing timestamp and the incoming streams' last ones."""

    key: bytes
    link_id: int = 0
    timestamp: int = field(default_factory=signing_timestamp_now)  # the next one we sign with
    streams: dict[tuple[int, int, int], int] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if len(self.key) != SIGNING_KEY_BYTES:
            raise UserError(f"a MAVLink 2 signing key has {SIGNING_KEY_BYTES} bytes")
        if not 0 <= self.link_id <= 255:
            raise UserError(f"a MAVLink 2 signing link id is 0..255, got {self.link_id}")

    def sign(self, frame: bytes) -> bytes:
        """``frame`` (packed with the signed flag, ending at its CRC) with its signature appended."""
        signed = frame + signature_block(frame, self.key, self.link_id, self.timestamp)
        self.timestamp += 1
        return signed

    def verdict(self, buf: bytes | bytearray, src_system: int, src_component: int) -> str:
        """``ok`` for a frame signed with our key whose timestamp is new, else the reason it is
        refused: ``unsigned`` (MAVLink 1, or no signature), ``bad_signature`` (another key, or
        damaged) or ``replayed`` (a timestamp not newer than the stream's last, or a new stream
        older than a minute). Only an ``ok`` frame moves the stream's timestamp."""
        if len(buf) < SIGNATURE_BYTES or buf[0] != MAGIC_V2 or not buf[2] & IFLAG_SIGNED:
            return "unsigned"
        if hashlib.sha256(self.key + bytes(buf[:-6])).digest()[:6] != bytes(buf[-6:]):
            return "bad_signature"
        timestamp = _TIMESTAMP.unpack(bytes(buf[-12:-6]) + b"\x00\x00")[0]
        stream = (buf[-13], src_system, src_component)
        last = self.streams.get(stream)
        if last is not None and timestamp <= last:
            return "replayed"
        if last is None and timestamp + NEW_STREAM_MAX_AGE < self.timestamp:
            return "replayed"
        if last is None and len(self.streams) >= MAX_STREAMS:
            del self.streams[min(self.streams, key=self.streams.__getitem__)]
        self.streams[stream] = timestamp
        self.timestamp = max(self.timestamp, timestamp)
        return "ok"

    def check(self, buf: bytes | bytearray, src_system: int, src_component: int) -> bool:
        return self.verdict(buf, src_system, src_component) == "ok"
