"""Fast MAVLink frame scanning: CRC-checked frames unpacked into light tuple views.

Shared by the tlog reader, the UDP links and the ``--master`` connection (pymavlink's byte-wise
parser costs ~20 µs per message; this ~2 µs). A frame is checked with its message's CRC_EXTRA
(x25 / MCRF4XX via ``fastcrc``) and unpacked only when asked for, into a namedtuple with the
message's field names and ``get_type()`` (what the decoders of :mod:`companion.mavlink.codec`
read). Link views also carry the sender's system id and the frame's bytes (``get_srcSystem()``,
``get_srcComponent()``, ``get_msgbuf()``).

Two scanners, one rule: :func:`parse_datagram` takes one datagram on its own (nothing carries
over to the next, so one hostile datagram cannot damage the frames of another);
:class:`StreamScanner` takes a byte stream (TCP, serial) in chunks and resynchronises on junk:
a damaged span is skipped from the next magic byte whose frame checks, so a false magic byte
in junk (announcing a long frame) neither loses nor holds back the genuine frames behind it.
A frame whose message id the dialect lacks cannot be CRC-checked: it is skipped whole when a
frame (or the end of the data) follows it, counted as ``unknown_msgid``.

The dialect is the common one, or ArduPilot's (``ardupilotmega``: common plus its own
messages), for links to a real autopilot. The scanner does not check signatures:
:class:`companion.mavlink.signing.Signer` does, and signs what :func:`pack_frame` packs.
"""

from __future__ import annotations

import struct
from collections import namedtuple
from collections.abc import Iterable
from dataclasses import dataclass
from operator import itemgetter
from typing import Any

from fastcrc.crc16 import mcrf4xx
from pymavlink.dialects.v20 import ardupilotmega
from pymavlink.dialects.v20 import common as mavlink

MAGIC_V2 = 0xFD
MAGIC_V1 = 0xFE
HEADER_V2 = 10  # magic, len, incompat, compat, seq, sysid, compid, msgid (3)
HEADER_V1 = 6
SIGNATURE_BYTES = 13
IFLAG_SIGNED = 0x01
CRC_INIT = 0xFFFF
LINK_EXTRA_FIELDS = ("src_system_", "msgbuf_")  # appended to link views


@dataclass(frozen=True, slots=True)
class MessageSpec:
    """How to check and unpack one message id."""

    crc_extra: bytes
    size: int
    view: Any  # callable: (payload bytes of full size, *extra values) -> view tuple


def _view_class(msgtype: type[mavlink.MAVLink_message], extra: tuple[str, ...]) -> Any:
    name, msgid = msgtype.msgname, msgtype.id
    base = namedtuple(name, [*msgtype.fieldnames, *extra], rename=True)  # type: ignore[misc]  # noqa: PYI024
    methods: dict[str, Any] = {"__slots__": (), "get_type": lambda self: name, "msgid": msgid}
    if extra:
        methods["get_srcSystem"] = lambda self: self[-2]
        methods["get_msgbuf"] = lambda self: self[-1]
        methods["get_srcComponent"] = lambda self: self[-1][6 if self[-1][0] == MAGIC_V2 else 4]
    return type(name, (base,), methods)


def _make_spec(msgtype: type[mavlink.MAVLink_message], extra: tuple[str, ...] = ()) -> MessageSpec:
    """Wire order -> field order, as pymavlink's ``decode`` does, but precomputed once."""
    cls = _view_class(msgtype, extra)
    lengths, orders = msgtype.lengths, msgtype.orders
    starts = [sum(lengths[: orders[i]]) for i in range(len(orders))]
    spans = [lengths[orders[i]] for i in range(len(orders))]
    unpack = msgtype.unpacker.unpack
    is_text = [t == "char" for t in msgtype.fieldtypes]
    new = tuple.__new__
    if all(s == 1 for s in spans) and not any(is_text):
        getter = itemgetter(*starts) if len(starts) > 1 else (lambda t: (t[starts[0]],))
        if extra:
            def view(payload: bytes, *more: Any) -> Any:
                return new(cls, (*getter(unpack(payload)), *more))
        else:
            def view(payload: bytes, *more: Any) -> Any:  # no extras: `more` is always empty
                return new(cls, getter(unpack(payload)))
    else:  # arrays (slices of the unpacked tuple) and/or NUL-padded text (as str, like pymavlink)
        keys = [s if n == 1 else slice(s, s + n) for s, n in zip(starts, spans, strict=True)]
        text_at = [i for i, text in enumerate(is_text) if text]

        def view(payload: bytes, *more: Any) -> Any:
            t = unpack(payload)
            values = [t[k] for k in keys]
            for i in text_at:
                values[i] = values[i].split(b"\x00", 1)[0].decode("utf-8", errors="replace")
            return new(cls, (*values, *more))

    return MessageSpec(bytes([msgtype.crc_extra]), msgtype.unpacker.size, view)


DIALECTS = {"common": mavlink.mavlink_map, "ardupilotmega": ardupilotmega.mavlink_map}
_SPECS: dict[tuple[int, bool, str], MessageSpec] = {}


def message_spec(msgid: int, link: bool = False, dialect: str = "common") -> MessageSpec | None:
    """The spec of ``msgid`` (None if the dialect lacks it); ``link``: views carry the sender's
    system id and the frame bytes."""
    spec = _SPECS.get((msgid, link, dialect))
    if spec is None:
        table = DIALECTS[dialect]
        if msgid in table:
            spec = _SPECS[msgid, link, dialect] = _make_spec(table[msgid], LINK_EXTRA_FIELDS if link else ())
    return spec


def message_ids(types: Iterable[str]) -> frozenset[int]:
    """MAVLink ids of the named message types (KeyError for a name the dialect lacks)."""
    ids = {m.msgname: i for i, m in mavlink.mavlink_map.items()}
    return frozenset(ids[t] for t in types)


def frame_at(data: bytes | bytearray, m: int, n: int, link: bool = False,
             dialect: str = "common") -> tuple[int, int, MessageSpec, bytes] | str:
    """The frame whose magic byte is at ``m`` in ``data[:n]``: (end, msgid, spec, payload), or the
    reason it is not one (``truncated``, ``garbage``, ``unknown_msgid``, ``bad_crc``)."""
    if m + HEADER_V1 + 2 > n:
        return "truncated"
    magic = data[m]
    if magic == MAGIC_V2:
        if m + HEADER_V2 > n:
            return "truncated"
        header = HEADER_V2
        sig = SIGNATURE_BYTES if data[m + 2] & IFLAG_SIGNED else 0
        msgid = data[m + 7] | data[m + 8] << 8 | data[m + 9] << 16
    elif magic == MAGIC_V1:
        header, sig, msgid = HEADER_V1, 0, data[m + 5]
    else:
        return "garbage"
    payload_end = m + header + data[m + 1]
    end = payload_end + 2 + sig
    if end > n:
        return "truncated"
    spec = message_spec(msgid, link, dialect)
    if spec is None:
        return "unknown_msgid"
    crc = mcrf4xx(spec.crc_extra, mcrf4xx(data[m + 1 : payload_end], CRC_INIT))
    if crc != data[payload_end] | data[payload_end + 1] << 8:
        return "bad_crc"
    return end, msgid, spec, bytes(data[m + header : payload_end])


def full_payload(spec: MessageSpec, body: bytes) -> bytes:
    """MAVLink 2 trims trailing zero bytes: pad back to the message's size (extensions absent)."""
    if len(body) < spec.size:
        body = body + bytes(spec.size - len(body))
    return body[: spec.size]


def _next_magic(data: bytes | bytearray, start: int, end: int) -> int:
    """The first magic byte (MAVLink 2 or 1) in ``data[start:end]``, ``end`` if none."""
    found = [i for i in (data.find(b"\xfd", start, end), data.find(b"\xfe", start, end)) if i >= 0]
    return min(found) if found else end


def _skip(data: bytes | bytearray, pos: int, n: int, reason: str, stream: bool,
          dialect: str) -> tuple[int, bool]:
    """Where to look for the next frame after a failure at ``pos``, and whether that skips one
    whole frame: past a frame of an unknown message id when no good frame starts inside it and a
    good frame follows it (or, in a datagram, it ends the datagram); else the next magic byte.
    Junk's false frames mostly carry unknown ids too: skipping their length on a guess could skip
    genuine frames, so the frames around must prove the guess."""
    resync = _next_magic(data, pos + 1, n)
    if reason != "unknown_msgid":
        return resync, False
    signature = SIGNATURE_BYTES if data[pos] == MAGIC_V2 and data[pos + 2] & IFLAG_SIGNED else 0
    end = pos + data[pos + 1] + 2 + signature + (HEADER_V2 if data[pos] == MAGIC_V2 else HEADER_V1)
    after = "" if end == n and not stream else "cut" if end >= n else frame_at(data, end, n, dialect=dialect)
    if isinstance(after, str) and after:
        return resync, False
    inside = resync
    while inside < end:  # a genuine frame inside the span: it was junk, not a frame
        if not isinstance(frame_at(data, inside, end, dialect=dialect), str):
            return resync, False
        inside = _next_magic(data, inside + 1, end)
    return end, True


def _next_good_frame(data: bytes | bytearray, pos: int, n: int, dialect: str) -> int:
    """Where the first complete frame that checks starts after ``pos`` (-1: none yet)."""
    i = _next_magic(data, pos + 1, n)
    while i < n:
        if not isinstance(frame_at(data, i, n, dialect=dialect), str):
            return i
        i = _next_magic(data, i + 1, n)
    return -1


def scan(data: bytes | bytearray, stream: bool = False,
         dialect: str = "common") -> tuple[list[Any], list[str], int]:
    """Link views of the good frames in ``data``, per damaged span the reason of its first failure,
    and the offset scanned up to. ``stream``: a frame cut by the end of ``data`` stops the scan
    there (its bytes are still to come) instead of counting as damage, unless a complete good
    frame starts inside its span: then it was a false magic byte in junk, skipped at once (the
    genuine frames behind it are never held back by it)."""
    n = len(data)
    views: list[Any] = []
    skipped: list[str] = []
    pos, lost = 0, ""
    while pos < n:
        parsed = frame_at(data, pos, n, link=True, dialect=dialect)
        if isinstance(parsed, str):
            if stream and parsed == "truncated":
                later = _next_good_frame(data, pos, n, dialect)
                if later < 0:
                    break  # its bytes may still come: wait
                lost, pos = lost or "garbage", later  # a good frame inside its span: it was junk
                continue
            nxt, whole = _skip(data, pos, n, parsed, stream, dialect)
            if whole and not lost:  # a whole frame of a message we cannot read: its own span
                skipped.append(parsed)
            else:
                lost = lost or parsed
            pos = nxt
            continue
        if lost:
            skipped.append(lost)
            lost = ""
        end, msgid, spec, body = parsed
        src = data[pos + 5] if data[pos] == MAGIC_V2 else data[pos + 3]
        views.append(spec.view(full_payload(spec, body), src, bytes(data[pos:end])))
        pos = end
    if lost:
        skipped.append(lost)
    return views, skipped, pos


def parse_datagram(data: bytes, dialect: str = "common") -> tuple[list[Any], list[str]]:
    """Link views of the good frames in one datagram and, per damaged span, the reason of its
    first failure (the scan resynchronises on the next magic byte whose frame checks)."""
    views, skipped, _ = scan(data, stream=False, dialect=dialect)
    return views, skipped


class StreamScanner:
    """Frames of a byte stream fed in chunks (TCP, serial): what :func:`scan` finds, the bytes of a
    frame not yet complete kept for the next chunk (at most one frame: the buffer is bounded)."""

    def __init__(self, dialect: str = "common") -> None:
        self.dialect = dialect
        self._buffer = bytearray()

    def feed(self, chunk: bytes) -> tuple[list[Any], list[str]]:
        buf = self._buffer
        buf += chunk
        views, skipped, pos = scan(buf, stream=True, dialect=self.dialect)
        del buf[:pos]
        return views, skipped

    def reset(self) -> None:
        """Forget a partial frame (the stream was reconnected)."""
        self._buffer.clear()


# --- packing ---------------------------------------------------------------------------------
_HEADER_V2 = struct.Struct("<BBBBBBBHB")
_CRC = struct.Struct("<H")


def _payload_only(mav: Any, crc_extra: int, payload: bytes, force_mavlink1: bool = False) -> bytes:
    return payload


def pack_frame(msg: mavlink.MAVLink_message, seq: int, system_id: int, component_id: int,
               signed: bool = False) -> bytes:
    """The MAVLink 2 frame of a pymavlink message, byte-equal to pymavlink's ``pack`` (its
    generated code builds the payload; header, zero trimming and CRC are done here). ``signed``:
    the header's signed flag is set and the frame ends at its CRC, ready for
    :meth:`companion.mavlink.signing.Signer.sign`."""
    msg._pack = _payload_only  # the instance's packer returns the payload
    try:
        payload = msg.pack(None)
    finally:
        del msg._pack
    body = payload.rstrip(b"\x00") or payload[:1]  # MAVLink 2 trims trailing zeros (keeps one byte)
    msgid = msg.get_msgId()
    header = _HEADER_V2.pack(MAGIC_V2, len(body), IFLAG_SIGNED if signed else 0, 0, seq, system_id,
                             component_id, msgid & 0xFFFF, msgid >> 16)
    crc = mcrf4xx(bytes((msg.crc_extra,)), mcrf4xx(header[1:] + body, CRC_INIT))
    return header + body + _CRC.pack(crc)
