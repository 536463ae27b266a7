"""What the companion sends back so an unmodified autopilot flies on its estimate.

- ``gps-input``: GPS_INPUT = a cleaned fix. The filter's position IS the fix with the
  estimated multipath bias removed (the filter models ``z = p + b + ν`` and estimates ``p``), so
  the cleaned fix is ``p̂`` in geodetic coordinates, with ``horiz_accuracy = sqrt(P_nn + P_ee)``,
  ``vert_accuracy = sqrt(P_dd)`` and ``speed_accuracy`` from the velocity block. β enters through
  the covariance: a low trust inflates R(β) and the bias process noise, so P grows while the
  fixes are doubted. The tight filter's position variances arrive already inflated by its measured
  consistency (``TightNavigator.accuracy_inflation``). While the estimate is not valid (``pos_valid``
  False) fix_type is 0.
  ArduPilot: ``GPS1_TYPE`` = 14 (MAVLink), in force after a reboot.
- ``vision``: VISION_POSITION_ESTIMATE, NED position in the autopilot's local frame and Euler attitude:
  horizontally about its EKF origin when it reports one (GPS_GLOBAL_ORIGIN; :func:`local_origin_ned_m`),
  vertically about our home (heights above the take-off point: the autopilot's barometer, or ours
  where we gave it the origin).
  ArduPilot: ``VISO_TYPE`` = 1, ``EK3_SRC1_POSXY`` = 6, ``EK3_SRC1_VELXY`` = 0,
  ``EK3_SRC1_POSZ`` = 1, ``EK3_SRC1_YAW`` = 1, reboot.
- ``odometry``: ODOMETRY with ``frame_id`` = MAV_FRAME_LOCAL_FRD (20) and ``child_frame_id`` =
  MAV_FRAME_BODY_FRD (12), the frames ArduPilot fuses (same parameters as ``vision``); velocity
  in the body frame; ``estimator_type`` = MAV_ESTIMATOR_TYPE_VIO (3). PX4 takes ODOMETRY with
  ``frame_id`` MAV_FRAME_LOCAL_NED/ENU/FRD/FLU, velocity in those or BODY_FRD, and
  ``estimator_type`` VISION (2) or VIO (3) (external vision) or MOCAP (6); other types (e.g.
  GPS_INS = 5) are refused — documented from PX4's receiver, not tested here.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from companion.domain.geodesy import LocalNedFrame
from companion.domain.rotation import quaternion_to_euler, rotation_ned_frd
from companion.domain.samples import NavEstimate

GPS_EPOCH_UNIX_S = 315_964_800  # 1980-01-06T00:00:00Z
GPS_LEAP_S = 18  # GPS time - UTC since 2017
WEEK_S = 604_800
FIX_3D = 3
UINT16_UNKNOWN = 65535
COV6_DIAGONAL = (0, 6, 11, 15, 18, 20)  # indices of the diagonal in a 6x6 upper triangle (21 entries)


@dataclass(frozen=True, slots=True)
class FeedConfig:
    # a GNSS receiver's rate: ArduPilot calls a GPS unhealthy when its fixes arrive more than 215 ms
    # apart on average (AP_GPS::is_healthy), so 5 Hz is at the edge; 10 Hz leaves room for jitter
    gps_input_hz: float = 10.0
    vision_hz: float = 20.0  # VISION_POSITION_ESTIMATE / ODOMETRY
    satellites: int = 10  # satellites_visible reported with a valid cleaned fix (the raw fix's if known)
    hdop: float = 0.8  # HDOP sent when the raw fix has none (ArduPilot pre-arm: < GPS_HDOP_GOOD / 100)
    # Attitude and body rates in VISION/ODOMETRY are the autopilot's own, passed through (the filter
    # estimates neither); their stated 1-σ (ArduPilot needs finite covariances):
    attitude_sigma_rad: float = 0.035  # ≈ 2°
    rate_sigma_rad_s: float = 0.01

    def period_us(self, feed: str) -> int:
        hz = self.gps_input_hz if feed == "gps-input" else self.vision_hz
        return round(1e6 / hz)


def gps_time(unix_s: float) -> tuple[int, int]:
    """(GPS week, ms of week) for a UNIX time."""
    gps_s = unix_s - GPS_EPOCH_UNIX_S + GPS_LEAP_S
    week = int(gps_s // WEEK_S)
    return week, int(round((gps_s - week * WEEK_S) * 1000))


def gps_input(e: NavEstimate, frame: LocalNedFrame, config: FeedConfig, hdop: float = math.nan,
              satellites: int = -1, unix_s: float | None = None) -> mavlink.MAVLink_gps_input_message:
    lat, lon, alt = frame.to_geodetic(np.asarray(e.p_ned_m, dtype=float))
    var = np.asarray(e.cov_diag, dtype=float)
    valid = bool(e.pos_valid) and bool(np.all(np.isfinite(var[:6])))
    week, week_ms = gps_time(time.time() if unix_s is None else unix_s)
    hdop = hdop if math.isfinite(hdop) else config.hdop
    return mavlink.MAVLink_gps_input_message(
        time_usec=int(e.t_us), gps_id=0, ignore_flags=0, time_week_ms=week_ms, time_week=week,
        fix_type=FIX_3D if valid else 0, lat=round(lat * 1e7), lon=round(lon * 1e7), alt=float(alt),
        hdop=float(hdop), vdop=float(hdop), vn=float(e.v_ned_m_s[0]), ve=float(e.v_ned_m_s[1]),
        vd=float(e.v_ned_m_s[2]),
        speed_accuracy=float(math.sqrt(var[3] + var[4] + var[5])) if valid else 0.0,
        horiz_accuracy=float(math.sqrt(var[0] + var[1])) if valid else 0.0,
        vert_accuracy=float(math.sqrt(var[2])) if valid else 0.0,
        satellites_visible=(satellites if satellites >= 0 else config.satellites) if valid else 0, yaw=0)


def covariance21(diagonal: tuple[float, ...]) -> list[float]:
    """Upper triangle (21 entries) of a 6x6 covariance with this diagonal and no cross terms.

    Every entry is finite: ArduPilot takes sqrt(c0 + c6 + c11) and sqrt(c15 + c18 + c20) of it
    and reports a NaN there as an internal error (measured: "PreArm: Internal errors 0x400")."""
    cov = [0.0] * 21
    for index, value in zip(COV6_DIAGONAL, diagonal, strict=True):
        cov[index] = float(value)
    return cov


def local_origin_ned_m(frame: LocalNedFrame, origin_lla: tuple[float, float, float] | None) -> np.ndarray:
    """Where the local-position feeds' origin lies in our frame: the autopilot's EKF origin
    (GPS_GLOBAL_ORIGIN) horizontally, our home vertically; zero without an origin. MAVLink's local
    frame is NED about the EKF origin, and an autopilot that set its origin from its own first GNSS fix
    (ArduPilot with a receiver of its own) has it where that fix was: in a street canyon 5-20 m from
    ours. Sending positions about OUR home would put the vehicle that far off. The origin's altitude is
    a GNSS altitude (tens of metres off in a canyon) and the autopilots' heights are not about it
    (ArduPilot's barometer, PX4's external-vision height about the origin we set), so heights stay ours."""
    if origin_lla is None:
        return np.zeros(3)
    o = frame.to_ned_m(*origin_lla)
    return np.array([o[0], o[1], 0.0])


def _pose_covariance(var: np.ndarray, config: FeedConfig) -> list[float]:
    """Position variances from the filter; attitude (the autopilot's own, passed through) stated."""
    att = config.attitude_sigma_rad ** 2
    return covariance21((var[0], var[1], var[2], att, att, att))


def vision_position(
        e: NavEstimate, q_ned_frd: np.ndarray, config: FeedConfig,
        origin_ned_m: np.ndarray | None = None) -> mavlink.MAVLink_vision_position_estimate_message:
    """``origin_ned_m``: the local frame's origin in ours (:func:`local_origin_ned_m`; None: our home)."""
    roll, pitch, yaw = quaternion_to_euler(np.asarray(q_ned_frd, dtype=float))
    p = np.asarray(e.p_ned_m, dtype=float) - (0.0 if origin_ned_m is None else origin_ned_m)
    return mavlink.MAVLink_vision_position_estimate_message(
        usec=int(e.t_us), x=float(p[0]), y=float(p[1]), z=float(p[2]), roll=roll, pitch=pitch, yaw=yaw,
        covariance=_pose_covariance(np.asarray(e.cov_diag), config), reset_counter=0)


def odometry(e: NavEstimate, q_ned_frd: np.ndarray, gyro_frd_rad_s: np.ndarray, config: FeedConfig,
             origin_ned_m: np.ndarray | None = None) -> mavlink.MAVLink_odometry_message:
    """``origin_ned_m`` as in :func:`vision_position`."""
    q = np.asarray(q_ned_frd, dtype=float)
    r_ned_frd = np.array(rotation_ned_frd(float(q[0]), float(q[1]), float(q[2]), float(q[3]), math.sqrt))
    r_ned_frd = r_ned_frd.reshape(3, 3)
    v_frd = r_ned_frd.T @ np.asarray(e.v_ned_m_s, dtype=float)
    var = np.asarray(e.cov_diag, dtype=float)
    rate = config.rate_sigma_rad_s ** 2
    vel_cov = covariance21((var[3], var[4], var[5], rate, rate, rate))
    p = np.asarray(e.p_ned_m, dtype=float) - (0.0 if origin_ned_m is None else origin_ned_m)
    return mavlink.MAVLink_odometry_message(
        time_usec=int(e.t_us), frame_id=mavlink.MAV_FRAME_LOCAL_FRD,
        child_frame_id=mavlink.MAV_FRAME_BODY_FRD,
        x=float(p[0]), y=float(p[1]), z=float(p[2]), q=[float(v) for v in q],
        vx=float(v_frd[0]), vy=float(v_frd[1]), vz=float(v_frd[2]),
        rollspeed=float(gyro_frd_rad_s[0]), pitchspeed=float(gyro_frd_rad_s[1]),
        yawspeed=float(gyro_frd_rad_s[2]),
        pose_covariance=_pose_covariance(var, config), velocity_covariance=vel_cov, reset_counter=0,
        estimator_type=mavlink.MAV_ESTIMATOR_TYPE_VIO, quality=max(1, min(100, round(100 * e.beta))))
