"""Attitude maths, written once: quaternions (w, x, y, z) of body FRD → NED, the rotation matrix
R_ned_frd, and ZYX Euler angles (roll φ, pitch θ, yaw ψ; R = Rz(ψ) Ry(θ) Rx(φ), the paper's ϱ).

Every caller (the simulator's 200 Hz inner loop and IMU blocks, the estimator's batch path, the
MAVLink codec, log readers, ground telemetry, the autopilot feeds) uses these functions. They
are plain arithmetic rather than ``scipy.spatial.transform.Rotation`` because most callers are
per-sample hot paths (building one scipy ``Rotation`` costs more than the filter's whole step per
IMU sample) and because the estimator's C core computes the same expressions and must give the
same bits; scipy's ``Rotation`` is the reference they are tested against (``tests/test_rotation.py``).
The matrix functions take floats or numpy arrays alike (one quaternion or a block of them,
element by element: the same bits).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

Rot = tuple[Any, Any, Any, Any, Any, Any, Any, Any, Any]  # R_ned_frd, row-major
Quat = tuple[Any, Any, Any, Any]  # (w, x, y, z)


def rotation_terms(w: Any, x: Any, y: Any, z: Any) -> Rot:
    """Row-major R_ned_frd of a UNIT quaternion; floats or arrays."""
    return (
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    )


def rotation_scaled(w: Any, x: Any, y: Any, z: Any, s: Any) -> Rot:
    """Row-major R_ned_frd of any quaternion with ``s = 2 / |q|²``; floats or arrays.

    Every term of R is quadratic in q, so the normalisation is folded into ``s``: no square root.
    Equal to ``rotation_ned_frd`` up to rounding (tested). The estimator's per-sample path computes
    the same expression in its C core (``_core.rotation_q``, the same bits: tested); this form
    serves the vectorised ``Navigator.push_imu_batch``.
    """
    xs, ys, zs = x * s, y * s, z * s
    wx, wy, wz = w * xs, w * ys, w * zs
    xx, xy, xz = x * xs, x * ys, x * zs
    yy, yz, zz = y * ys, y * zs, z * zs
    return (1.0 - (yy + zz), xy - wz, xz + wy,
            xy + wz, 1.0 - (xx + zz), yz - wx,
            xz - wy, yz + wx, 1.0 - (xx + yy))


def normalised(w: Any, x: Any, y: Any, z: Any, sqrt: Callable[[Any], Any] = math.sqrt) -> tuple[Any, Quat]:
    """(|q|, q / |q|); floats (``math.sqrt``) or arrays (``np.sqrt``)."""
    n = sqrt(w * w + x * x + y * y + z * z)
    return n, (w / n, x / n, y / n, z / n)


def rotation_ned_frd(w: Any, x: Any, y: Any, z: Any, sqrt: Callable[[Any], Any] = math.sqrt) -> Rot:
    """Row-major R_ned_frd of any quaternion (normalised here); floats or arrays alike."""
    return rotation_terms(*normalised(w, x, y, z, sqrt)[1])


def rotation_matrix(q_ned_frd: Sequence[float] | np.ndarray) -> np.ndarray:
    """R_ned_frd of a unit quaternion (4,) -> (3, 3), or of a block (n, 4) -> (n, 3, 3)."""
    q = np.asarray(q_ned_frd, dtype=float)
    if q.ndim == 1:
        return np.array(rotation_terms(*q.tolist())).reshape(3, 3)
    return np.stack(rotation_terms(*q.T), axis=-1).reshape(-1, 3, 3)


def quaternion_to_euler(q: Sequence[float] | np.ndarray) -> tuple[float, float, float]:
    """ZYX Euler angles (roll, pitch, yaw) in radians of a unit quaternion (pitch clipped to ±π/2)."""
    w, x, y, z = map(float, q)
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


def yaw_of(q: Sequence[float] | np.ndarray) -> float:
    """Yaw (rad, about NED down) of a unit quaternion."""
    return quaternion_to_euler(q)[2]


def euler_to_quaternion(roll_rad: float, pitch_rad: float, yaw_rad: float) -> Quat:
    """Unit quaternion (w, x, y, z) of ZYX Euler angles."""
    cr, sr = math.cos(roll_rad / 2), math.sin(roll_rad / 2)
    cp, sp = math.cos(pitch_rad / 2), math.sin(pitch_rad / 2)
    cy, sy = math.cos(yaw_rad / 2), math.sin(yaw_rad / 2)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )


def quaternion_product(a: Any, b: Any) -> np.ndarray:
    """Hamilton product a ⊗ b of (..., 4) quaternions (w, x, y, z)."""
    aw, ax, ay, az = np.moveaxis(np.asarray(a, dtype=float), -1, 0)
    bw, bx, by, bz = np.moveaxis(np.asarray(b, dtype=float), -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw], axis=-1)


_S = math.sqrt(0.5)
Q_ENU_NED = (0.0, _S, _S, 0.0)  # NED -> ENU: swap north and east, flip down
Q_FRD_FLU = (0.0, 1.0, 0.0, 0.0)  # FLU -> FRD: half a turn about the forward axis


def enu_flu(q_ned_frd: Any) -> np.ndarray:
    """(n, 4) body FRD -> NED quaternions as body FLU -> ENU (the ROS and Foxglove convention),
    ``q_enu_flu = Q_ENU_NED ⊗ q_ned_frd ⊗ Q_FRD_FLU``, with w >= 0."""
    q = quaternion_product(quaternion_product(Q_ENU_NED, np.asarray(q_ned_frd, dtype=float).reshape(-1, 4)),
                           Q_FRD_FLU)
    return np.where(q[:, :1] < 0, -q, q)
