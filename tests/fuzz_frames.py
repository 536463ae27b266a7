"""Seeded hostile MAVLink frames for the fuzz tests, each with the counter class it must land in.

Every generated datagram holds ONE frame (or one piece of junk) and an ``expect`` tag:

- ``link``: rejected by the receiving link (garbage, bad CRC, unknown id, bad or missing
  signature, wrong system or component id) — at least one link rejection counter moves;
- ``node``: passes the link (signed with the run's key, right system and component id) and
  must be rejected by the receiving node (range, plausibility or clock) — exactly one node
  rejection counter moves;
- ``ground``: accepted by the vehicle's ground port (any ids) and counted there by type.

Hostile ``node`` content is built so that it can never be used: every message has a value out of
range (NaN, ±inf, beyond the codec's limits), or an unsupported frame/mask, or a stamp far from
the receiver's clock (past stamps assume the receiver's time is beyond ``PAST_STAMP_MAX_US``
+ the widest back window, i.e. fire only after 8 s of simulated time).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from companion.mavlink import codec
from companion.mavlink.udp_link import (
    BRIDGE_COMPONENT_ID,
    ESTIMATOR_COMPONENT_ID,
    SIGNING_EPOCH_UNIX_S,
    VEHICLE_COMPONENT_ID,
)

mavlink = codec.mavlink
PAST_STAMP_MAX_US = 1_000_000
FUZZ_START_S = 8.0  # simulated time after which past stamps are outside every back window
BAD_FLOATS = (math.nan, math.inf, -math.inf, 3.0e38, -3.0e38, 1e9, -1e9)
LOCAL_NED = mavlink.MAV_FRAME_LOCAL_NED


@dataclass(frozen=True, slots=True)
class Fuzz:
    target: str  # vehicle_estimator | vehicle_bridge | ground | estimator | bridge
    data: bytes
    expect: str  # link | node | ground
    kind: str  # generator class, for messages


class _Signer:
    """Packs messages as (system, component), signed with ``key`` (or another key, or unsigned)."""

    def __init__(self, key: bytes | None, link_id: int) -> None:
        self._links: dict[tuple[int, int], mavlink.MAVLink] = {}
        self.key, self.link_id = key, link_id

    def pack(self, msg: mavlink.MAVLink_message, system_id: int, component_id: int) -> bytes:
        link = self._links.get((system_id, component_id))
        if link is None:
            link = self._links[system_id, component_id] = codec.new_link(system_id, component_id)
            if self.key is not None:
                link.signing.secret_key = self.key
                link.signing.sign_outgoing = True
                link.signing.link_id = self.link_id
                link.signing.timestamp = int((time.time() - SIGNING_EPOCH_UNIX_S) * 100_000)
        return codec.pack(link, msg)


class FrameFuzzer:
    """``frames(n)``: n seeded hostile datagrams spread over the five targets."""

    def __init__(self, rng: np.random.Generator, key: bytes) -> None:
        self.rng = rng
        self.good = _Signer(key, link_id=77)
        self.wrong = _Signer(bytes(rng.integers(0, 256, 32, dtype=np.uint8)), link_id=78)
        self.unsigned = _Signer(None, link_id=0)
        self._pools: dict[tuple[str, int, bool, int], list[bytes]] = {}
        self._past_us = PAST_STAMP_MAX_US

    # -- value pickers -------------------------------------------------------------------------
    def _bad(self) -> float:
        return float(BAD_FLOATS[int(self.rng.integers(len(BAD_FLOATS)))])

    def _far_us(self) -> int:
        """A stamp far in the future or the past (µs). Past stamps only ever decrease and future
        ones are spread over 2^62 µs, so no run of them agrees like a rebooted clock's would (a
        key holder COULD forge such a run: that is what the key is for)."""
        if self.rng.random() < 0.5:
            self._past_us = max(self._past_us - int(self.rng.integers(1, 8)), 0)
            return self._past_us
        return int(self.rng.integers(2**33, 2**62))

    def _far_ms(self) -> int:
        if self.rng.random() < 0.5:
            return int(self.rng.integers(PAST_STAMP_MAX_US // 1000))
        return int(self.rng.integers(2**23, 2**32))

    def _now_us(self) -> int:
        """A stamp that may well be in window (content must then be bad)."""
        return int(self.rng.integers(10_000_000, 60_000_000))

    def _vec_with_bad(self, good: float = 0.0) -> list[float]:
        v = [good, good, good]
        v[int(self.rng.integers(3))] = self._bad()
        return v

    # -- hostile messages each receiver must reject (right ids, right key) ------------------------
    def _to_estimator(self) -> mavlink.MAVLink_message:
        r = self.rng.integers(7)
        f = codec.IMU_FIELDS_ACC_GYRO
        if r == 0:  # absurd or non-finite specific force / rate
            acc, gyro = [0.0, 0.0, -9.8], [0.0, 0.0, 0.0]
            if self.rng.random() < 0.5:
                acc = self._vec_with_bad(-9.8)
            else:
                gyro = self._vec_with_bad()
            return mavlink.MAVLink_highres_imu_message(self._now_us(), *acc, *gyro, 0, 0, 0, 0, 0, 0, 0, f, 0)
        if r == 1:  # plausible values, stamp far off: the clock guard rejects a lone one
            return mavlink.MAVLink_highres_imu_message(self._far_us(), 0.1, 0.0, -9.8, 0, 0, 0,
                                                       0, 0, 0, 0, 0, 0, 0, f, 0)
        if r == 2:  # fields not updated
            return mavlink.MAVLink_highres_imu_message(self._now_us(), 0, 0, -9.8, 0, 0, 0,
                                                       0, 0, 0, 0, 0, 0, 0, 0, 0)
        if r == 3:  # attitude: broken quaternion or far stamp
            if self.rng.random() < 0.5:
                q = [1.0, 0.0, 0.0, 0.0]
                q[int(self.rng.integers(4))] = self._bad()
                return mavlink.MAVLink_attitude_quaternion_message(self._now_us() // 1000, *q, 0, 0, 0,
                                                                   [0.0] * 4)
            return mavlink.MAVLink_attitude_quaternion_message(self._far_ms(), 1, 0, 0, 0, 0, 0, 0, [0.0] * 4)
        if r == 4:  # GNSS far from home, impossible lat, or far stamp
            pick = self.rng.integers(3)
            lat, lon = (int(self.rng.integers(-900_000_000, 900_000_000)), 0) if pick == 0 else (
                (2_000_000_000, 0) if pick == 1 else (-378_594_910, 1_447_647_800))
            t = self._now_us() if pick < 2 else self._far_us()
            return mavlink.MAVLink_gps_raw_int_message(t, 3, lat, lon, 10_000, 80, 65535, 65535, 65535,
                                                       12, 0, 100, 200, 0, 0, 0)
        if r == 5:  # RAW_IMU beyond 16 g (mg)
            return mavlink.MAVLink_raw_imu_message(self._now_us(), int(self.rng.integers(16_500, 32_767)),
                                                   0, 0, 0, 0, 0, 0, 0, 0)
        return mavlink.MAVLink_timesync_message(0, self._far_us() % 2**53 * 1000)  # a step marker far off

    def _to_vehicle_from_estimator(self) -> mavlink.MAVLink_message:
        r = self.rng.integers(4)
        cov = [0.01] * 21
        if r == 0:  # bad position / velocity / variance, plausible stamp
            p, v = [1.0, 2.0, -10.0], [0.0, 0.0, 0.0]
            which = self.rng.integers(3)
            if which == 0:
                p = self._vec_with_bad(1.0)
            elif which == 1:
                v = self._vec_with_bad()
            else:
                cov = list(cov)
                cov[0] = -1.0 if self.rng.random() < 0.5 else self._bad()
                cov[0] = cov[0] if not (math.isfinite(cov[0]) and cov[0] > 0 and cov[0] < 1e12) else -1.0
            return mavlink.MAVLink_odometry_message(self._now_us(), LOCAL_NED, LOCAL_NED, *p, [1, 0, 0, 0],
                                                    *v, 0, 0, 0, cov, cov, 0, 0, 50)
        if r == 1:  # a perfectly good estimate, stamped far from the vehicle's time
            return mavlink.MAVLink_odometry_message(self._far_us(), LOCAL_NED, LOCAL_NED, 1.0, 2.0, -10.0,
                                                    [1, 0, 0, 0], 0, 0, 0, 0, 0, 0, cov, cov, 0, 0, 50)
        if r == 2:  # unsupported frame
            return mavlink.MAVLink_odometry_message(self._now_us(), mavlink.MAV_FRAME_BODY_FRD, LOCAL_NED,
                                                    1.0, 2.0, -10.0, [1, 0, 0, 0], 0, 0, 0, 0, 0, 0,
                                                    cov, cov, 0, 0, 50)
        # belief: non-finite, outside [0, 1], or far stamp
        name = codec.BELIEF_NAME.encode()
        if self.rng.random() < 0.5:
            return mavlink.MAVLink_named_value_float_message(self._far_ms(), name, 0.5)
        bad = self._bad() if self.rng.random() < 0.5 else float(self.rng.choice([-0.5, 1.5, 7.0]))
        return mavlink.MAVLink_named_value_float_message(self._now_us() // 1000, name, bad)

    def _to_vehicle_from_bridge(self) -> mavlink.MAVLink_message:
        r = self.rng.integers(4)
        mask = 0b110_000_000_000  # yaw and yaw rate ignored, like the bridge
        p = [10.0, 10.0, -10.0]
        if r == 0:
            p = self._vec_with_bad(10.0)
            return mavlink.MAVLink_set_position_target_local_ned_message(
                self._now_us() // 1000, 1, 1, LOCAL_NED, mask, *p, 0, 0, 0, 0, 0, 0, 0, 0)
        if r == 1:  # good setpoint, stamp far off
            return mavlink.MAVLink_set_position_target_local_ned_message(
                self._far_ms(), 1, 1, LOCAL_NED, mask, *p, 0, 0, 0, 0, 0, 0, 0, 0)
        if r == 2:  # position ignored / force flag
            return mavlink.MAVLink_set_position_target_local_ned_message(
                self._now_us() // 1000, 1, 1, LOCAL_NED, mask | 0b111, *p, 0, 0, 0, 0, 0, 0, 0, 0)
        return mavlink.MAVLink_set_position_target_local_ned_message(
            self._now_us() // 1000, 1, 1, mavlink.MAV_FRAME_GLOBAL, mask, *p, 0, 0, 0, 0, 0, 0, 0, 0)

    def _to_bridge(self) -> mavlink.MAVLink_message:
        return mavlink.MAVLink_timesync_message(0, self._far_us() % 2**53 * 1000)

    # -- datagrams -----------------------------------------------------------------------------
    HOSTILE: dict[str, tuple[Callable[[FrameFuzzer], mavlink.MAVLink_message], int]] = {
        "estimator": (_to_estimator, VEHICLE_COMPONENT_ID),
        "bridge": (_to_bridge, VEHICLE_COMPONENT_ID),
        "vehicle_estimator": (_to_vehicle_from_estimator, ESTIMATOR_COMPONENT_ID),
        "vehicle_bridge": (_to_vehicle_from_bridge, BRIDGE_COMPONENT_ID),
        "ground": (_to_vehicle_from_estimator, 190),
    }
    TARGETS = tuple(HOSTILE)

    POOL = 64  # signed hostile frames per target that the link-level classes are cut from

    def _pooled(self, target: str, signer: _Signer, system_id: int, component: int) -> bytes:
        """A frame from a small pool: link-level rejection does not need a fresh one (a repeat of
        a signed frame is a replay, which the link refuses too)."""
        key = (target, id(signer), system_id == 1, component)
        pool = self._pools.setdefault(key, [])
        if len(pool) < self.POOL:
            make, _ = self.HOSTILE[target]
            pool.append(signer.pack(make(self), system_id, component))
        return pool[int(self.rng.integers(len(pool)))]

    def one(self, target: str) -> Fuzz:
        make, component = self.HOSTILE[target]
        rng = self.rng
        cls = int(rng.integers(9))
        if cls == 0:  # random bytes
            return Fuzz(target, rng.bytes(int(rng.integers(1, 280))), "link", "random_bytes")
        if cls == 1:  # bit flips of a signed frame
            frame = bytearray(self._pooled(target, self.good, 1, component))
            for _ in range(int(rng.integers(1, 4))):
                k = int(rng.integers(len(frame) * 8))
                frame[k // 8] ^= 1 << (k % 8)
            return Fuzz(target, bytes(frame), "link", "bit_flips")
        if cls == 2:  # truncated
            frame = self._pooled(target, self.good, 1, component)
            return Fuzz(target, frame[: int(rng.integers(1, len(frame)))], "link", "truncated")
        if cls == 3:
            return Fuzz(target, self._pooled(target, self.unsigned, 1, component), "link", "unsigned")
        if cls == 4:
            return Fuzz(target, self._pooled(target, self.wrong, 1, component), "link", "wrong_key")
        if target == "ground" and cls in (5, 6):  # the ground port takes any system and component
            return Fuzz(target, self.good.pack(make(self), int(rng.integers(2, 255)), component), "ground",
                        "any_ids")
        if cls == 5:
            return Fuzz(target, self._pooled(target, self.good, 42, component), "link", "wrong_system_id")
        if cls == 6:
            return Fuzz(target, self._pooled(target, self.good, 1, (component + 1) % 256), "link",
                        "wrong_component_id")
        expect = "ground" if target == "ground" else "node"
        return Fuzz(target, self.good.pack(make(self), 1, component), expect, "hostile_values")

    def frames(self, n: int) -> list[Fuzz]:
        targets = self.rng.integers(len(self.TARGETS), size=n)
        return [self.one(self.TARGETS[int(k)]) for k in targets]
