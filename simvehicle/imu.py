"""IMU model: specific force and angular rate in body FRD with white noise (σ_a = 0.08 m/s²) and,
when configured (``ImuConfig``, e.g. the ``realistic`` scenario's MEMS part), turn-on bias, bias
random walk and scale-factor error.

Works on a block of physics steps at once (one control period), so the 200 Hz loop itself
stays free of numpy. Specific force is what an accelerometer measures: every force but
gravity, divided by mass — thrust along body -z and air drag — so ≈ (0, 0, -9.81) at rest.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from companion.domain.rotation import rotation_terms
from simvehicle.config import ImuConfig, VehicleConfig
from simvehicle.noise import NormalBlocks


def specific_force_frd(vehicle: VehicleConfig, thrust_n: float,
                       x: Sequence[float]) -> tuple[float, float, float]:
    """True specific force in body FRD for thrust and state ``x`` (RigidBody layout): (-c Rᵀv - T e_3) / m."""
    _, _, _, vn, ve, vd, w, qx, qy, qz = x[:10]
    r = rotation_terms(w, qx, qy, qz)
    # Rᵀ v, the NED velocity in body axes
    bx = r[0] * vn + r[3] * ve + r[6] * vd
    by = r[1] * vn + r[4] * ve + r[7] * vd
    bz = r[2] * vn + r[5] * ve + r[8] * vd
    c = vehicle.drag_n_s_m
    inv_m = 1.0 / vehicle.mass_kg
    return -c * bx * inv_m, -c * by * inv_m, (-thrust_n - c * bz) * inv_m


class Imu:
    """Adds the configured errors to true specific force and body rates (seeded).

    ``measured = (1 + s) ∘ true + b + w`` per axis: ``s`` scale-factor errors and the turn-on
    part of ``b`` drawn once at construction, ``b`` then a random walk per sample, ``w`` white.
    With only white noise configured (``cfg.ideal``) nothing else is drawn: the paper's stream.
    """

    def __init__(self, cfg: ImuConfig, rng: np.random.Generator, rate_hz: float = 200.0) -> None:
        self.cfg = cfg
        self._normals = NormalBlocks(rng)
        self._ideal = cfg.ideal
        half_band = 0.5 * rate_hz  # white noise of a density over the Nyquist band
        self.sigma_acc_m_s2 = math.sqrt(cfg.sigma_acc_m_s2**2
                                        + cfg.acc_noise_density_m_s2_rt_hz**2 * half_band)
        self.sigma_gyro_rad_s = math.sqrt(cfg.sigma_gyro_rad_s**2
                                          + cfg.gyro_noise_density_rad_s_rt_hz**2 * half_band)
        dt_rt_s = math.sqrt(1.0 / rate_hz)
        walk = [cfg.acc_bias_walk_m_s2_rt_s] * 3 + [cfg.gyro_bias_walk_rad_s_rt_s] * 3
        self._walk = np.array(walk) * dt_rt_s
        if self._ideal:
            self.bias = np.zeros(6)  # [acc (m/s²), gyro (rad/s)] per FRD axis
            self.scale = np.zeros(6)
        else:
            draw = rng.standard_normal(12)
            turn_on = [cfg.acc_bias_turn_on_m_s2] * 3 + [cfg.gyro_bias_turn_on_rad_s] * 3
            self.bias = draw[:6] * np.array(turn_on)
            self.scale = draw[6:] * np.array([cfg.acc_scale_factor] * 3 + [cfg.gyro_scale_factor] * 3)

    def measure(self, f_frd_m_s2: np.ndarray, omega_frd_rad_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Noisy (acc_frd_m_s2, gyro_frd_rad_s) blocks of the same shape (n, 3) as the inputs.

        The white noise is ``rng.standard_normal((n, 6))`` (served from blocks: the same stream);
        a non-ideal IMU then takes (n, 6) more for the bias walk (the bias of sample k includes
        its own step)."""
        n = f_frd_m_s2.shape[0]
        noise = self._normals.take(6 * n).reshape(n, 6)
        if self._ideal:
            acc = f_frd_m_s2 + self.cfg.sigma_acc_m_s2 * noise[:, :3]
            gyro = omega_frd_rad_s + self.cfg.sigma_gyro_rad_s * noise[:, 3:]
            return acc, gyro
        steps = self._normals.take(6 * n).reshape(n, 6) * self._walk
        bias = self.bias + np.cumsum(steps, axis=0)
        self.bias = bias[-1].copy()
        true = np.hstack([f_frd_m_s2, omega_frd_rad_s])
        sigma = np.array([self.sigma_acc_m_s2] * 3 + [self.sigma_gyro_rad_s] * 3)
        out = true * (1.0 + self.scale) + bias + sigma * noise
        return out[:, :3], out[:, 3:]
