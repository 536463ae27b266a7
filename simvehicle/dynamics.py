"""Rigid-body quadrotor (eq. 6-8) in NED with body FRD, integrated with RK4.

The paper's 12-state vector ``s = [p, v, φ, θ, ψ, ω]`` (eq. 6) is available from
``RigidBody.state12()``; internally attitude is a unit quaternion (w, x, y, z), body FRD to
NED, renormalised after every step, so the rotation matrix stays orthonormal and there is no
gimbal lock. Translational dynamics (eq. 7, written in NED, thrust along body -z):

    p' = v,    v' = g e_3 - (T / m) R e_3 - (c_drag / m) v

Rotational dynamics (eq. 8): ω' = I⁻¹ (τ - ω × I ω), q' = ½ q ⊗ (0, ω).
The inner loop is plain Python floats: one step allocates no numpy arrays.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from companion.domain.rotation import euler_to_quaternion, quaternion_to_euler, rotation_matrix
from simvehicle.config import VehicleConfig

# state layout: 0-2 p_ned_m, 3-5 v_ned_m_s, 6-9 q_ned_frd (w, x, y, z), 10-12 omega_frd_rad_s


class RigidBody:
    """The true vehicle state and its RK4 integrator (mutable; one per simulated vehicle)."""

    def __init__(self, cfg: VehicleConfig, p_ned_m: Sequence[float] | np.ndarray,
                 yaw_rad: float = 0.0) -> None:
        self.cfg = cfg
        self._inv_m = 1.0 / cfg.mass_kg
        self._g = cfg.gravity_m_s2
        self._drag_per_kg = cfg.drag_n_s_m / cfg.mass_kg
        self._ixx, self._iyy, self._izz = cfg.inertia_kg_m2
        q = euler_to_quaternion(0.0, 0.0, yaw_rad)
        self.x: list[float] = [*map(float, p_ned_m), 0.0, 0.0, 0.0, *q, 0.0, 0.0, 0.0]

    # -- the model ---------------------------------------------------------------------
    def _deriv(self, vn: float, ve: float, vd: float, qw: float, qx: float, qy: float, qz: float,
               p: float, q: float, r: float, a: float, tx: float, ty: float, tz: float) -> tuple[float, ...]:
        """Time derivative of (v, q, ω) at thrust acceleration ``a = T/m`` (p' = v is implicit).

        The reference form of the model; ``step`` evaluates the same expressions inline.
        """
        c = self._drag_per_kg
        ixx, iyy, izz = self._ixx, self._iyy, self._izz
        return (
            -a * 2 * (qx * qz + qw * qy) - c * vn,
            -a * 2 * (qy * qz - qw * qx) - c * ve,
            self._g - a * (1 - 2 * (qx * qx + qy * qy)) - c * vd,
            0.5 * (-qx * p - qy * q - qz * r),
            0.5 * (qw * p + qy * r - qz * q),
            0.5 * (qw * q + qz * p - qx * r),
            0.5 * (qw * r + qx * q - qy * p),
            (tx + (iyy - izz) * q * r) / ixx,
            (ty + (izz - ixx) * p * r) / iyy,
            (tz + (ixx - iyy) * p * q) / izz,
        )

    def step(self, dt_s: float, thrust_n: float, tx: float, ty: float, tz: float) -> None:
        """Advance by ``dt_s`` with thrust and body torques held constant (zero-order hold), RK4.

        ``_deriv`` written out four times (the 200 Hz hot loop: no calls, no tuples); the
        stage values are bit-for-bit those of calling ``_deriv`` (tested).
        """
        n, e, d, vn, ve, vd, qw, qx, qy, qz, p, q, r = self.x
        a = thrust_n * self._inv_m
        ma2 = -a * 2
        c, g = self._drag_per_kg, self._g
        ixx, iyy, izz = self._ixx, self._iyy, self._izz
        jx, jy, jz = iyy - izz, izz - ixx, ixx - iyy
        h = 0.5 * dt_s
        # stage 1 at the start
        k1vn = ma2 * (qx * qz + qw * qy) - c * vn
        k1ve = ma2 * (qy * qz - qw * qx) - c * ve
        k1vd = g - a * (1 - 2 * (qx * qx + qy * qy)) - c * vd
        k1w = 0.5 * (-qx * p - qy * q - qz * r)
        k1x = 0.5 * (qw * p + qy * r - qz * q)
        k1y = 0.5 * (qw * q + qz * p - qx * r)
        k1z = 0.5 * (qw * r + qx * q - qy * p)
        k1p = (tx + jx * q * r) / ixx
        k1q = (ty + jy * p * r) / iyy
        k1r = (tz + jz * p * q) / izz
        # stage 2 at the half step along k1
        vn1, ve1, vd1 = vn + h * k1vn, ve + h * k1ve, vd + h * k1vd
        w, x, y, z = qw + h * k1w, qx + h * k1x, qy + h * k1y, qz + h * k1z
        wp, wq, wr = p + h * k1p, q + h * k1q, r + h * k1r
        k2vn = ma2 * (x * z + w * y) - c * vn1
        k2ve = ma2 * (y * z - w * x) - c * ve1
        k2vd = g - a * (1 - 2 * (x * x + y * y)) - c * vd1
        k2w = 0.5 * (-x * wp - y * wq - z * wr)
        k2x = 0.5 * (w * wp + y * wr - z * wq)
        k2y = 0.5 * (w * wq + z * wp - x * wr)
        k2z = 0.5 * (w * wr + x * wq - y * wp)
        k2p = (tx + jx * wq * wr) / ixx
        k2q = (ty + jy * wp * wr) / iyy
        k2r = (tz + jz * wp * wq) / izz
        # stage 3 at the half step along k2
        vn2, ve2, vd2 = vn + h * k2vn, ve + h * k2ve, vd + h * k2vd
        w, x, y, z = qw + h * k2w, qx + h * k2x, qy + h * k2y, qz + h * k2z
        wp, wq, wr = p + h * k2p, q + h * k2q, r + h * k2r
        k3vn = ma2 * (x * z + w * y) - c * vn2
        k3ve = ma2 * (y * z - w * x) - c * ve2
        k3vd = g - a * (1 - 2 * (x * x + y * y)) - c * vd2
        k3w = 0.5 * (-x * wp - y * wq - z * wr)
        k3x = 0.5 * (w * wp + y * wr - z * wq)
        k3y = 0.5 * (w * wq + z * wp - x * wr)
        k3z = 0.5 * (w * wr + x * wq - y * wp)
        k3p = (tx + jx * wq * wr) / ixx
        k3q = (ty + jy * wp * wr) / iyy
        k3r = (tz + jz * wp * wq) / izz
        # stage 4 at the full step along k3
        vn3, ve3, vd3 = vn + dt_s * k3vn, ve + dt_s * k3ve, vd + dt_s * k3vd
        w, x, y, z = qw + dt_s * k3w, qx + dt_s * k3x, qy + dt_s * k3y, qz + dt_s * k3z
        wp, wq, wr = p + dt_s * k3p, q + dt_s * k3q, r + dt_s * k3r
        k4vn = ma2 * (x * z + w * y) - c * vn3
        k4ve = ma2 * (y * z - w * x) - c * ve3
        k4vd = g - a * (1 - 2 * (x * x + y * y)) - c * vd3
        k4w = 0.5 * (-x * wp - y * wq - z * wr)
        k4x = 0.5 * (w * wp + y * wr - z * wq)
        k4y = 0.5 * (w * wq + z * wp - x * wr)
        k4z = 0.5 * (w * wr + x * wq - y * wp)
        k4p = (tx + jx * wq * wr) / ixx
        k4q = (ty + jy * wp * wr) / iyy
        k4r = (tz + jz * wp * wq) / izz
        s = dt_s / 6.0
        # position: p' = v, so its RK4 stages are the stage velocities
        qw += s * (k1w + 2 * (k2w + k3w) + k4w)
        qx += s * (k1x + 2 * (k2x + k3x) + k4x)
        qy += s * (k1y + 2 * (k2y + k3y) + k4y)
        qz += s * (k1z + 2 * (k2z + k3z) + k4z)
        inv = 1.0 / math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        self.x = [
            n + s * (vn + 2 * vn1 + 2 * vn2 + vn3),
            e + s * (ve + 2 * ve1 + 2 * ve2 + ve3),
            d + s * (vd + 2 * vd1 + 2 * vd2 + vd3),
            vn + s * (k1vn + 2 * (k2vn + k3vn) + k4vn),
            ve + s * (k1ve + 2 * (k2ve + k3ve) + k4ve),
            vd + s * (k1vd + 2 * (k2vd + k3vd) + k4vd),
            qw * inv, qx * inv, qy * inv, qz * inv,
            p + s * (k1p + 2 * (k2p + k3p) + k4p),
            q + s * (k1q + 2 * (k2q + k3q) + k4q),
            r + s * (k1r + 2 * (k2r + k3r) + k4r),
        ]

    # -- views -------------------------------------------------------------------------
    @property
    def q_ned_frd(self) -> tuple[float, float, float, float]:
        return self.x[6], self.x[7], self.x[8], self.x[9]

    def rotation(self) -> np.ndarray:
        """R_ned_frd (body FRD to NED), the paper's ϱ(φ, θ, ψ)."""
        return rotation_matrix(self.q_ned_frd)

    def state12(self) -> np.ndarray:
        """The paper's state (eq. 6): [n, e, d, v_n, v_e, v_d, φ, θ, ψ, p, q, r]."""
        x = self.x
        return np.array([*x[0:6], *quaternion_to_euler(x[6:10]), *x[10:13]])
