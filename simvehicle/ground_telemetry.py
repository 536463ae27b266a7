"""What the vehicle tells a ground station, as an autopilot would: pure encoders of a snapshot.

:class:`VehicleStatus` is one control period's state as the autopilot knows it: its navigation
position and velocity (the companion's estimate it flies on, dead-reckoned while stale), the
attitude and body rates, the thrust command, armed flag and flight mode, and the health of
its inputs. Each ``encode_*`` turns it into one common.xml message, every field in the
message's own units and conventions (degE7, mm, cm/s, cdeg, "unknown" values as the spec
says). Nothing here does I/O; :mod:`simvehicle.groundlink` schedules and sends.

Geometry: the local NED frame is the mission's (origin = GPS_GLOBAL_ORIGIN, the mission home);
HOME_POSITION is the ground point under the flight's start (down = 0), so GLOBAL_POSITION_INT
``relative_alt`` is the height above that ground.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from companion.domain.geodesy import LocalNedFrame
from companion.domain.rotation import quaternion_to_euler, yaw_of
from companion.mavlink.codec import DEG_E7

UINT16_MAX = 65535
INT16_MAX = 32767
# What the vehicle has and uses (SYS_STATUS bits); the magnetometer and barometer are not simulated.
SENSORS_PRESENT = (
    mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO
    | mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    | mavlink.MAV_SYS_STATUS_SENSOR_GPS
    | mavlink.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
    | mavlink.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
    | mavlink.MAV_SYS_STATUS_SENSOR_YAW_POSITION
    | mavlink.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
    | mavlink.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
    | mavlink.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
    | mavlink.MAV_SYS_STATUS_AHRS
    | mavlink.MAV_SYS_STATUS_PREARM_CHECK
)
# healthy only while a fresh estimate is flown on (position control and prearm need a position)
_NEEDS_ESTIMATE = (
    mavlink.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
    | mavlink.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
    | mavlink.MAV_SYS_STATUS_PREARM_CHECK
)
FIRMWARE_VERSION = (0, 1, 0)  # beliefnav's version (major, minor, patch) in AUTOPILOT_VERSION
CAPABILITIES = (
    mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST  # all REAL32: same either way
    | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
)


@dataclass(frozen=True, slots=True)
class VehicleStatus:
    t_us: int  # boot time
    p_ned_m: np.ndarray  # the autopilot's navigation position (local NED)
    v_ned_m_s: np.ndarray
    q_ned_frd: np.ndarray  # attitude, body FRD -> NED, (w, x, y, z)
    rates_frd_rad_s: np.ndarray  # body rates (roll, pitch, yaw rate)
    thrust_fraction: float  # commanded thrust / maximum thrust, 0..1
    armed: bool
    mode: str  # a key of companion.mavlink.codec.CUSTOM_MODES
    estimate_ok: bool  # flying on a fresh estimate (False: holding on a stale one)
    gnss_ok: bool  # GNSS fixes are flowing (False: disabled or lost)


@dataclass(frozen=True, slots=True)
class Home:
    """Home (ground under the start) and the local frame whose origin is GPS_GLOBAL_ORIGIN."""

    frame: LocalNedFrame
    home_ned_m: np.ndarray

    def geodetic(self) -> tuple[float, float, float]:
        return self.frame.to_geodetic(self.home_ned_m)


def _clamp_int(value: float, limit: int) -> int:
    return max(-limit, min(limit, round(value)))


def _deg_e7(deg: float) -> int:
    return round(deg * DEG_E7)


def _heading_deg(q: np.ndarray) -> float:
    return math.degrees(yaw_of(q)) % 360.0


def encode_global_position(s: VehicleStatus, home: Home) -> mavlink.MAVLink_global_position_int_message:
    lat, lon, alt = home.frame.to_geodetic(s.p_ned_m)
    vn, ve, vd = (_clamp_int(c * 100, INT16_MAX) for c in s.v_ned_m_s)
    relative_m = float(home.home_ned_m[2] - s.p_ned_m[2])  # up from home
    hdg = round(_heading_deg(s.q_ned_frd) * 100) % 36000
    return mavlink.MAVLink_global_position_int_message(
        s.t_us // 1000, _deg_e7(lat), _deg_e7(lon), round(alt * 1000), round(relative_m * 1000),
        vn, ve, vd, hdg,
    )


def encode_local_position(s: VehicleStatus) -> mavlink.MAVLink_local_position_ned_message:
    p, v = s.p_ned_m, s.v_ned_m_s
    return mavlink.MAVLink_local_position_ned_message(s.t_us // 1000, p[0], p[1], p[2], v[0], v[1], v[2])


def encode_attitude_euler(s: VehicleStatus) -> mavlink.MAVLink_attitude_message:
    roll, pitch, yaw = quaternion_to_euler(s.q_ned_frd)
    w = s.rates_frd_rad_s
    return mavlink.MAVLink_attitude_message(s.t_us // 1000, roll, pitch, yaw, w[0], w[1], w[2])


def encode_attitude_quaternion(s: VehicleStatus) -> mavlink.MAVLink_attitude_quaternion_message:
    q, w = s.q_ned_frd, s.rates_frd_rad_s
    return mavlink.MAVLink_attitude_quaternion_message(
        s.t_us // 1000, q[0], q[1], q[2], q[3], w[0], w[1], w[2], [0.0, 0.0, 0.0, 0.0])  # no display offset


def encode_vfr_hud(s: VehicleStatus, home: Home) -> mavlink.MAVLink_vfr_hud_message:
    """No wind is simulated, so airspeed = ground speed; throttle = commanded thrust in %."""
    _, _, alt = home.frame.to_geodetic(s.p_ned_m)
    speed = math.hypot(float(s.v_ned_m_s[0]), float(s.v_ned_m_s[1]))
    throttle = max(0, min(100, round(100.0 * s.thrust_fraction)))
    return mavlink.MAVLink_vfr_hud_message(
        speed, speed, round(_heading_deg(s.q_ned_frd)) % 360, throttle, alt, -float(s.v_ned_m_s[2]))


def encode_home_position(home: Home, t_us: int) -> mavlink.MAVLink_home_position_message:
    lat, lon, alt = home.geodetic()
    h = home.home_ned_m
    # q: the ground is level, heading north (identity); approach vector: none (0, 0, 0)
    return mavlink.MAVLink_home_position_message(
        _deg_e7(lat), _deg_e7(lon), round(alt * 1000), h[0], h[1], h[2], [1.0, 0.0, 0.0, 0.0],
        0.0, 0.0, 0.0, t_us)


def encode_gps_global_origin(home: Home, t_us: int) -> mavlink.MAVLink_gps_global_origin_message:
    f = home.frame
    return mavlink.MAVLink_gps_global_origin_message(
        _deg_e7(f.home_lat_deg), _deg_e7(f.home_lon_deg), round(f.home_alt_m * 1000), t_us)


def encode_extended_sys_state() -> mavlink.MAVLink_extended_sys_state_message:
    """Not a VTOL; always in the air (the flight starts hovering and never lands)."""
    return mavlink.MAVLink_extended_sys_state_message(
        mavlink.MAV_VTOL_STATE_UNDEFINED, mavlink.MAV_LANDED_STATE_IN_AIR)


def sensor_health(s: VehicleStatus) -> int:
    health = SENSORS_PRESENT
    if not s.gnss_ok:
        health &= ~mavlink.MAV_SYS_STATUS_SENSOR_GPS
    if not s.estimate_ok:
        health &= ~_NEEDS_ESTIMATE
    return health


def encode_sys_status(s: VehicleStatus, drop_rate_c_percent: int) -> mavlink.MAVLink_sys_status_message:
    """Sensor bits as above; battery not simulated (UINT16_MAX / -1 = not sent, as the spec says)."""
    return mavlink.MAVLink_sys_status_message(
        SENSORS_PRESENT, SENSORS_PRESENT, sensor_health(s), 0, UINT16_MAX, -1, -1,
        max(0, min(10_000, drop_rate_c_percent)), 0, 0, 0, 0, 0)


def encode_autopilot_version() -> mavlink.MAVLink_autopilot_version_message:
    major, minor, patch = FIRMWARE_VERSION
    version = (major << 24) | (minor << 16) | (patch << 8) | mavlink.FIRMWARE_VERSION_TYPE_DEV
    zeros8 = [0] * 8
    return mavlink.MAVLink_autopilot_version_message(
        CAPABILITIES, version, 0, 0, 0, zeros8, zeros8, zeros8, 0, 0, 0)  # no hardware UID


def encode_statustext(severity: int, text: str) -> mavlink.MAVLink_statustext_message:
    raw = text.encode("ascii", errors="replace")[:50]
    return mavlink.MAVLink_statustext_message(severity, raw)
