"""Fast MAVLink frame scanning: CRC-checked frames unpacked into light tuple views.

Shared by the tlog reader and the UDP links (pymavlink's byte-wise parser costs ~20 µs per
message; this ~2 µs). A frame is checked with its message's CRC_EXTRA (x25 / MCRF4XX via
``fastcrc``) and unpacked only when asked for, into a namedtuple with the message's field
names and ``get_type()`` (what the decoders of :mod:`companion.mavlink.codec` read).
Link views also carry the sender's system id and the frame's bytes (``get_srcSystem()``,
``get_msgbuf()``). The scanner does not check signatures: a signing link checks each signed
frame's signature itself (``companion.mavlink.udp_link.check_signature``) and signs what it packs
with :func:`signature_block`.
"""

from __future__ import annotations

import hashlib
import struct
from collections import namedtuple
from collections.abc import Iterable
from dataclasses import dataclass
from operator import itemgetter
from typing import Any

from fastcrc.crc16 import mcrf4xx
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
    else:  # arrays (slices of the unpacked tuple) and/or NUL-padded text
        keys = [s if n == 1 else slice(s, s + n) for s, n in zip(starts, spans, strict=True)]
        text_at = [i for i, text in enumerate(is_text) if text]

        def view(payload: bytes, *more: Any) -> Any:
            t = unpack(payload)
            values = [t[k] for k in keys]
            for i in text_at:
                values[i] = values[i].rstrip(b"\x00")
            return new(cls, (*values, *more))

    return MessageSpec(bytes([msgtype.crc_extra]), msgtype.unpacker.size, view)


_SPECS: dict[tuple[int, bool], MessageSpec] = {}


def message_spec(msgid: int, link: bool = False) -> MessageSpec | None:
    """The spec of ``msgid`` (None if the common dialect lacks it); ``link``: views carry the
    sender's system id and the frame bytes."""
    spec = _SPECS.get((msgid, link))
    if spec is None and msgid in mavlink.mavlink_map:
        spec = _SPECS[msgid, link] = _make_spec(mavlink.mavlink_map[msgid], LINK_EXTRA_FIELDS if link else ())
    return spec


def message_ids(types: Iterable[str]) -> frozenset[int]:
    """MAVLink ids of the named message types (KeyError for a name the dialect lacks)."""
    ids = {m.msgname: i for i, m in mavlink.mavlink_map.items()}
    return frozenset(ids[t] for t in types)


def frame_at(data: bytes, m: int, n: int, link: bool = False) -> tuple[int, int, MessageSpec, bytes] | str:
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
    spec = message_spec(msgid, link)
    if spec is None:
        return "unknown_msgid"
    crc = mcrf4xx(spec.crc_extra, mcrf4xx(data[m + 1 : payload_end], CRC_INIT))
    if crc != data[payload_end] | data[payload_end + 1] << 8:
        return "bad_crc"
    return end, msgid, spec, data[m + header : payload_end]


def full_payload(spec: MessageSpec, body: bytes) -> bytes:
    """MAVLink 2 trims trailing zero bytes: pad back to the message's size (extensions absent)."""
    if len(body) < spec.size:
        body = body + bytes(spec.size - len(body))
    return body[: spec.size]


def parse_datagram(data: bytes) -> tuple[list[Any], list[str]]:
    """Link views of the good frames in ``data`` and, per damaged span, the reason of its first
    failure (the scan resynchronises on the next magic byte whose frame checks)."""
    n = len(data)
    views: list[Any] = []
    skipped: list[str] = []
    pos, lost = 0, ""
    while pos < n:
        parsed = frame_at(data, pos, n, link=True)
        if isinstance(parsed, str):
            lost = lost or parsed
            nxt = [i for i in (data.find(b"\xfd", pos + 1), data.find(b"\xfe", pos + 1)) if i >= 0]
            pos = min(nxt) if nxt else n
            continue
        if lost:
            skipped.append(lost)
            lost = ""
        end, msgid, spec, body = parsed
        src = data[pos + 5] if data[pos] == MAGIC_V2 else data[pos + 3]
        views.append(spec.view(full_payload(spec, body), src, data[pos:end]))
        pos = end
    if lost:
        skipped.append(lost)
    return views, skipped


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
    :func:`signature_block`."""
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


_LINK_TIMESTAMP = struct.Struct("<BQ")


def signature_block(frame: bytes, secret_key: bytes, link_id: int, timestamp: int) -> bytes:
    """The 13 bytes that sign ``frame`` (packed with ``signed=True``): link id, 48-bit timestamp
    (10 µs ticks since 2015) and the first 6 bytes of SHA-256(key + frame + link id + timestamp),
    as pymavlink's ``sign_packet``."""
    tail = _LINK_TIMESTAMP.pack(link_id, timestamp)[:7]
    return tail + hashlib.sha256(secret_key + frame + tail).digest()[:6]
