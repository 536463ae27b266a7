"""Onboard attitude estimate: a Mahony complementary filter on the simulated IMU (body FRD → NED).

What a flight controller without GNSS aiding of its attitude would send: the gyro integrated,
roll/pitch pulled toward the accelerometer's gravity direction, yaw toward a heading reference
(a magnetometer: true yaw + a bias drawn once + white noise, at ``heading_rate_hz``), gyro biases
estimated by the integral terms. Its errors are real ones: the accelerometer sees specific force,
so while the vehicle accelerates the "gravity" it pulls toward is tilted by ≈ a / g, and the gyro
bias / scale errors leak in between corrections.

Per sample, with ``v̂ = Rᵀ e_down`` (estimated down axis in body), ``a = −f / |f|`` (measured):

    e_rp  = a × v̂                       (roll/pitch error, body)
    e_yaw = wrap(ψ_ref − ψ̂) · v̂         (heading error about the down axis, body; at heading samples)
    ω'    = ω − b̂ + kp_rp e_rp + kp_yaw e_yaw
    b̂    ← b̂ − (ki_rp e_rp + ki_yaw e_yaw) Δt
    q     ← normalise(q ⊗ [1, ω' Δt / 2])

Plain float arithmetic per sample (a sequential filter; ~5 µs per 200 Hz sample).
"""

from __future__ import annotations

import math

import numpy as np

from companion.domain.rotation import rotation_terms, yaw_of
from simvehicle.config import AhrsConfig

_TWO_PI = 2.0 * math.pi


def _wrap(a: float) -> float:
    return (a + math.pi) % _TWO_PI - math.pi


def _mul(a: tuple[float, ...], b: tuple[float, ...]) -> tuple[float, float, float, float]:
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)


class Ahrs:
    """The complementary filter; ``update`` takes one control period of IMU samples (seeded)."""

    def __init__(self, cfg: AhrsConfig, rate_hz: float, q0_ned_frd: np.ndarray,
                 rng: np.random.Generator) -> None:
        self.cfg = cfg
        self.dt_s = 1.0 / rate_hz
        self._rng = rng
        self._heading_every = max(1, round(rate_hz / cfg.heading_rate_hz))
        self._tick = 0
        e = cfg.initial_tilt_error_rad * rng.standard_normal(3)
        half = 0.5 * e
        dq = (1.0, float(half[0]), float(half[1]), float(half[2]))
        q = _mul(tuple(float(c) for c in q0_ned_frd), dq)
        n = math.sqrt(sum(c * c for c in q))
        self.q = (q[0] / n, q[1] / n, q[2] / n, q[3] / n)
        self.heading_bias_rad = float(cfg.heading_bias_rad * rng.standard_normal())
        self.gyro_bias_rad_s = [0.0, 0.0, 0.0]  # the filter's estimate b̂

    def update(self, acc_frd_m_s2: np.ndarray, gyro_frd_rad_s: np.ndarray,
               q_true_ned_frd: np.ndarray) -> np.ndarray:
        """Estimated attitude after each sample of the period, (n, 4); ``q_true`` only feeds the
        heading reference (a magnetometer sees the true heading)."""
        c, dt = self.cfg, self.dt_s
        n = acc_frd_m_s2.shape[0]
        ticks = [(self._tick + i + 1) % self._heading_every == 0 for i in range(n)]
        n_heading = sum(ticks)
        heading_noise = (c.heading_noise_rad * self._rng.standard_normal(n_heading)).tolist()
        self._tick += n
        out = np.empty((n, 4))
        w, x, y, z = self.q
        bx, by, bz = self.gyro_bias_rad_s
        kp, ki = c.kp_rp_1_s, c.ki_rp_1_s2
        kpy, kiy = c.kp_yaw_1_s, c.ki_yaw_1_s2
        h = 0
        for i, ((fx, fy, fz), (gx, gy, gz)) in enumerate(zip(acc_frd_m_s2.tolist(), gyro_frd_rad_s.tolist(),
                                                             strict=True)):
            # estimated down axis in body: third row of R_ned_frd
            vx, vy, vz = rotation_terms(w, x, y, z)[6:]
            norm = math.sqrt(fx * fx + fy * fy + fz * fz)
            ex = ey = ez = 0.0
            if norm > 1e-6:
                ax, ay, az = -fx / norm, -fy / norm, -fz / norm
                ex, ey, ez = ay * vz - az * vy, az * vx - ax * vz, ax * vy - ay * vx
            cx, cy, cz = kp * ex, kp * ey, kp * ez
            ix, iy, iz = ki * ex, ki * ey, ki * ez
            if ticks[i]:
                k = self._heading_every
                psi_ref = yaw_of(q_true_ned_frd[i]) + self.heading_bias_rad + heading_noise[h]
                h += 1
                e_psi = _wrap(psi_ref - yaw_of((w, x, y, z)))
                cx, cy, cz = cx + kpy * k * e_psi * vx, cy + kpy * k * e_psi * vy, cz + kpy * k * e_psi * vz
                ix, iy, iz = ix + kiy * k * e_psi * vx, iy + kiy * k * e_psi * vy, iz + kiy * k * e_psi * vz
            bx, by, bz = bx - ix * dt, by - iy * dt, bz - iz * dt
            hx, hy, hz = 0.5 * dt * (gx - bx + cx), 0.5 * dt * (gy - by + cy), 0.5 * dt * (gz - bz + cz)
            w, x, y, z = (w - x * hx - y * hy - z * hz, x + w * hx + y * hz - z * hy,
                          y + w * hy - x * hz + z * hx, z + w * hz + x * hy - y * hx)
            s = 1.0 / math.sqrt(w * w + x * x + y * y + z * z)
            w, x, y, z = w * s, x * s, y * s, z * s
            out[i] = (w, x, y, z)
        self.q = (w, x, y, z)
        self.gyro_bias_rad_s = [bx, by, bz]
        return out


def attitude_error_rad(q_est: np.ndarray, q_true: np.ndarray) -> np.ndarray:
    """Angle (rad) of the rotation between estimated and true attitudes, per row of (n, 4) blocks."""
    d = np.abs(np.sum(np.asarray(q_est) * np.asarray(q_true), axis=-1))
    return 2.0 * np.arccos(np.clip(d, 0.0, 1.0))
