"""Standard tlog files: each MAVLink frame preceded by its arrival time (8-byte big-endian µs).

:class:`TlogWriter` writes them (``mavlogdump.py`` and MAVProxy read the result).
:func:`read_tlog` is a fast reader for replay: it scans frames itself, checks each frame's
CRC (x25 / MCRF4XX with the message's CRC_EXTRA, via ``fastcrc``) and unpacks only the message
types asked for into light tuple views with the message's field names (what the decoders of
:mod:`companion.mavlink.codec` read). A damaged log is read as far as it is readable:
the reader resynchronises on the next frame whose CRC checks, and counts what it skipped by
reason (``bad_crc``, ``bad_length``, ``garbage``, ``unknown_msgid``, ``truncated``, and
``bad_stamp`` for an arrival stamp beyond int64).
"""

from __future__ import annotations

import os
from collections import Counter
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any, BinaryIO

from companion.mavlink.codec import mavlink, new_link, pack
from companion.mavlink.frames import (
    HEADER_V2,
    SIGNATURE_BYTES,
    MessageSpec,
    frame_at,
    full_payload,
    message_ids,
)

STAMP_BYTES = 8
READ_BLOCK = 1 << 20  # bytes read at a time
MAX_RECORD = STAMP_BYTES + HEADER_V2 + 255 + 2 + SIGNATURE_BYTES  # the longest stamped frame
MAX_STAMP_US = 2**63 - 1  # arrival stamps are int64 µs (numpy, JSON and every consumer)


class TlogWriter:
    """Append frames to a tlog; a context manager. ``write`` packs a pymavlink message."""

    def __init__(self, path: str | Path, system_id: int = 1, component_id: int = 1) -> None:
        self.path = Path(path)
        self._file: BinaryIO = open(self.path, "wb")  # noqa: SIM115 - closed by close()/__exit__
        self._link = new_link(system_id, component_id)
        self.frames_written = 0

    def write(self, arrival_us: int, msg: mavlink.MAVLink_message) -> None:
        self.write_frame(arrival_us, pack(self._link, msg))

    def write_frame(self, arrival_us: int, frame: bytes) -> None:
        """Record a frame as received (any sender)."""
        self._file.write(arrival_us.to_bytes(STAMP_BYTES, "big") + frame)
        self.frames_written += 1

    def flush(self) -> None:
        self._file.flush()

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> TlogWriter:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()


# --- fast reader -------------------------------------------------------------------------------


@dataclass
class TlogReader:
    """Iterate ``(arrival_us, message_view)``; after (or during) iteration ``skipped`` counts
    damaged spans by reason, ``skipped_bytes`` their size, ``frames`` the good frames seen
    (including types not asked for); ``position``/``size`` (bytes) show progress."""

    path: Path
    wanted: frozenset[int] | None = None
    skipped: Counter[str] = field(default_factory=Counter)
    skipped_bytes: int = 0
    frames: int = 0
    position: int = 0
    size: int = 0

    def __iter__(self) -> Iterator[tuple[int, Any]]:
        # Read in blocks (memory flat in the file's length); a frame is parsed only when the
        # block holds a whole record past it, or at the end of the file.
        self.size = self.path.stat().st_size
        wanted = self.wanted
        with open(self.path, "rb") as f:
            data, base, pos, eof = b"", 0, 0, False  # base: file offset of data[0]
            lost_at, lost_reason = -1, ""  # file offset of the damaged span being skipped (-1: in sync)
            while True:
                if not eof and len(data) - pos < MAX_RECORD:
                    block = f.read(READ_BLOCK)
                    eof = len(block) < READ_BLOCK
                    data, base, pos = data[pos:] + block, base + pos, 0
                n = len(data)
                if pos >= n:
                    break
                parsed = self._frame_at(data, pos, n)
                if isinstance(parsed, str):
                    if lost_at < 0:
                        lost_at, lost_reason = base + pos, parsed
                    pos = self._next_candidate(data, pos + 1, n)
                    continue
                end, msgid, spec, body = parsed
                if lost_at >= 0:
                    # a "truncated" frame followed by good ones had a corrupt length byte
                    reason = "bad_length" if lost_reason == "truncated" else lost_reason
                    self._skip(reason, base + pos - lost_at)
                    lost_at = -1
                self.frames += 1
                if wanted is None or msgid in wanted:
                    stamp = int.from_bytes(data[pos : pos + STAMP_BYTES], "big")
                    self.position = base + end
                    if stamp > MAX_STAMP_US:  # not an int64 µs time: counted, never passed on
                        self._skip("bad_stamp", end - pos)
                    else:
                        yield stamp, spec.view(full_payload(spec, body))
                pos = end
        if lost_at >= 0:
            self._skip(lost_reason, self.size - lost_at)
        self.position = self.size

    def _skip(self, reason: str, size: int) -> None:
        self.skipped[reason] += 1
        self.skipped_bytes += size

    def _frame_at(self, data: bytes, pos: int, n: int) -> tuple[int, int, MessageSpec, bytes] | str:
        """The frame starting at ``pos`` (stamp first), or the reason it is not one."""
        return frame_at(data, pos + STAMP_BYTES, n)

    @staticmethod
    def _next_candidate(data: bytes, start: int, n: int) -> int:
        """Next position whose byte after the stamp is a MAVLink magic; if none in ``data``, the
        first position whose stamp may still end in the next block."""
        best = max(start, n - STAMP_BYTES)
        for magic in (b"\xfd", b"\xfe"):
            i = data.find(magic, start + STAMP_BYTES)
            if 0 <= i < best + STAMP_BYTES:
                best = i - STAMP_BYTES
        return best


def read_tlog(path: str | Path, types: Iterable[str] | None = None) -> TlogReader:
    """Fast tlog reader; ``types`` (message names) limits what is unpacked and yielded."""
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(os.fspath(p))
    return TlogReader(p, None if types is None else message_ids(types))
