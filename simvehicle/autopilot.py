"""Cascaded position/attitude controller (eq. 9-11), flying on the ESTIMATED state.

Outer loop (control rate): PID on the estimate, integral active only within ``eps_int`` of
the reference (eq. 9), small-angle mapping to roll/pitch (eq. 10, written for NED/FRD in
the heading frame: pitching nose-down accelerates forward, so ``θ_cmd = -a_fwd / g`` and
``φ_cmd = +a_right / g``), collective thrust ``T = m (g - a_down) / (cos φ cos θ)``
(the paper's ``m (g + a_z)`` with z up, plus tilt compensation).
Inner loop (physics rate): PD on roll/pitch with rate damping (eq. 11); yaw held the same way.

The autopilot's navigation state is the latest estimate; in a control period that brings no
newer one it is dead-reckoned with the vehicle's own IMU and attitude (specific force rotated
to NED plus gravity), so it stays current while the estimate is late. Without a fresh estimate
(none yet, non-finite, or older than ``stale_estimate_s``) the autopilot holds on its own: it
brakes to zero velocity at the dead-reckoned point where the estimate went stale (or its start
point) and stays there until a fresh estimate returns.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from companion.domain.rotation import quaternion_to_euler, rotation_matrix
from companion.domain.samples import NavEstimate, Setpoint
from simvehicle.config import AutopilotConfig, VehicleConfig


def _finite(*arrays: np.ndarray) -> bool:
    return all(math.isfinite(x) for a in arrays for x in a.tolist())


_ZERO3 = np.zeros(3)
_ZERO3.flags.writeable = False
_TWO_PI = 2 * math.pi


class Autopilot:
    """Outer loop ``outer()`` once per control period, inner loop ``inner()`` every physics step."""

    def __init__(self, cfg: AutopilotConfig, vehicle: VehicleConfig, p_hold_ned_m: np.ndarray,
                 yaw_hold_rad: float = 0.0) -> None:
        self.cfg = cfg
        self._m = vehicle.mass_kg
        self._g = vehicle.gravity_m_s2
        self._t_max = vehicle.max_thrust_n
        self._tau_max = vehicle.max_torque_nm
        self._dt_s = 1.0 / vehicle.control_rate_hz
        self._kp = (cfg.kp_xy_1_s2, cfg.kp_xy_1_s2, cfg.kp_z_1_s2)
        self._kd = (cfg.kd_xy_1_s, cfg.kd_xy_1_s, cfg.kd_z_1_s)
        self._ki = (cfg.ki_xy_1_s3, cfg.ki_xy_1_s3, cfg.ki_z_1_s3)
        self._tilt = cfg.max_tilt_rad
        self._k_att, self._d_att = cfg.k_att_nm_rad, cfg.d_att_nm_s_rad
        self._k_yaw, self._d_yaw = cfg.k_yaw_nm_rad, cfg.d_yaw_nm_s_rad
        self.yaw_hold_rad = yaw_hold_rad
        self.hold_p_ned_m = np.array(p_hold_ned_m, dtype=float)
        # the autopilot's own navigation state: the last estimate, dead-reckoned while stale
        self.nav_p_ned_m = self.hold_p_ned_m.copy()
        self.nav_v_ned_m_s = np.zeros(3)
        self._nav_est_t_us = -1  # boot time of the estimate the navigation state was last set from
        self._imu_period: tuple[np.ndarray, np.ndarray] | None = None  # (q_ned_frd, acc_frd) blocks
        self._g_ned = np.array([0.0, 0.0, self._g])
        self._physics_dt_s = vehicle.physics_dt_us * 1e-6
        self.integral_m_s = [0.0, 0.0, 0.0]  # ∫ (p_ref - p_hat) dt per NED axis
        self.holding = True  # True while flying without a fresh estimate
        self.roll_cmd_rad = 0.0
        self.pitch_cmd_rad = 0.0
        self.accel_down_cmd_m_s2 = 0.0

    # -- outer loop --------------------------------------------------------------------
    def outer(self, t_us: int, estimate: NavEstimate | None, setpoint: Setpoint | None) -> None:
        cfg = self.cfg
        stale_us = cfg.stale_estimate_s * 1e6
        fresh = (
            estimate is not None
            and 0 <= t_us - estimate.t_us <= stale_us
            and _finite(estimate.p_ned_m, estimate.v_ned_m_s)
        )
        if fresh and estimate.t_us > self._nav_est_t_us:  # type: ignore[union-attr]
            assert estimate is not None
            self.nav_p_ned_m = np.array(estimate.p_ned_m, dtype=float)
            self.nav_v_ned_m_s = np.array(estimate.v_ned_m_s, dtype=float)
            self._nav_est_t_us = estimate.t_us
        elif self._imu_period is not None:  # no newer estimate: dead-reckon the last period
            self.dead_reckon(*self._imu_period)
        self._imu_period = None
        if fresh:
            self.holding = False
        elif not self.holding or math.hypot(*self.nav_v_ned_m_s.tolist()) > cfg.hold_brake_speed_m_s:
            # lost the estimate: brake (the point held moves along until slow), then hold that point
            self.holding = True
            self.hold_p_ned_m = self.nav_p_ned_m.copy()
        sp_ok = (
            setpoint is not None
            and 0 <= t_us - setpoint.t_us <= stale_us
            and _finite(setpoint.p_ned_m, setpoint.v_ned_m_s, setpoint.a_ned_m_s2)
        )
        if fresh and sp_ok:
            assert setpoint is not None
            p_ref, v_ref, a_ref = setpoint.p_ned_m, setpoint.v_ned_m_s, setpoint.a_ned_m_s2
            self.hold_p_ned_m = np.array(p_ref, dtype=float)
        else:
            p_ref, v_ref, a_ref = self.hold_p_ned_m, _ZERO3, _ZERO3
        self.track(p_ref, v_ref, a_ref)

    def track(self, p_ref: np.ndarray, v_ref: np.ndarray, a_ref: np.ndarray) -> None:
        """Eq. 9-10 on the autopilot's navigation state: sets roll/pitch/down-acceleration commands."""
        cfg = self.cfg
        err = [r - p for r, p in zip(p_ref.tolist(), self.nav_p_ned_m.tolist(), strict=True)]
        if math.sqrt(err[0] ** 2 + err[1] ** 2 + err[2] ** 2) < cfg.eps_int_m:
            self.integral_m_s = [i + e * self._dt_s for i, e in zip(self.integral_m_s, err, strict=True)]
        lim_i, lim_a = cfg.max_integral_m_s2, cfg.max_accel_m_s2
        a_n, a_e, a_d = (
            min(lim_a, max(-lim_a, a + kp * e + kd * (vr - v) + min(lim_i, max(-lim_i, ki * i))))
            for a, e, vr, v, i, kp, kd, ki in zip(
                a_ref.tolist(), err, v_ref.tolist(), self.nav_v_ned_m_s.tolist(), self.integral_m_s,
                self._kp, self._kd, self._ki, strict=True,
            )
        )
        c, s = math.cos(self.yaw_hold_rad), math.sin(self.yaw_hold_rad)
        a_fwd, a_right = c * a_n + s * a_e, -s * a_n + c * a_e
        self.pitch_cmd_rad = min(self._tilt, max(-self._tilt, -a_fwd / self._g))
        self.roll_cmd_rad = min(self._tilt, max(-self._tilt, a_right / self._g))
        self.accel_down_cmd_m_s2 = a_d

    def imu_period(self, q_ned_frd: np.ndarray, acc_frd_m_s2: np.ndarray) -> None:
        """The attitude (n, 4) and measured specific force (n, 3) of the period just flown; the next
        ``outer()`` dead-reckons with them unless a newer estimate replaces the navigation state."""
        self._imu_period = (q_ned_frd, acc_frd_m_s2)

    def dead_reckon(self, q_ned_frd: np.ndarray, acc_frd_m_s2: np.ndarray) -> None:
        """Propagate the own navigation state over one period of IMU samples (physics rate)."""
        dt_s = self._physics_dt_s
        acc_ned_m_s2 = np.einsum("nij,nj->ni", rotation_matrix(q_ned_frd), acc_frd_m_s2) + self._g_ned
        v = self.nav_v_ned_m_s + dt_s * np.cumsum(acc_ned_m_s2, axis=0)
        self.nav_p_ned_m = self.nav_p_ned_m + dt_s * v.sum(axis=0)
        self.nav_v_ned_m_s = v[-1].copy()

    # -- inner loop --------------------------------------------------------------------
    def inner(self, x: Sequence[float]) -> tuple[float, float, float, float]:
        """Eq. 11: (thrust_n, tau_roll, tau_pitch, tau_yaw) from the attitude and body rates of the
        rigid-body state ``x`` (``RigidBody.x`` layout: quaternion at 6-9, body rates at 10-12)."""
        roll, pitch, yaw = quaternion_to_euler(x[6:10])
        p, q, r = x[10], x[11], x[12]
        tilt_cos = max(0.5, math.cos(roll) * math.cos(pitch))
        thrust = min(self._t_max, max(0.0, self._m * (self._g - self.accel_down_cmd_m_s2) / tilt_cos))
        lim = self._tau_max
        yaw_err = (self.yaw_hold_rad - yaw + math.pi) % _TWO_PI - math.pi
        tx = self._k_att * (self.roll_cmd_rad - roll) - self._d_att * p
        ty = self._k_att * (self.pitch_cmd_rad - pitch) - self._d_att * q
        tz = self._k_yaw * yaw_err - self._d_yaw * r
        return thrust, min(lim, max(-lim, tx)), min(lim, max(-lim, ty)), min(lim, max(-lim, tz))
