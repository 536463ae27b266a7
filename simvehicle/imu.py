"""IMU model: specific force and angular rate in body FRD with white noise (σ_a = 0.08 m/s²).

Works on a block of physics steps at once (one control period), so the 200 Hz loop itself
stays free of numpy. Specific force is what an accelerometer measures: every force but
gravity, divided by mass — thrust along body -z and air drag — so ≈ (0, 0, -9.81) at rest.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from simvehicle.config import ImuConfig, VehicleConfig
from simvehicle.noise import NormalBlocks


def rotations(q_ned_frd: np.ndarray) -> np.ndarray:
    """R_ned_frd for a block of unit quaternions (n, 4) -> (n, 3, 3)."""
    w, x, y, z = q_ned_frd.T
    R = np.empty((q_ned_frd.shape[0], 3, 3))
    R[:, 0, 0] = 1 - 2 * (y * y + z * z)
    R[:, 0, 1] = 2 * (x * y - w * z)
    R[:, 0, 2] = 2 * (x * z + w * y)
    R[:, 1, 0] = 2 * (x * y + w * z)
    R[:, 1, 1] = 1 - 2 * (x * x + z * z)
    R[:, 1, 2] = 2 * (y * z - w * x)
    R[:, 2, 0] = 2 * (x * z - w * y)
    R[:, 2, 1] = 2 * (y * z + w * x)
    R[:, 2, 2] = 1 - 2 * (x * x + y * y)
    return R


def specific_force_frd(vehicle: VehicleConfig, thrust_n: float,
                       x: Sequence[float]) -> tuple[float, float, float]:
    """True specific force in body FRD for thrust and state ``x`` (RigidBody layout): (-c Rᵀv - T e_3) / m."""
    _, _, _, vn, ve, vd, w, qx, qy, qz = x[:10]
    # Rᵀ v, the NED velocity in body axes
    bx = (1 - 2 * (qy * qy + qz * qz)) * vn + 2 * (qx * qy + w * qz) * ve + 2 * (qx * qz - w * qy) * vd
    by = 2 * (qx * qy - w * qz) * vn + (1 - 2 * (qx * qx + qz * qz)) * ve + 2 * (qy * qz + w * qx) * vd
    bz = 2 * (qx * qz + w * qy) * vn + 2 * (qy * qz - w * qx) * ve + (1 - 2 * (qx * qx + qy * qy)) * vd
    c = vehicle.drag_n_s_m
    inv_m = 1.0 / vehicle.mass_kg
    return -c * bx * inv_m, -c * by * inv_m, (-thrust_n - c * bz) * inv_m


class Imu:
    """Adds the configured white noise to true specific force and body rates (seeded)."""

    def __init__(self, cfg: ImuConfig, rng: np.random.Generator) -> None:
        self.cfg = cfg
        self._normals = NormalBlocks(rng)

    def measure(self, f_frd_m_s2: np.ndarray, omega_frd_rad_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Noisy (acc_frd_m_s2, gyro_frd_rad_s) blocks of the same shape (n, 3) as the inputs.

        The noise is ``rng.standard_normal((n, 6))`` (served from blocks: the same stream)."""
        n = f_frd_m_s2.shape[0]
        noise = self._normals.take(6 * n).reshape(n, 6)
        acc = f_frd_m_s2 + self.cfg.sigma_acc_m_s2 * noise[:, :3]
        gyro = omega_frd_rad_s + self.cfg.sigma_gyro_rad_s * noise[:, 3:]
        return acc, gyro
