"""Fuzz the MAVLink decoders and the link's signature check (in process, seeded).

Every message type a node decodes, with each field drawn from boundary values (0, ±1, type
limits), NaN, ±inf, float32 extremes and random values, packed to real bytes and parsed by the
fast scanner: a decoder returns a finite, in-limit value or raises ``CodecError`` — nothing else.
"""

from __future__ import annotations

import dataclasses
import math
import socket
import time

import numpy as np
import pytest

from companion.domain.geodesy import LocalNedFrame
from companion.mavlink import codec
from companion.mavlink.frames import parse_datagram
from companion.mavlink.udp_link import SIGNING_EPOCH_UNIX_S, LinkConfig, UdpLink

mavlink = codec.mavlink
HOME = LocalNedFrame(-37.8594910, 144.7647800, 10.0)
INT_RANGES = {"uint8_t": (0, 255), "int8_t": (-128, 127), "uint16_t": (0, 65535), "int16_t": (-32768, 32767),
              "uint32_t": (0, 2**32 - 1), "int32_t": (-(2**31), 2**31 - 1), "uint64_t": (0, 2**64 - 1),
              "int64_t": (-(2**63), 2**63 - 1)}
FLOATS = (0.0, -0.0, 1.0, -1.0, math.nan, math.inf, -math.inf, 3.4e38, -3.4e38, 1e-45, 9.81, 157.0, 35.0)

DECODERS = {
    "HIGHRES_IMU": codec.decode_imu, "RAW_IMU": codec.decode_raw_imu, "SCALED_IMU": codec.decode_scaled_imu,
    "ATTITUDE_QUATERNION": codec.decode_attitude, "ATTITUDE": codec.decode_attitude_euler,
    "GPS_RAW_INT": lambda m: codec.decode_sample(m, HOME), "ODOMETRY": codec.decode_odometry,
    "SET_POSITION_TARGET_LOCAL_NED": codec.decode_setpoint, "NAMED_VALUE_FLOAT": codec.decode_named_value,
    "ESTIMATOR_STATUS": codec.decode_estimator_status, "SYSTEM_TIME": codec.decode_system_time,
    "HEARTBEAT": codec.decode_heartbeat, "SIM_STATE": lambda m: codec.decode_truth(m, HOME, 0),
}
CLASSES = {cls.msgname: cls for cls in mavlink.mavlink_map.values() if cls.msgname in DECODERS}


def _value(rng: np.random.Generator, ftype: str, length: int):
    if ftype == "char":
        return bytes(rng.integers(0, 256, int(rng.integers(0, length + 1)), dtype=np.uint8))
    if length > 0:  # arrays
        return [_value(rng, ftype, 0) for _ in range(length)]
    if ftype in ("float", "double"):
        return float(FLOATS[int(rng.integers(len(FLOATS)))]) if rng.random() < 0.6 else float(
            rng.normal(0, 10 ** rng.integers(0, 12)))
    lo, hi = INT_RANGES[ftype]
    return int(rng.choice([lo, hi, 0, 1, int(rng.integers(lo, hi, endpoint=True, dtype=np.uint64
                                                             if ftype == "uint64_t" else np.int64))]))


def _finite_values(x) -> bool:
    values = [getattr(x, f) for f in x.__dataclass_fields__] if hasattr(x, "__dataclass_fields__") else []
    for v in values:
        arr = np.asarray(v)
        if arr.dtype.kind == "f" and not np.all(np.isfinite(arr[~np.isnan(arr)] if arr.ndim else arr)):
            return False
    return True


@pytest.mark.parametrize("name", sorted(DECODERS))
def test_decoders_return_a_value_or_a_codec_error_for_any_field_values(name):
    rng = np.random.default_rng(sum(map(ord, name)))
    cls = CLASSES[name]
    link = codec.new_link(1, 1)
    outcomes = {"ok": 0}
    for _ in range(1_500):
        fields = [_value(rng, t, cls.array_lengths[cls.orders[i]]) for i, t in enumerate(cls.fieldtypes)]
        msg = cls(*fields)
        try:
            frame = codec.pack(link, msg)
        except Exception:  # noqa: BLE001 - pymavlink cannot pack it: no frame, nothing to decode
            continue
        views, _ = parse_datagram(frame)
        assert len(views) == 1
        try:
            value = DECODERS[name](views[0])
        except codec.CodecError as exc:
            outcomes[exc.reason] = outcomes.get(exc.reason, 0) + 1
            continue
        outcomes["ok"] += 1
        if name == "ESTIMATOR_STATUS":  # NaN = no test made
            value = dataclasses.replace(value, pos_horiz_ratio=0.0 if math.isnan(value.pos_horiz_ratio)
                                        else value.pos_horiz_ratio,
                                        vel_ratio=0.0 if math.isnan(value.vel_ratio) else value.vel_ratio)
        assert _finite_values(value) or name in ("SIM_STATE", "ODOMETRY", "GPS_RAW_INT"), (name, value)
    assert sum(outcomes.values()) > 1_000, outcomes  # most draws really reached the decoder


def _signed(key: bytes, link_id: int, t_sign: int, system_id: int = 1, component_id: int = 1) -> bytes:
    mav = codec.new_link(system_id, component_id)
    mav.signing.secret_key, mav.signing.sign_outgoing = key, True
    mav.signing.link_id, mav.signing.timestamp = link_id, t_sign
    return codec.pack(mav, codec.encode_heartbeat("companion"))


def test_a_forged_frame_with_a_huge_timestamp_cannot_cut_a_signed_stream():
    """pymavlink records a stream's timestamp before it checks the signature; the link must not."""
    key = bytes(range(32))
    now = int((time.time() - SIGNING_EPOCH_UNIX_S) * 100_000)
    with UdpLink(LinkConfig(signing_key=key)) as rx, socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        def send(frame: bytes) -> int:
            s.sendto(frame, ("127.0.0.1", rx.port))
            return len(rx.recv(timeout_s=1.0))

        assert send(_signed(key, 5, now)) == 1
        forged = bytearray(_signed(bytes(32), 5, 2**47))  # same stream, wrong key, far future
        assert send(bytes(forged)) == 0
        assert send(_signed(key, 5, now + 10)) == 1  # the genuine stream goes on
        assert send(_signed(key, 5, now + 10)) == 0  # a replay is still refused
        assert rx.counters.bad_signature == 2
