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

With ``gnss_velocity_reference`` (ArduPilot DCM's drift correction, Premerlani's "roll-pitch drift
compensation"), the reference is no longer gravity alone. Between two usable fixes (≥
``gnss_min_satellites``, a velocity reported), each taken as valid at its arrival − ``gnss_delay_s``
(the lag the autopilot assumes, not the receiver's true one), the specific force rotated to NED with the
estimate is integrated (``F``, over the same interval Δt), and the fixes' velocities give the one the
vehicle really had:

    g_b = F / (Δt g),   g_e = ((v_k − v_{k−1}) / Δt − g e_down) / g     (NED, both normalised)
    e_rp = Rᵀ (g_b × g_e)   held as the correction kp_rp_gnss e_rp until the next fix,
    b̂  ← b̂ − ki_rp e_rp Δt  once per fix

(for a non-accelerating vehicle ``g_e = −e_down`` and this is the accelerometer's tilt error above,
averaged over the interval). Like DCM, no innovation gate: the receiver's velocity errors, its latency
(true vs assumed) and its dropouts are the errors of this reference. Without a usable fix for
``gnss_timeout_s`` the filter falls back to the accelerometer alone (the plain filter above) until two
fixes in a row are usable again:
DCM's fallback without a GPS lock (for a multicopter, which has no airspeed to fall back on).

Plain float arithmetic per sample (a sequential filter; ~5 µs per 200 Hz sample).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from companion.domain.physics import STANDARD_GRAVITY_M_S2
from companion.domain.rotation import rotation_terms, yaw_of
from simvehicle.config import AhrsConfig

_TWO_PI = 2.0 * math.pi


def _wrap(a: float) -> float:
    return (a + math.pi) % _TWO_PI - math.pi


def _unit(x: float, y: float, z: float) -> tuple[float, float, float] | None:
    n = math.sqrt(x * x + y * y + z * z)
    return None if not n > 1e-9 else (x / n, y / n, z / n)


def gnss_tilt_error(f_int_ned: Sequence[float], dv_ned_m_s: Sequence[float], dt_s: float,
                    r_ned_frd: Sequence[float]) -> tuple[float, float, float] | None:
    """Roll/pitch error (body) of the GNSS-aided reference: ``Rᵀ (g_b × g_e)`` with ``g_b`` the
    integrated NED specific force ``f_int`` over ``dt`` and ``g_e`` the one the velocity change
    ``dv`` implies (module docstring); None when either is degenerate. ``r_ned_frd`` row-major R."""
    g = STANDARD_GRAVITY_M_S2
    gb = _unit(*(c / (dt_s * g) for c in f_int_ned))
    ge = _unit(dv_ned_m_s[0] / (dt_s * g), dv_ned_m_s[1] / (dt_s * g), dv_ned_m_s[2] / (dt_s * g) - 1.0)
    if gb is None or ge is None:
        return None
    ex, ey, ez = gb[1] * ge[2] - gb[2] * ge[1], gb[2] * ge[0] - gb[0] * ge[2], gb[0] * ge[1] - gb[1] * ge[0]
    r = r_ned_frd
    return (r[0] * ex + r[3] * ey + r[6] * ez, r[1] * ex + r[4] * ey + r[7] * ez,
            r[2] * ex + r[5] * ey + r[8] * ez)


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
        # GNSS-aided reference: the NED specific force integrated up to each tick (index − base),
        # the last usable fix (assumed validity tick, velocity, arrival tick), the held correction
        self._cum: list[tuple[float, float, float]] = [(0.0, 0.0, 0.0)]
        self._cum_base = 0
        self._delay_ticks = round(cfg.gnss_delay_s * rate_hz)
        self._timeout_ticks = max(1, round(cfg.gnss_timeout_s * rate_hz))
        self._prev_fix: tuple[int, tuple[float, float, float], int] | None = None
        self._held = (0.0, 0.0, 0.0)
        self._aided_until = -1  # the held correction applies through this tick
        self.gnss_corrections = 0  # fixes that corrected the tilt (counters for tests and checks)

    def update(self, acc_frd_m_s2: np.ndarray, gyro_frd_rad_s: np.ndarray, q_true_ned_frd: np.ndarray,
               gnss: Sequence[tuple[int, np.ndarray | None, int]] = ()) -> np.ndarray:
        """Estimated attitude after each sample of the period, (n, 4); ``q_true`` only feeds the
        heading reference (a magnetometer sees the true heading). ``gnss``: the fixes that arrived in
        the period as (sample index of arrival, NED velocity or None, satellites), used only with
        ``gnss_velocity_reference``."""
        c, dt = self.cfg, self.dt_s
        n = acc_frd_m_s2.shape[0]
        t0 = self._tick
        ticks = [(t0 + i + 1) % self._heading_every == 0 for i in range(n)]
        n_heading = sum(ticks)
        heading_noise = (c.heading_noise_rad * self._rng.standard_normal(n_heading)).tolist()
        self._tick += n
        aided = c.gnss_velocity_reference
        arrivals: dict[int, list[tuple[np.ndarray | None, int]]] = {}
        if aided:
            for i_arr, v_fix, sats in gnss:
                arrivals.setdefault(int(i_arr), []).append((v_fix, int(sats)))
        cum = self._cum
        sx, sy, sz = cum[-1]
        out = np.empty((n, 4))
        w, x, y, z = self.q
        bx, by, bz = self.gyro_bias_rad_s
        kp, ki = c.kp_rp_1_s, c.ki_rp_1_s2
        kpy, kiy = c.kp_yaw_1_s, c.ki_yaw_1_s2
        h = 0
        aided_until = self._aided_until
        for i, ((fx, fy, fz), (gx, gy, gz)) in enumerate(zip(acc_frd_m_s2.tolist(), gyro_frd_rad_s.tolist(),
                                                             strict=True)):
            r = rotation_terms(w, x, y, z)
            # estimated down axis in body: third row of R_ned_frd
            vx, vy, vz = r[6:]
            if aided:
                sx += (r[0] * fx + r[1] * fy + r[2] * fz) * dt
                sy += (r[3] * fx + r[4] * fy + r[5] * fz) * dt
                sz += (r[6] * fx + r[7] * fy + r[8] * fz) * dt
                cum.append((sx, sy, sz))
            if aided and t0 + i + 1 <= aided_until:
                cx, cy, cz = self._held
                ix = iy = iz = 0.0
            else:
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
            if not aided or i not in arrivals:
                continue
            tick = t0 + i + 1
            for v_fix, sats in arrivals[i]:
                e_dt = self._gnss_fix(tick, v_fix, sats, rotation_terms(w, x, y, z))
                if e_dt is not None:
                    (ex, ey, ez), dt_fix = e_dt
                    kg = c.kp_rp_gnss_1_s
                    self._held = (kg * ex, kg * ey, kg * ez)
                    bx, by, bz = bx - ki * ex * dt_fix, by - ki * ey * dt_fix, bz - ki * ez * dt_fix
                    aided_until = self._aided_until = tick + self._timeout_ticks
                    self.gnss_corrections += 1
        self.q = (w, x, y, z)
        self.gyro_bias_rad_s = [bx, by, bz]
        keep = self._timeout_ticks + self._delay_ticks + 2
        if len(cum) > 2 * keep:
            drop = len(cum) - keep
            del cum[:drop]
            self._cum_base += drop
        return out

    def _gnss_fix(self, tick: int, v_fix: np.ndarray | None, sats: int,
                  r: Sequence[float]) -> tuple[tuple[float, float, float], float] | None:
        """A fix arrived at ``tick``: the body tilt error and the interval it spans, or None (not
        usable, the first after a gap, or outside the kept history)."""
        if v_fix is None or sats < self.cfg.gnss_min_satellites or not np.isfinite(v_fix).all():
            return None
        v = (float(v_fix[0]), float(v_fix[1]), float(v_fix[2]))
        t_valid = tick - self._delay_ticks
        prev = self._prev_fix
        if (prev is None or tick - prev[2] > self._timeout_ticks or t_valid <= prev[0]
                or prev[0] < self._cum_base):
            self._prev_fix = (t_valid, v, tick)  # (re)start: the next fix is compared with this one
            return None
        a, b = self._cum[prev[0] - self._cum_base], self._cum[t_valid - self._cum_base]
        dt_fix = (t_valid - prev[0]) * self.dt_s
        f_int = (b[0] - a[0], b[1] - a[1], b[2] - a[2])
        dv = (v[0] - prev[1][0], v[1] - prev[1][1], v[2] - prev[1][2])
        self._prev_fix = (t_valid, v, tick)
        e = gnss_tilt_error(f_int, dv, dt_fix, r)
        return None if e is None else (e, dt_fix)


def attitude_error_rad(q_est: np.ndarray, q_true: np.ndarray) -> np.ndarray:
    """Angle (rad) of the rotation between estimated and true attitudes, per row of (n, 4) blocks."""
    d = np.abs(np.sum(np.asarray(q_est) * np.asarray(q_true), axis=-1))
    return 2.0 * np.arccos(np.clip(d, 0.0, 1.0))
