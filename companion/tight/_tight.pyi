"""Types of the tight filter's C core (``_tight.c``); the formulas are model.py's."""

from typing import Any

import numpy as np

def predict_cov(P: np.ndarray, T_s: float, nA: Any, nB: Any, live: np.ndarray, q_acc_ne: float,
                q_acc_d: float, q_rw: float, q_ned: float, q_clock: float, q_isb: float, q_drift: float,
                q_heading: float, q_yaw_bias: float, heading_live: bool, a: Any = None, b: Any = None,
                q_hold_ne: float = 0.0, q_hold_d: float = 0.0, q_hold_rw: float = 0.0, q_coast: float = 0.0,
                q_baro: float = 0.0) -> np.ndarray: ...
def held_noise(a: Any, b: Any, q_white: tuple[float, float, float], q_rw: float, q_coast: float
               ) -> tuple[float, ...] | None: ...
def innovations(x: np.ndarray, P: np.ndarray, r0_ecef_m: np.ndarray, c_ecef_ned: np.ndarray,
                sat_pos_ecef_m: np.ndarray, slot: np.ndarray, z_m: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]: ...
def update(x: np.ndarray, P: np.ndarray, H: np.ndarray, HP: np.ndarray, y: np.ndarray, r: np.ndarray,
           used: np.ndarray, r0_ecef_m: np.ndarray, c_ecef_ned: np.ndarray, sat_pos_ecef_m: np.ndarray,
           sat_vel_ecef_m_s: np.ndarray, z_rate_m_s: np.ndarray, r_rate_m2_s2: np.ndarray, gate2: float
           ) -> tuple[np.ndarray, np.ndarray, float, int]: ...
def belief_step(theta: np.ndarray, h_fast: np.ndarray, h_slow: np.ndarray, y: np.ndarray, s0: np.ndarray,
                r_nominal: np.ndarray, theta_prior: np.ndarray, eta: float, lambda_reg: float,
                alpha_fast: float, alpha_slow: float, omega_fast: float, nu: float, k: float, kappa: float,
                theta_min: float, theta_max: float, gate2: float, first_order: bool, epoch_scale: bool,
                early: float
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]: ...
def snapshot(H: np.ndarray, y: np.ndarray, r: np.ndarray, used: np.ndarray, p_pred: np.ndarray,
             sat_pos_ecef_m: np.ndarray, sat_vel_ecef_m_s: np.ndarray, rate_m_s: np.ndarray,
             r_rate_m2_s2: np.ndarray, r0_ecef_m: np.ndarray, c_ecef_ned: np.ndarray
             ) -> np.ndarray | None: ...
def carry_states(rows: np.ndarray, dt_s: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]: ...
