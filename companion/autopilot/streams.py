"""What the companion asks the autopilot to send, and how.

First MAV_CMD_SET_MESSAGE_INTERVAL per message (ArduPilot and PX4 both honour it; ArduPilot
refuses more than 200 Hz at its default loop rate). If the IMU has not arrived
``fallback_after_s`` after asking, the legacy REQUEST_DATA_STREAM groups are asked for too
(RAW_SENSORS, EXTRA1, POSITION, EXTENDED_STATUS). Both are asked again after a reboot and
whenever the IMU stops for ``silence_s``.
"""

from __future__ import annotations

from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

US_PER_S = 1_000_000


@dataclass(frozen=True, slots=True)
class StreamRates:
    imu_hz: float = 50.0  # HIGHRES_IMU (50-200 Hz; the estimator holds each sample <= 50 ms)
    attitude_hz: float = 50.0  # ATTITUDE_QUATERNION
    # GPS_RAW_INT / GPS2_RAW: twice a 10 Hz receiver's rate, so no fix is missed (repeats are dropped)
    gnss_hz: float = 20.0
    system_time_hz: float = 1.0  # SYSTEM_TIME (boot time <-> UNIX time)
    position_hz: float = 10.0  # GLOBAL_POSITION_INT, LOCAL_POSITION_NED (the autopilot's own estimate)
    origin_hz: float = 1.0  # GPS_GLOBAL_ORIGIN, HOME_POSITION
    fallback_after_s: float = 3.0  # wall time without IMU before REQUEST_DATA_STREAM is tried too
    silence_s: float = 3.0  # wall time without IMU after which everything is asked again


def interval_requests(target_system: int, target_component: int, rates: StreamRates,
                      gnss_instance: int = 1) -> list[mavlink.MAVLink_command_long_message]:
    """One SET_MESSAGE_INTERVAL command per message the companion needs."""
    gnss_id = mavlink.MAVLINK_MSG_ID_GPS_RAW_INT if gnss_instance == 1 else mavlink.MAVLINK_MSG_ID_GPS2_RAW
    wanted = (
        (mavlink.MAVLINK_MSG_ID_HIGHRES_IMU, rates.imu_hz),
        (mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION, rates.attitude_hz),
        (gnss_id, rates.gnss_hz),
        (mavlink.MAVLINK_MSG_ID_SYSTEM_TIME, rates.system_time_hz),
        (mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, rates.position_hz),
        (mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED, rates.position_hz),
        (mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN, rates.origin_hz),
        (mavlink.MAVLINK_MSG_ID_HOME_POSITION, rates.origin_hz),
    )
    return [
        mavlink.MAVLink_command_long_message(
            target_system, target_component, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
            float(msg_id), float(round(US_PER_S / hz)), 0, 0, 0, 0, 0)
        for msg_id, hz in wanted
    ]


def data_stream_requests(target_system: int, target_component: int,
                         rates: StreamRates) -> list[mavlink.MAVLink_request_data_stream_message]:
    """The legacy REQUEST_DATA_STREAM groups carrying the same messages (RAW_IMU, ATTITUDE, ...)."""
    groups = (
        (mavlink.MAV_DATA_STREAM_RAW_SENSORS, rates.imu_hz),  # RAW_IMU, SCALED_IMU2
        (mavlink.MAV_DATA_STREAM_EXTRA1, rates.attitude_hz),  # ATTITUDE
        (mavlink.MAV_DATA_STREAM_EXTENDED_STATUS, rates.gnss_hz),  # GPS_RAW_INT, SYSTEM_TIME
        (mavlink.MAV_DATA_STREAM_POSITION, rates.position_hz),  # GLOBAL_POSITION_INT, LOCAL_POSITION_NED
    )
    return [
        mavlink.MAVLink_request_data_stream_message(target_system, target_component, group, round(hz), 1)
        for group, hz in groups
    ]
