"""A synthetic autopilot at rest at home, as frames (PX4-like streams), for the hardening tests:
its own messages, and forged ones with its ids. Time = its boot time = our clock (x1), seconds."""

from __future__ import annotations

import math
from collections.abc import Iterator

from pymavlink.dialects.v20 import common as mavlink

HOME = (47.397742, 8.545594, 488.0)  # lat deg, lon deg, alt m (PX4 SITL's Zurich home)
UNIX0_US = 1_700_000_000_000_000  # UNIX time at boot 0
G = 9.80665
IMU_FIELDS = 0b111111


def packed(msg: mavlink.MAVLink_message, system_id: int = 1, component_id: int = 1,
           seq: int = 0) -> mavlink.MAVLink_message:
    """``msg`` packed as (system, component): its sender ids and bytes set, as if received."""
    link = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
    link.seq = seq & 0xFF
    msg.pack(link)
    return msg


def heartbeat(autopilot: int = mavlink.MAV_AUTOPILOT_PX4,
              vehicle: int = mavlink.MAV_TYPE_QUADROTOR) -> mavlink.MAVLink_heartbeat_message:
    return mavlink.MAVLink_heartbeat_message(vehicle, autopilot, 0, 0, mavlink.MAV_STATE_STANDBY, 3)


def imu(t_us: int, acc_z: float = -G, acc_y: float = 0.0) -> mavlink.MAVLink_highres_imu_message:
    return mavlink.MAVLink_highres_imu_message(t_us, 0.0, acc_y, acc_z, 0.0, 0.0, 0.0, 0, 0, 0, 0, 0, 0, 0,
                                               IMU_FIELDS, 0)


def attitude(t_us: int) -> mavlink.MAVLink_attitude_quaternion_message:
    return mavlink.MAVLink_attitude_quaternion_message(t_us // 1000, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                                                       [0.0, 0.0, 0.0, 0.0])


def gps(t_us: int, lat: float = HOME[0], lon: float = HOME[1], alt: float = HOME[2],
        fix_type: int = 3) -> mavlink.MAVLink_gps_raw_int_message:
    return mavlink.MAVLink_gps_raw_int_message(t_us, fix_type, round(lat * 1e7), round(lon * 1e7),
                                               round(alt * 1000), 80, 120, 0, 0, 12, 0, 500, 800, 0, 0, 0)


def system_time(t_us: int, unix_us: int | None = None) -> mavlink.MAVLink_system_time_message:
    return mavlink.MAVLink_system_time_message(UNIX0_US + t_us if unix_us is None else unix_us, t_us // 1000)


def global_position(t_us: int) -> mavlink.MAVLink_global_position_int_message:
    return mavlink.MAVLink_global_position_int_message(
        t_us // 1000, round(HOME[0] * 1e7), round(HOME[1] * 1e7), round(HOME[2] * 1000), 0, 0, 0, 0, 0)


def stream(t0_s: float, t1_s: float, system_id: int = 1) -> Iterator[tuple[float, mavlink.MAVLink_message]]:
    """(time s, packed message) in time order: HEARTBEAT and SYSTEM_TIME 1 Hz, HIGHRES_IMU and
    ATTITUDE_QUATERNION 50 Hz, GPS_RAW_INT and GLOBAL_POSITION_INT 10 Hz."""
    seq = 0
    for k in range(math.ceil(t0_s * 50), math.floor(t1_s * 50) + 1):
        t_us = k * 20_000
        msgs = [attitude(t_us), imu(t_us)]
        if k % 5 == 0:
            msgs += [gps(t_us), global_position(t_us)]
        if k % 50 == 0:
            msgs += [heartbeat(), system_time(t_us)]
        for m in msgs:
            seq += 1
            yield t_us / 1e6, packed(m, system_id, 1, seq)
