"""MAVLink 2 (common dialect) <-> domain types: the one translation layer for the UDP link and tlogs.

``encode_*`` build pymavlink message objects (pack them with :func:`pack`); ``decode_*`` read any
object with the message's field names as attributes — a pymavlink message or the lightweight
views of :mod:`companion.mavlink.tlog`. Decoders never pass on a non-finite or out-of-range value:
they raise :class:`CodecError`, whose ``reason`` the caller counts.

Units and conventions on the wire:

- HIGHRES_IMU: ``time_usec`` boot time; body-FRD specific force (m/s²) and rate (rad/s).
- ATTITUDE_QUATERNION: ``q1..q4`` = w, x, y, z, body FRD -> NED; ``time_boot_ms`` (ms); body rates
  NaN (not carried), ``repr_offset_q`` zeros (not supported).
- GPS_RAW_INT: ``time_usec`` = VALIDITY time (when the fix was true), so in arrival order it may
  go backwards: a fix with less latency can overtake an older one (the simulated latency varies
  by up to 1.2 s); receivers order by it, not by arrival. lat/lon degE7, alt mm; ``eph`` = HDOP
  x 100 (65535 unknown -> NaN); ``h_acc``/``v_acc`` mm (0 = not sent -> NaN);
  ``satellites_visible`` passed through (255 = unknown, as MAVLink says); ``vel`` (cm/s) and
  ``cog`` (cdeg) = the horizontal velocity (65535 unknown -> none; the vertical is not carried:
  NaN), ``vel_acc`` mm/s its accuracy. GPS2_RAW the same; GPS_INPUT and HIL_GPS (decode only)
  carry a full NED velocity (GPS_INPUT m/s, each part unless ``ignore_flags`` says unset; HIL_GPS
  cm/s).
- SIM_STATE: no time field (the caller supplies the matching IMU time); position as
  ``lat_int``/``lon_int`` degE7 (float ``lat``/``lon`` too, in degrees) and ``alt`` m, converted
  with a :class:`LocalNedFrame`. It carries p, v, q only: bias, latency and clearance of a
  decoded :class:`TruthState` are NaN (unknown), never a made-up zero.
- ODOMETRY: LOCAL_NED position and NED velocity (``child_frame_id`` = LOCAL_NED), variances on
  the covariance diagonals (off-diagonals 0). Attitude is not estimated: ``q`` = (NaN, 0, 0, 0)
  (NaN first = unknown, as the covariances' convention) and the attitude/rate variances are
  +inf (no information), so ``pose_covariance[0]`` stays a real variance. ``quality`` as the spec
  defines it: -1 while the estimate is not valid (``pos_valid`` False), else 0 (unknown/unset).
  β and NIS travel in NAMED_VALUE_FLOAT ``GNSS_BETA``/``GNSS_NIS`` and ESTIMATOR_STATUS, the
  estimated bias in DEBUG_VECT ``GNSS_BIAS`` (x, y, z = north, east, down, m; ``time_usec`` boot
  time), so a decoded ODOMETRY has NaN β, bias and NIS.
- ESTIMATOR_STATUS: ``flags`` say which outputs are valid now (velocity and position only while
  ``pos_valid``; ``GPS_GLITCH`` while GNSS is rejected by the innovation gate);
  ``pos_horiz_ratio`` = the estimator's last horizontal GNSS innovation test ratio (NIS /
  gate²), NaN until a fix was tested; ``vel_ratio`` the same for the receiver's velocity (NaN when
  the last fix had none); ``ACCEL_ERROR`` while the IMU-propagated motion disagrees with the GNSS
  velocity; ratios of tests we never make (vertical, magnetometer, height above terrain, airspeed)
  are NaN ("not computed"), never 0 ("perfect").
- SET_POSITION_TARGET_LOCAL_NED: LOCAL_NED, ``time_boot_ms`` (ms); velocity/acceleration marked
  ignored in ``type_mask`` decode as zero feed-forward; ignored position is an error.
- RAW_IMU / SCALED_IMU (decode only): acceleration mg, rate mrad/s, body FRD.
- ATTITUDE (decode only): ZYX Euler roll/pitch/yaw (rad).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

os.environ.setdefault("MAVLINK20", "1")

import numpy as np  # noqa: E402
from pymavlink.dialects.v20 import common as mavlink  # noqa: E402

from companion.domain.geodesy import LocalNedFrame  # noqa: E402
from companion.domain.physics import (  # noqa: E402
    MAX_PRESSURE_ALT_M,
    MAX_SPECIFIC_FORCE_M_S2,
    STANDARD_GRAVITY_M_S2,
)
from companion.domain.rotation import euler_to_quaternion, normalised, quaternion_to_euler  # noqa: E402
from companion.domain.samples import (  # noqa: E402
    AttitudeSample,
    GnssFix,
    ImuSample,
    NavEstimate,
    Setpoint,
    TruthState,
)

UINT16_UNKNOWN = 65535
DEG_E7 = 1e7
QUAT_NORM_TOLERANCE = 0.05  # |‖q‖ - 1| beyond this is a corrupt attitude, not rounding
IMU_FIELDS_ACC_GYRO = 0b111111  # HIGHRES_IMU fields_updated bits for xacc..zgyro
# HIGHRES_IMU fields_updated bits (HIGHRES_IMU_UPDATED_FLAGS): abs_pressure, pressure_alt, temperature
IMU_FIELD_ABS_PRESSURE = 1 << 9
IMU_FIELD_PRESSURE_ALT = 1 << 11
IMU_FIELD_TEMPERATURE = 1 << 12
BELIEF_NAME = "GNSS_BETA"
NIS_NAME = "GNSS_NIS"
BIAS_NAME = "GNSS_BIAS"  # DEBUG_VECT: the estimated GNSS bias, x/y/z = north/east/down [m]
_NAN3 = (math.nan, math.nan, math.nan)
_SETPOINT_TYPE_MASK = (
    mavlink.POSITION_TARGET_TYPEMASK_YAW_IGNORE | mavlink.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
)
_VEL_IGNORE = 0b000111000
_ACC_IGNORE = 0b111000000
_POS_IGNORE = 0b000000111
# Upper-triangle (row-major) indices of the diagonal of a 6x6 covariance, as ODOMETRY packs it.
_COV6_DIAG = (0, 6, 11, 15, 18, 20)
ESTIMATOR_HEALTHY_FLAGS = (
    mavlink.ESTIMATOR_VELOCITY_HORIZ
    | mavlink.ESTIMATOR_VELOCITY_VERT
    | mavlink.ESTIMATOR_POS_HORIZ_REL
    | mavlink.ESTIMATOR_POS_HORIZ_ABS
    | mavlink.ESTIMATOR_POS_VERT_ABS
)
ODOMETRY_QUALITY_FAILED = -1  # ODOMETRY.quality: -1 = failed, 0 = unknown/unset (spec)
ODOMETRY_QUALITY_UNKNOWN = 0
# The vehicle identifies as PX4-compatible so that ground stations (QGroundControl, MAVSDK,
# MAVProxy) decode its custom mode with PX4's layout (main mode in bits 16-23, sub mode in
# 24-31); it is not PX4: see docs/groundstation.md. Companions are not autopilots (INVALID).
ROLE_TYPES = {  # HEARTBEAT (type, autopilot) per process role
    "vehicle": (mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4),
    "companion": (mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID),
}
PX4_MAIN_MODE_AUTO = 4
PX4_MAIN_MODE_OFFBOARD = 6
PX4_AUTO_SUB_MODE_LOITER = 3
CUSTOM_MODES = {  # our flight modes -> HEARTBEAT custom_mode (PX4 layout)
    "OFFBOARD": PX4_MAIN_MODE_OFFBOARD << 16,  # flying the companion's setpoints on its estimate
    "HOLD": (PX4_MAIN_MODE_AUTO << 16) | (PX4_AUTO_SUB_MODE_LOITER << 24),  # holding a point
}
VEHICLE_BASE_MODE = (  # HEARTBEAT base_mode of the flying vehicle (SAFETY_ARMED added when armed)
    mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    | mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED
    | mavlink.MAV_MODE_FLAG_GUIDED_ENABLED
)


@dataclass(frozen=True, slots=True)
class WireLimits:
    """What a decoded (or encoded) value may be; beyond it the frame is rejected as ``out_of_range``.

    Generous for any real quadrotor, tight enough that an absurd value never reaches a filter,
    the autopilot or a packer (whose fixed-size integer fields would overflow).
    """

    max_specific_force_m_s2: float = MAX_SPECIFIC_FORCE_M_S2  # |f| per axis: 16 g (IMU full scale)
    max_rate_rad_s: float = 35.0  # |ω| per axis: 2000 °/s gyro full scale
    max_home_distance_m: float = 50_000.0  # positions (local NED, or a fix) this close to home
    max_speed_m_s: float = 200.0  # |v| per axis
    max_accel_m_s2: float = 200.0  # setpoint feed-forward |a| per axis
    max_variance: float = 1e12  # ODOMETRY covariance diagonal (m², (m/s)²)
    max_stamp_us: int = 2**62  # µs stamps (int64 headroom); ms stamps must fit uint32 when sent
    max_pressure_alt_m: float = MAX_PRESSURE_ALT_M  # |pressure altitude| (m)


LIMITS = WireLimits()
UINT32_MAX = 2**32 - 1
FLOAT32_MAX = 3.4028234663852886e38


class CodecError(ValueError):
    """A message that cannot be turned into a domain value; ``reason`` is a stable counter name."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f"{reason}: {detail}")
        self.reason = reason


# --- wire-only records (no domain type of their own) ---------------------------------------


@dataclass(frozen=True, slots=True)
class EstimatorStatus:
    """ESTIMATOR_STATUS: health flags, NIS over its gate, 1-σ accuracies."""

    t_us: int
    flags: int
    pos_horiz_ratio: float  # NIS / gate (χ² threshold): > 1 means the fix failed the gate; NaN: no test
    pos_horiz_accuracy_m: float
    pos_vert_accuracy_m: float
    vel_ratio: float = math.nan  # the same for the receiver's horizontal velocity (NaN: none tested)


@dataclass(frozen=True, slots=True)
class NamedValue:
    """NAMED_VALUE_FLOAT, e.g. ``GNSS_BETA`` or ``GNSS_NIS``."""

    t_us: int
    name: str
    value: float


@dataclass(frozen=True, slots=True)
class Heartbeat:
    mav_type: int
    autopilot: int
    system_status: int
    base_mode: int = 0
    custom_mode: int = 0

    @property
    def armed(self) -> bool:
        return bool(self.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)


@dataclass(frozen=True, slots=True)
class ClockPair:
    """SYSTEM_TIME: pairs the sender's UNIX (or simulated) clock with its boot time."""

    time_unix_us: int
    t_boot_us: int


# --- link helpers ----------------------------------------------------------------------------


def new_link(system_id: int, component_id: int) -> mavlink.MAVLink:
    """A MAVLink 2 packer/parser (no file); use with :func:`pack` and ``parse_buffer``."""
    link = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
    link.robust_parsing = True
    return link


def pack(link: mavlink.MAVLink, msg: mavlink.MAVLink_message) -> bytes:
    """Serialise ``msg`` as one MAVLink 2 frame and advance the link's sequence number."""
    frame = msg.pack(link)
    link.seq = (link.seq + 1) % 256
    return frame


# --- checks ----------------------------------------------------------------------------------


def _finite(name: str, *values: float) -> None:
    for v in values:
        if not math.isfinite(v):
            raise CodecError("non_finite", f"{name} has a non-finite field")


def _vec(name: str, x: float, y: float, z: float) -> np.ndarray:
    if not math.isfinite(x + y + z):  # NaN/inf in any term (float32 inputs cannot overflow)
        raise CodecError("non_finite", f"{name} has a non-finite field")
    return np.array((x, y, z), dtype=float)


def _bounded(name: str, bound: float, x: float, y: float, z: float) -> np.ndarray:
    v = _vec(name, x, y, z)
    if not max(abs(x), abs(y), abs(z)) <= bound:
        raise CodecError("out_of_range", f"{name} beyond {bound:g}")
    return v


def _ms_stamp(name: str, t_us: int) -> None:
    if not 0 <= t_us // 1000 <= UINT32_MAX:
        raise CodecError("bad_stamp", f"{name} stamp {t_us} µs beyond uint32 ms")


def _stamp_us(name: str, t_us: int) -> int:
    t = int(t_us)
    if not 0 <= t <= LIMITS.max_stamp_us:
        raise CodecError("bad_stamp", f"{name} stamp {t} µs")
    return t


def _unit_quaternion(name: str, w: float, x: float, y: float, z: float) -> np.ndarray:
    norm, q = normalised(w, x, y, z)
    if not abs(norm - 1.0) <= QUAT_NORM_TOLERANCE:  # also catches NaN
        if not math.isfinite(norm):
            raise CodecError("non_finite", f"{name} has a non-finite field")
        raise CodecError("out_of_range", f"{name} quaternion norm {norm:.3f}")
    return np.array(q)


def _lat_lon(name: str, lat_deg: float, lon_deg: float) -> None:
    if not (-90.0 <= lat_deg <= 90.0 and -180.0 <= lon_deg <= 180.0):
        raise CodecError("out_of_range", f"{name} lat/lon {lat_deg:.7f},{lon_deg:.7f}")


def _text(raw: str | bytes) -> str:
    if isinstance(raw, bytes):
        return raw.split(b"\x00", 1)[0].decode("ascii", errors="replace")
    return raw


# --- estimator inputs ---------------------------------------------------------------------------


def encode_imu(s: ImuSample, abs_pressure_hpa: float = math.nan, temperature_c: float = math.nan
               ) -> mavlink.MAVLink_highres_imu_message:
    """HIGHRES_IMU: acceleration and rates; with a barometer (``s.pressure_alt_m``) its pressure altitude,
    and the absolute pressure and temperature when given (finite), each with its fields_updated bit."""
    a, g = s.acc_frd_m_s2, s.gyro_frd_rad_s
    flags = IMU_FIELDS_ACC_GYRO
    alt = 0.0 if s.pressure_alt_m is None else s.pressure_alt_m
    flags |= 0 if s.pressure_alt_m is None else IMU_FIELD_PRESSURE_ALT
    hpa = abs_pressure_hpa if math.isfinite(abs_pressure_hpa) else 0.0
    flags |= IMU_FIELD_ABS_PRESSURE if math.isfinite(abs_pressure_hpa) else 0
    temp = temperature_c if math.isfinite(temperature_c) else 0.0
    flags |= IMU_FIELD_TEMPERATURE if math.isfinite(temperature_c) else 0
    return mavlink.MAVLink_highres_imu_message(
        s.t_us, a[0], a[1], a[2], g[0], g[1], g[2], 0.0, 0.0, 0.0, hpa, 0.0, alt, temp,
        flags, 0,
    )


def decode_imu(m: Any) -> ImuSample:
    """HIGHRES_IMU; its pressure altitude passed on when fields_updated says so (bit 11): a value not finite
    or beyond ``max_pressure_alt_m`` is passed as NaN (the tight filter counts it, uses nothing), the IMU
    sample kept. Without bit 11 (a log of fields_updated 63 and a constant 1013.25 hPa) there is none."""
    if m.fields_updated & IMU_FIELDS_ACC_GYRO != IMU_FIELDS_ACC_GYRO:
        raise CodecError("fields_not_updated", f"HIGHRES_IMU fields_updated={m.fields_updated:#x}")
    alt = None
    if m.fields_updated & IMU_FIELD_PRESSURE_ALT:
        alt = float(m.pressure_alt)
        alt = alt if abs(alt) <= LIMITS.max_pressure_alt_m else math.nan  # (NaN fails the comparison too)
    return ImuSample(
        _stamp_us("HIGHRES_IMU", m.time_usec),
        _bounded("HIGHRES_IMU acc", LIMITS.max_specific_force_m_s2, m.xacc, m.yacc, m.zacc),
        _bounded("HIGHRES_IMU gyro", LIMITS.max_rate_rad_s, m.xgyro, m.ygyro, m.zgyro),
        alt,
    )


def _decode_scaled(t_us: int, m: Any) -> ImuSample:
    mg = STANDARD_GRAVITY_M_S2 / 1000.0
    return ImuSample(
        _stamp_us("IMU", t_us),
        _bounded("IMU acc", LIMITS.max_specific_force_m_s2, m.xacc * mg, m.yacc * mg, m.zacc * mg),
        _bounded("IMU gyro", LIMITS.max_rate_rad_s, m.xgyro * 1e-3, m.ygyro * 1e-3, m.zgyro * 1e-3),
    )


def decode_raw_imu(m: Any) -> ImuSample:
    """RAW_IMU as ArduPilot sends it: mg and mrad/s, body FRD, ``time_usec``."""
    return _decode_scaled(int(m.time_usec), m)


def decode_scaled_imu(m: Any) -> ImuSample:
    """SCALED_IMU: mg and mrad/s, body FRD, ``time_boot_ms``."""
    return _decode_scaled(int(m.time_boot_ms) * 1000, m)


def encode_attitude(s: AttitudeSample) -> mavlink.MAVLink_attitude_quaternion_message:
    """Attitude only: the body rates are not carried (NaN, unknown; HIGHRES_IMU has the measured
    ones); ``repr_offset_q`` all zero = not supported, as the spec says."""
    q = s.q_ned_frd
    nan = math.nan
    return mavlink.MAVLink_attitude_quaternion_message(
        s.t_us // 1000, q[0], q[1], q[2], q[3], nan, nan, nan, [0.0, 0.0, 0.0, 0.0]
    )


def decode_attitude(m: Any) -> AttitudeSample:
    return AttitudeSample(
        _stamp_us("ATTITUDE_QUATERNION", int(m.time_boot_ms) * 1000),
        _unit_quaternion("ATTITUDE_QUATERNION", m.q1, m.q2, m.q3, m.q4),
    )


def decode_attitude_euler(m: Any) -> AttitudeSample:
    _finite("ATTITUDE", m.roll, m.pitch, m.yaw)
    return AttitudeSample(_stamp_us("ATTITUDE", int(m.time_boot_ms) * 1000),
                          np.array(euler_to_quaternion(m.roll, m.pitch, m.yaw)))


def _mm(value_m: float) -> int:
    return 0 if not math.isfinite(value_m) else max(1, min(2**32 - 1, round(value_m * 1000.0)))


def _speed_course(v_ned_m_s: np.ndarray | None) -> tuple[int, int]:
    """GPS_RAW_INT ``vel`` (ground speed, cm/s) and ``cog`` (course over ground, cdeg 0..35999) of a
    NED velocity; unknown (UINT16_MAX) without a horizontal velocity. A speed too slow to give a
    course (< 0.5 cm/s) is sent as 0 with course 0."""
    if v_ned_m_s is None or not (math.isfinite(v_ned_m_s[0]) and math.isfinite(v_ned_m_s[1])):
        return UINT16_UNKNOWN, UINT16_UNKNOWN
    speed_cm_s = round(math.hypot(v_ned_m_s[0], v_ned_m_s[1]) * 100.0)
    if speed_cm_s == 0:
        return 0, 0
    course_cdeg = round(math.degrees(math.atan2(v_ned_m_s[1], v_ned_m_s[0])) * 100.0) % 36000
    return min(UINT16_UNKNOWN - 1, speed_cm_s), course_cdeg


def encode_gnss(f: GnssFix) -> mavlink.MAVLink_gps_raw_int_message:
    """GPS_RAW_INT of ``f``: its horizontal velocity as ``vel``/``cog`` (the vertical has no field),
    its speed accuracy as ``vel_acc``."""
    eph = UINT16_UNKNOWN
    if math.isfinite(f.hdop):
        eph = max(0, min(UINT16_UNKNOWN - 1, round(f.hdop * 100)))
    vel, cog = _speed_course(f.v_ned_m_s)
    return mavlink.MAVLink_gps_raw_int_message(
        f.t_validity_us, f.fix_type, round(f.lat_deg * DEG_E7), round(f.lon_deg * DEG_E7),
        round(f.alt_m * 1000.0), eph, UINT16_UNKNOWN, vel, cog,
        f.satellites_visible, 0, _mm(f.h_acc_m), _mm(f.v_acc_m), _mm(f.vel_acc_m_s), 0, 0,
    )


def _ground_velocity(name: str, vel_cm_s: int, cog_cdeg: int) -> np.ndarray | None:
    """NED velocity (vertical NaN: not reported) from ground speed and course; None when either is
    unknown (UINT16_MAX), except a speed of 0 (no course needed)."""
    if vel_cm_s == UINT16_UNKNOWN or (cog_cdeg == UINT16_UNKNOWN and vel_cm_s != 0):
        return None
    if cog_cdeg != UINT16_UNKNOWN and not 0 <= cog_cdeg <= 36000:
        raise CodecError("out_of_range", f"{name} cog {cog_cdeg}")
    speed, course = vel_cm_s / 100.0, math.radians((cog_cdeg if cog_cdeg != UINT16_UNKNOWN else 0) / 100.0)
    if speed > LIMITS.max_speed_m_s:
        raise CodecError("out_of_range", f"{name} vel {speed:.0f} m/s")
    return np.array([speed * math.cos(course), speed * math.sin(course), math.nan])


def _accuracy_m(value_mm: int) -> float:
    """A packed accuracy (mm or mm/s; 0 = not sent) in m or m/s, NaN when not sent."""
    return value_mm / 1000.0 if value_mm else math.nan


def decode_gnss(m: Any) -> GnssFix:
    """GPS_RAW_INT or GPS2_RAW (the same fields): ground speed and course as the horizontal
    velocity (no vertical: NaN), ``vel_acc`` as its accuracy."""
    name = m.get_type()
    lat_deg, lon_deg = m.lat / DEG_E7, m.lon / DEG_E7
    _lat_lon(name, lat_deg, lon_deg)
    return GnssFix(
        t_validity_us=_stamp_us(name, m.time_usec),
        lat_deg=lat_deg,
        lon_deg=lon_deg,
        alt_m=m.alt / 1000.0,
        fix_type=int(m.fix_type),
        satellites_visible=int(m.satellites_visible),
        h_acc_m=_accuracy_m(m.h_acc),
        v_acc_m=_accuracy_m(m.v_acc),
        hdop=m.eph / 100.0 if m.eph != UINT16_UNKNOWN else math.nan,
        v_ned_m_s=_ground_velocity(name, int(m.vel), int(m.cog)),
        vel_acc_m_s=_accuracy_m(getattr(m, "vel_acc", 0)),
    )


def decode_gps_input(m: Any) -> GnssFix:
    """GPS_INPUT (a fix handed to an autopilot): ``vn``/``ve``/``vd`` (m/s) and the accuracies (m,
    m/s) unless its ``ignore_flags`` say they are not set; ``alt`` m MSL; ``time_usec`` as sent."""
    ign = int(m.ignore_flags)
    lat_deg, lon_deg = m.lat / DEG_E7, m.lon / DEG_E7
    _lat_lon("GPS_INPUT", lat_deg, lon_deg)
    _finite("GPS_INPUT", m.alt)
    nan = math.nan
    v = [nan, nan, nan]
    if not ign & mavlink.GPS_INPUT_IGNORE_FLAG_VEL_HORIZ:
        v[0:2] = _bounded("GPS_INPUT velocity", LIMITS.max_speed_m_s, m.vn, m.ve, 0.0)[0:2].tolist()
    if not ign & mavlink.GPS_INPUT_IGNORE_FLAG_VEL_VERT:
        v[2] = float(_bounded("GPS_INPUT velocity", LIMITS.max_speed_m_s, 0.0, 0.0, m.vd)[2])

    def given(flag: int, value: float) -> float:
        return float(value) if not ign & flag and math.isfinite(value) and value > 0 else nan

    return GnssFix(
        t_validity_us=_stamp_us("GPS_INPUT", m.time_usec),
        lat_deg=lat_deg, lon_deg=lon_deg, alt_m=float(m.alt),
        fix_type=int(m.fix_type), satellites_visible=int(m.satellites_visible),
        h_acc_m=given(mavlink.GPS_INPUT_IGNORE_FLAG_HORIZONTAL_ACCURACY, m.horiz_accuracy),
        v_acc_m=given(mavlink.GPS_INPUT_IGNORE_FLAG_VERTICAL_ACCURACY, m.vert_accuracy),
        hdop=given(mavlink.GPS_INPUT_IGNORE_FLAG_HDOP, m.hdop),
        v_ned_m_s=None if all(math.isnan(c) for c in v) else np.array(v),
        vel_acc_m_s=given(mavlink.GPS_INPUT_IGNORE_FLAG_SPEED_ACCURACY, m.speed_accuracy),
    )


def decode_hil_gps(m: Any) -> GnssFix:
    """HIL_GPS (a simulator's fix): ``vn``/``ve``/``vd`` cm/s as the NED velocity, ``eph`` = HDOP x 100."""
    lat_deg, lon_deg = m.lat / DEG_E7, m.lon / DEG_E7
    _lat_lon("HIL_GPS", lat_deg, lon_deg)
    return GnssFix(
        t_validity_us=_stamp_us("HIL_GPS", m.time_usec),
        lat_deg=lat_deg, lon_deg=lon_deg, alt_m=m.alt / 1000.0,
        fix_type=int(m.fix_type), satellites_visible=int(m.satellites_visible),
        hdop=m.eph / 100.0 if m.eph != UINT16_UNKNOWN else math.nan,
        v_ned_m_s=_bounded("HIL_GPS velocity", LIMITS.max_speed_m_s, m.vn / 100.0, m.ve / 100.0,
                           m.vd / 100.0),
    )


# GNSS fixes by message name (the autopilot adapter picks its source among them).
GNSS_DECODERS: dict[str, Callable[[Any], GnssFix]] = {
    "GPS_RAW_INT": decode_gnss, "GPS2_RAW": decode_gnss, "GPS_INPUT": decode_gps_input,
    "HIL_GPS": decode_hil_gps,
}


# Estimator inputs by message name; decode_sample dispatches on these.
SAMPLE_DECODERS: dict[str, Callable[[Any], ImuSample | AttitudeSample | GnssFix]] = {
    "HIGHRES_IMU": decode_imu,
    "RAW_IMU": decode_raw_imu,
    "SCALED_IMU": decode_scaled_imu,
    "ATTITUDE_QUATERNION": decode_attitude,
    "ATTITUDE": decode_attitude_euler,
    "GPS_RAW_INT": decode_gnss,
}


def decode_sample(m: Any, home: LocalNedFrame | None = None) -> ImuSample | AttitudeSample | GnssFix | None:
    """The estimator input a message carries, None if it carries none; CodecError if it is bad.
    With ``home``, a fix farther than ``LIMITS.max_home_distance_m`` from it is ``out_of_range``."""
    decoder = SAMPLE_DECODERS.get(m.get_type())
    if decoder is None:
        return None
    sample = decoder(m)
    if home is not None and isinstance(sample, GnssFix):
        d_m = float(np.linalg.norm(home.to_ned_m(sample.lat_deg, sample.lon_deg, sample.alt_m)))
        if not d_m <= LIMITS.max_home_distance_m:
            raise CodecError("out_of_range", f"GPS_RAW_INT {d_m:.0f} m from home")
    return sample


# --- truth ------------------------------------------------------------------------------------


def encode_truth(s: TruthState, frame: LocalNedFrame,
                 to_geodetic: Callable[[np.ndarray], tuple[float, float, float]] | None = None,
                 ) -> mavlink.MAVLink_sim_state_message:
    """SIM_STATE of ``s``; ``to_geodetic`` (default ``frame.to_geodetic``) may be a faster
    converter of the same frame, e.g. the vehicle's ``simvehicle.gnss.NedToGeodetic``."""
    lat, lon, alt = (to_geodetic or frame.to_geodetic)(s.p_ned_m)
    q, v = s.q_ned_frd, s.v_ned_m_s
    roll, pitch, yaw = quaternion_to_euler(q)
    nan = math.nan
    return mavlink.MAVLink_sim_state_message(
        q[0], q[1], q[2], q[3], roll, pitch, yaw, nan, nan, nan, nan, nan, nan,
        lat, lon, alt, 0.0, 0.0, v[0], v[1], v[2], round(lat * DEG_E7), round(lon * DEG_E7),
    )


def decode_truth(m: Any, frame: LocalNedFrame, t_us: int) -> TruthState:
    """SIM_STATE has no time: ``t_us`` is that of the IMU sample sent in the same tick."""
    if m.lat_int or m.lon_int:
        lat, lon = m.lat_int / DEG_E7, m.lon_int / DEG_E7
    else:
        lat, lon = float(m.lat), float(m.lon)
    _finite("SIM_STATE", lat, lon, m.alt)
    _lat_lon("SIM_STATE", lat, lon)
    return TruthState(
        t_us=t_us,
        p_ned_m=frame.to_ned_m(lat, lon, m.alt),
        v_ned_m_s=_vec("SIM_STATE velocity", m.vn, m.ve, m.vd),
        q_ned_frd=_unit_quaternion("SIM_STATE", m.q1, m.q2, m.q3, m.q4),
        gnss_bias_ned_m=np.array(_NAN3),
        gnss_latency_s=math.nan,
        clearance_m=math.nan,
    )


# --- estimator outputs ------------------------------------------------------------------------


def _cov21(diag3: np.ndarray) -> list[float]:
    cov = [0.0] * 21
    for i, var in zip(_COV6_DIAG[:3], diag3, strict=True):
        cov[i] = float(var)
    for i in _COV6_DIAG[3:]:
        cov[i] = math.inf  # attitude / angular-rate variance: not estimated, no information
    return cov


def check_sendable(e: NavEstimate) -> None:
    """CodecError (the sender drops and counts) unless ``e`` is finite and plausible: nothing absurd
    or non-finite is ever sent, and nothing that would overflow a packed field."""
    _stamp_us("estimate", e.t_us)
    _bounded("estimate position", LIMITS.max_home_distance_m, *(float(x) for x in e.p_ned_m))
    _bounded("estimate velocity", LIMITS.max_speed_m_s, *(float(x) for x in e.v_ned_m_s))
    var = [float(x) for x in e.cov_diag[0:6]]
    _finite("estimate covariance", *var)
    if not 0.0 <= min(var) <= max(var) <= LIMITS.max_variance:
        raise CodecError("out_of_range", "estimate covariance")


def estimate_valid(e: NavEstimate) -> bool:
    """The estimator says the estimate is valid and its position/velocity variances are finite."""
    return bool(e.pos_valid) and bool(np.all(np.isfinite(e.cov_diag[0:6])))


def encode_odometry(e: NavEstimate) -> mavlink.MAVLink_odometry_message:
    """ODOMETRY of ``e``; CodecError unless it passes :func:`check_sendable`."""
    check_sendable(e)
    p, v = e.p_ned_m, e.v_ned_m_s
    quality = ODOMETRY_QUALITY_UNKNOWN if estimate_valid(e) else ODOMETRY_QUALITY_FAILED
    nan = math.nan
    return mavlink.MAVLink_odometry_message(
        e.t_us, mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_LOCAL_NED,
        p[0], p[1], p[2], [nan, 0.0, 0.0, 0.0], v[0], v[1], v[2], nan, nan, nan,
        _cov21(e.cov_diag[0:3]), _cov21(e.cov_diag[3:6]), e.gnss_resets % 256,  # reset_counter
        mavlink.MAV_ESTIMATOR_TYPE_GPS_INS, quality,
    )


def decode_odometry(m: Any) -> NavEstimate:
    if m.frame_id != mavlink.MAV_FRAME_LOCAL_NED or m.child_frame_id != mavlink.MAV_FRAME_LOCAL_NED:
        raise CodecError("unsupported_frame", f"ODOMETRY frame {m.frame_id}/{m.child_frame_id}")
    pos_var = [m.pose_covariance[i] for i in _COV6_DIAG[:3]]
    vel_var = [m.velocity_covariance[i] for i in _COV6_DIAG[:3]]
    _finite("ODOMETRY covariance", *pos_var, *vel_var)
    if not 0.0 <= min(*pos_var, *vel_var) <= max(*pos_var, *vel_var) <= LIMITS.max_variance:
        raise CodecError("out_of_range", "ODOMETRY variance")
    if m.quality > 100:
        raise CodecError("out_of_range", f"ODOMETRY quality {m.quality}")
    return NavEstimate(
        t_us=_stamp_us("ODOMETRY", m.time_usec),
        p_ned_m=_bounded("ODOMETRY position", LIMITS.max_home_distance_m, m.x, m.y, m.z),
        v_ned_m_s=_bounded("ODOMETRY velocity", LIMITS.max_speed_m_s, m.vx, m.vy, m.vz),
        b_ned_m=np.array(_NAN3),
        cov_diag=np.array([*pos_var, *vel_var, *_NAN3]),
        beta=math.nan,  # β travels in NAMED_VALUE_FLOAT GNSS_BETA; quality is the spec's
        nis=math.nan,
        method="odometry",
        pos_valid=int(m.quality) != ODOMETRY_QUALITY_FAILED,
        gnss_resets=int(m.reset_counter),
    )


def estimator_flags(e: NavEstimate) -> int:
    """ESTIMATOR_STATUS_FLAGS of ``e``: position/velocity bits while the estimate is valid (the
    fly-away guard clears them), GPS_GLITCH while the innovation gate rejects GNSS, ACCEL_ERROR while
    the IMU-propagated motion disagrees with the GNSS velocity (``imu_gnss_disagreement``)."""
    flags = ESTIMATOR_HEALTHY_FLAGS if estimate_valid(e) else 0
    flags |= mavlink.ESTIMATOR_GPS_GLITCH if e.gnss_glitch else 0
    return flags | (mavlink.ESTIMATOR_ACCEL_ERROR if e.imu_gnss_disagreement else 0)


def encode_estimator_status(e: NavEstimate) -> mavlink.MAVLink_estimator_status_message:
    """Flags and ratios of the tests actually made (see the module notes); 1-σ accuracies.
    ``pos_horiz_ratio`` = the estimator's ``pos_horiz_test_ratio`` (NaN: no fix tested yet;
    clamped to the float32 maximum). ``e`` must pass :func:`check_sendable`."""
    ratio = min(e.pos_horiz_test_ratio, FLOAT32_MAX)  # NaN stays NaN
    vel_ratio = min(e.vel_test_ratio, FLOAT32_MAX)
    horiz = math.sqrt(float(e.cov_diag[0] + e.cov_diag[1]))
    vert = math.sqrt(float(e.cov_diag[2]))
    nan = math.nan
    return mavlink.MAVLink_estimator_status_message(
        e.t_us, estimator_flags(e), vel_ratio, ratio, nan, nan, nan, nan, horiz, vert,
    )


def decode_estimator_status(m: Any) -> EstimatorStatus:
    _finite("ESTIMATOR_STATUS", m.pos_horiz_accuracy, m.pos_vert_accuracy)
    for name in ("pos_horiz_ratio", "vel_ratio"):
        value = getattr(m, name)
        if not (math.isnan(value) or 0.0 <= value < math.inf):  # NaN: no test made
            raise CodecError("out_of_range", f"ESTIMATOR_STATUS {name} {value}")
    return EstimatorStatus(
        int(m.time_usec), int(m.flags), float(m.pos_horiz_ratio),
        float(m.pos_horiz_accuracy), float(m.pos_vert_accuracy), float(m.vel_ratio),
    )


def encode_named_value(t_us: int, name: str, value: float) -> mavlink.MAVLink_named_value_float_message:
    """CodecError (drop and count) for a value a float32 cannot hold or a stamp beyond uint32 ms."""
    raw = name.encode("ascii")
    if len(raw) > 10:
        raise ValueError(f"NAMED_VALUE_FLOAT name {name!r} longer than 10 characters")
    if not abs(value) <= FLOAT32_MAX:
        raise CodecError("out_of_range", f"NAMED_VALUE_FLOAT {name} value {value!r}")
    _ms_stamp("NAMED_VALUE_FLOAT", t_us)
    return mavlink.MAVLink_named_value_float_message(t_us // 1000, raw, value)


def decode_named_value(m: Any) -> NamedValue:
    name = _text(m.name)
    _finite(f"NAMED_VALUE_FLOAT {name}", m.value)
    return NamedValue(int(m.time_boot_ms) * 1000, name, float(m.value))


def encode_belief(e: NavEstimate) -> list[mavlink.MAVLink_named_value_float_message]:
    """GNSS_BETA and (once a fix was fused, i.e. finite) GNSS_NIS for one estimate."""
    return [
        encode_named_value(e.t_us, name, value)
        for name, value in ((BELIEF_NAME, e.beta), (NIS_NAME, e.nis))
        if math.isfinite(value)
    ]


def encode_bias(e: NavEstimate) -> mavlink.MAVLink_debug_vect_message:
    """DEBUG_VECT ``GNSS_BIAS``: the estimated GNSS bias, north/east/down [m]."""
    b = e.b_ned_m
    return mavlink.MAVLink_debug_vect_message(BIAS_NAME.encode("ascii"), e.t_us, float(b[0]), float(b[1]),
                                              float(b[2]))


def decode_bias(m: Any) -> tuple[int, np.ndarray]:
    """(boot time [us], bias NED [m]) of a DEBUG_VECT ``GNSS_BIAS``; another name is a CodecError."""
    name = _text(m.name)
    if name != BIAS_NAME:
        raise CodecError("name", f"DEBUG_VECT {name!r} is not {BIAS_NAME}")
    return int(m.time_usec), _vec("DEBUG_VECT GNSS_BIAS", m.x, m.y, m.z)


# --- planner bridge ---------------------------------------------------------------------------


def encode_setpoint(
    s: Setpoint, target_system: int = 1, target_component: int = 1
) -> mavlink.MAVLink_set_position_target_local_ned_message:
    """CodecError (drop and count) for a setpoint that is not finite and plausible."""
    p, v, a = s.p_ned_m, s.v_ned_m_s, s.a_ned_m_s2
    _ms_stamp("setpoint", s.t_us)
    _bounded("setpoint position", LIMITS.max_home_distance_m, *(float(x) for x in p))
    _bounded("setpoint velocity", LIMITS.max_speed_m_s, *(float(x) for x in v))
    _bounded("setpoint acceleration", LIMITS.max_accel_m_s2, *(float(x) for x in a))
    return mavlink.MAVLink_set_position_target_local_ned_message(
        s.t_us // 1000, target_system, target_component, mavlink.MAV_FRAME_LOCAL_NED,
        _SETPOINT_TYPE_MASK, p[0], p[1], p[2], v[0], v[1], v[2], a[0], a[1], a[2], 0.0, 0.0,
    )


def decode_setpoint(m: Any) -> Setpoint:
    if m.coordinate_frame != mavlink.MAV_FRAME_LOCAL_NED:
        raise CodecError("unsupported_frame", f"SET_POSITION_TARGET_LOCAL_NED frame {m.coordinate_frame}")
    mask = int(m.type_mask)
    if mask & (_POS_IGNORE | mavlink.POSITION_TARGET_TYPEMASK_FORCE_SET):
        raise CodecError("unsupported_frame", f"SET_POSITION_TARGET_LOCAL_NED type_mask {mask:#x}")
    zero = np.zeros(3)
    lim = LIMITS
    return Setpoint(
        _stamp_us("setpoint", int(m.time_boot_ms) * 1000),
        _bounded("setpoint position", lim.max_home_distance_m, m.x, m.y, m.z),
        zero if mask & _VEL_IGNORE else _bounded("setpoint velocity", lim.max_speed_m_s, m.vx, m.vy, m.vz),
        zero.copy() if mask & _ACC_IGNORE
        else _bounded("setpoint acceleration", lim.max_accel_m_s2, m.afx, m.afy, m.afz),
    )


# --- link housekeeping ------------------------------------------------------------------------


def encode_heartbeat(role: str, armed: bool = False, mode: str | None = None,
                     system_status: int = mavlink.MAV_STATE_ACTIVE) -> mavlink.MAVLink_heartbeat_message:
    """A companion's heartbeat (base and custom mode 0: not an autopilot), or the vehicle's with
    its armed flag and flight ``mode`` (a key of :data:`CUSTOM_MODES`)."""
    mav_type, autopilot = ROLE_TYPES[role]
    base_mode = custom_mode = 0
    if role == "vehicle":
        base_mode = VEHICLE_BASE_MODE | (mavlink.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0)
        custom_mode = CUSTOM_MODES[mode or "OFFBOARD"]
    return mavlink.MAVLink_heartbeat_message(mav_type, autopilot, base_mode, custom_mode, system_status, 3)


def decode_heartbeat(m: Any) -> Heartbeat:
    return Heartbeat(int(m.type), int(m.autopilot), int(m.system_status), int(m.base_mode),
                     int(m.custom_mode))


def encode_system_time(time_unix_us: int, t_boot_us: int) -> mavlink.MAVLink_system_time_message:
    return mavlink.MAVLink_system_time_message(time_unix_us, t_boot_us // 1000)


def decode_system_time(m: Any) -> ClockPair:
    return ClockPair(int(m.time_unix_usec), int(m.time_boot_ms) * 1000)
