"""State, process and measurement models of the tightly coupled filter (pure numpy).

State (``N_STATE`` = 21)::

    x = [p (NED, m), v (NED, m/s), a (body accelerometer bias, m/s²), d (NED acceleration error,
         m/s²), c_s (receiver clock × c per system slot, m; ``CLOCK_SLOTS``), ḋ (common drift, m/s),
         ψ₀ (odometry heading offset, rad), b_ω (odometry yaw-rate bias, rad/s)]

and, once a barometer was seen (``N_STATE_BARO`` = 22: the entries' state grows by one; without a
barometer it stays 21, bit for bit as before), ``b_baro`` (m, ``I_BARO``): the pressure altitude's
unknown datum, a random walk (the sensor's thermal drift, the weather).

``p, v, a, d`` move exactly as the loose filter's (``companion.estimator.model``: the IMU history's
prefix integrals give the block's mean and transition for any attitude history); every system's
clock moves with the common drift, ``c_s ← c_s + T ḋ``. A system's slot is live once one of its
satellites was seen (before that its value and variance are 0 and it gets no process noise).

Measurements, per satellite ``i`` with position ``r_i`` (ECEF at transmission) and velocity ``u_i``,
the receiver at ``r = r₀ + C p`` (``C`` = R_ecef_ned at home, ``r₀`` home's ECEF), ``v_e = C v``:

    pseudorange      ρ_i = |r_i − r| + ω_e (x_i y − y_i x) / c + c_s(i)
    range rate       ρ̇_i = g_i (1 − l_i·u_i / c) + ω_e (u_iy x + y_i v_x − u_ix y − x_i v_y) / c + ḋ,
                     g_i = l_i · (u_i − v_e),  l_i = (r_i − r) / |r_i − r|

    barometric height h_baro = −p_D + b_baro

(the Sagnac term and its rate, the light-time rate of ``companion.gnss.spp``; the barometer's height is
the state's above the frame's tangent plane: a kilometre away the Earth's curvature puts it 8 cm lower,
well inside the barometer's σ). Their Jacobians are exact (tested against finite differences); H has as
many columns as the state ``x`` (21 or 22).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from companion.gnss.constants import C_M_S, OMEGA_E_RAD_S
from companion.gnss.geometry import ecef_to_geodetic, ecef_to_ned_matrix, geodetic_to_ecef
from companion.gnss.systems import System

CLOCK_SLOTS: tuple[System, ...] = tuple(System)
SLOT_OF = np.full(max(int(s) for s in System) + 1, -1, dtype=int)
for _i, _s in enumerate(CLOCK_SLOTS):
    SLOT_OF[int(_s)] = _i
N_NAV = 12
I_P, I_V, I_A, I_D = 0, 3, 6, 9
I_CLK = N_NAV
N_CLK = len(CLOCK_SLOTS)
I_DRIFT = I_CLK + N_CLK
I_HEADING = I_DRIFT + 1  # heading offset ψ₀ of a ground vehicle's odometry (rad): heading = ψ₀ + ∫ yaw rate
I_YAW_BIAS = I_HEADING + 1  # the odometry yaw rate's bias b_ω (rad/s): ψ̇₀ = −b_ω
N_STATE = I_YAW_BIAS + 1
I_BARO = N_STATE  # the barometer's datum offset b_baro (m), once a barometer was seen
N_STATE_BARO = I_BARO + 1
NAV_OF_LOOSE = np.r_[0:6, 9:15]  # the loose 15-state's p, v, a, d (its GNSS bias b dropped)
_W = OMEGA_E_RAD_S / C_M_S


class Frame(NamedTuple):
    """The local NED frame's anchor in ECEF."""

    r0_ecef_m: np.ndarray  # (3,)
    c_ecef_ned: np.ndarray  # (3, 3): d_ecef = C d_ned
    lat_rad: float
    lon_rad: float
    h_m: float

    @classmethod
    def at_ecef(cls, r0_ecef_m: np.ndarray) -> Frame:
        lat, lon, h = (float(v) for v in ecef_to_geodetic(np.asarray(r0_ecef_m, float)))
        return cls.at_geodetic(lat, lon, h)

    @classmethod
    def at_geodetic(cls, lat_rad: float, lon_rad: float, h_m: float) -> Frame:
        r0 = geodetic_to_ecef(lat_rad, lon_rad, h_m)
        return cls(np.asarray(r0, float), ecef_to_ned_matrix(lat_rad, lon_rad).T, lat_rad, lon_rad, h_m)

    def ecef(self, p_ned_m: np.ndarray) -> np.ndarray:
        return self.r0_ecef_m + self.c_ecef_ned @ p_ned_m

    def ned(self, r_ecef_m: np.ndarray) -> np.ndarray:
        return self.c_ecef_ned.T @ (np.asarray(r_ecef_m, float) - self.r0_ecef_m)


def pseudorange(x: np.ndarray, frame: Frame, sat_pos_ecef_m: np.ndarray, slot: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(predicted pseudoranges (m,), H (m, N_STATE), unit line of sight receiver→satellite (m, 3))."""
    r = frame.ecef(x[I_P:I_P + 3])
    d = sat_pos_ecef_m - r
    rng = np.sqrt(np.einsum("ij,ij->i", d, d))
    los = d / rng[:, None]
    sag = _W * (sat_pos_ecef_m[:, 0] * r[1] - sat_pos_ecef_m[:, 1] * r[0])
    pred = rng + sag + x[I_CLK + slot]
    m = len(slot)
    H = np.zeros((m, len(x)))
    dr = -los
    dr[:, 0] -= _W * sat_pos_ecef_m[:, 1]
    dr[:, 1] += _W * sat_pos_ecef_m[:, 0]
    H[:, I_P:I_P + 3] = dr @ frame.c_ecef_ned
    H[np.arange(m), I_CLK + slot] = 1.0
    return pred, H, los


def range_rate(x: np.ndarray, frame: Frame, sat_pos_ecef_m: np.ndarray, sat_vel_ecef_m_s: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """(predicted pseudorange rates (m,), H (m, N_STATE)); see the module doc."""
    C = frame.c_ecef_ned
    r = frame.ecef(x[I_P:I_P + 3])
    ve = C @ x[I_V:I_V + 3]
    rs, us = sat_pos_ecef_m, sat_vel_ecef_m_s
    d = rs - r
    rng = np.sqrt(np.einsum("ij,ij->i", d, d))
    los = d / rng[:, None]
    dv = us - ve
    g = np.einsum("ij,ij->i", los, dv)
    s = np.einsum("ij,ij->i", los, us)
    f = 1.0 - s / C_M_S
    sag = _W * (us[:, 0] * r[1] + rs[:, 0] * ve[1] - us[:, 1] * r[0] - rs[:, 1] * ve[0])
    pred = g * f + sag + x[I_DRIFT]
    # ∂l/∂r = −(I − l lᵀ)/ρ:  ∂(l·w)/∂r = −(w − (l·w) l)/ρ
    dg_dr = -(dv - g[:, None] * los) / rng[:, None]
    ds_dr = -(us - s[:, None] * los) / rng[:, None]
    dm_dr = dg_dr * f[:, None] - (g / C_M_S)[:, None] * ds_dr
    dm_dr[:, 0] -= _W * us[:, 1]
    dm_dr[:, 1] += _W * us[:, 0]
    dm_dv = -los * f[:, None]
    dm_dv[:, 0] -= _W * rs[:, 1]
    dm_dv[:, 1] += _W * rs[:, 0]
    H = np.zeros((len(rs), len(x)))
    H[:, I_P:I_P + 3] = dm_dr @ C
    H[:, I_V:I_V + 3] = dm_dv @ C
    H[:, I_DRIFT] = 1.0
    return pred, H


def speed(x: np.ndarray) -> tuple[float, np.ndarray]:
    """(horizontal speed |v_NE| (m/s), its H row (N_STATE,))."""
    vn, ve = float(x[I_V]), float(x[I_V + 1])
    s = float(np.hypot(vn, ve))
    h = np.zeros(len(x))
    if s > 1e-6:
        h[I_V], h[I_V + 1] = vn / s, ve / s
    return s, h


def odometry_velocity(x: np.ndarray, speed_m_s: float, yaw_integral_rad: float
                      ) -> tuple[np.ndarray, np.ndarray]:
    """A ground vehicle's odometry as a horizontal velocity: (v_NE − s [cos ψ, sin ψ], H (2, N_STATE))
    with ψ = ψ₀ + ∫ yaw rate (the vehicle moves along its heading: no side slip)."""
    psi = float(x[I_HEADING]) + yaw_integral_rad
    c, s = np.cos(psi), np.sin(psi)
    y = -np.array([x[I_V] - speed_m_s * c, x[I_V + 1] - speed_m_s * s])
    H = np.zeros((2, len(x)))
    H[0, I_V] = H[1, I_V + 1] = 1.0
    H[0, I_HEADING] = speed_m_s * s
    H[1, I_HEADING] = -speed_m_s * c
    return y, H


def lateral_velocity(x: np.ndarray, yaw_integral_rad: float) -> tuple[np.ndarray, np.ndarray]:
    """A ground vehicle's velocity across its heading ψ = ψ₀ + ∫ yaw rate, measured as zero (no side
    slip; a gyro's yaw rate without a wheel speed): (0 − v_across, H (1, N_STATE)),
    v_across = −v_N sin ψ + v_E cos ψ."""
    psi = float(x[I_HEADING]) + yaw_integral_rad
    c, s = np.cos(psi), np.sin(psi)
    H = np.zeros((1, len(x)))
    H[0, I_V], H[0, I_V + 1] = -s, c
    H[0, I_HEADING] = -(x[I_V] * c + x[I_V + 1] * s)
    return np.array([-(H[0, I_V] * x[I_V] + H[0, I_V + 1] * x[I_V + 1])]), H


def baro_height(x: np.ndarray) -> tuple[float, np.ndarray]:
    """(the barometer's predicted height −p_D + b_baro (m), its H row (N_STATE_BARO,)); ``x`` with b_baro."""
    h = np.zeros(len(x))
    h[I_P + 2] = -1.0
    h[I_BARO] = 1.0
    return float(x[I_BARO] - x[I_P + 2]), h


def elevation_rad(los_ecef: np.ndarray, frame: Frame) -> np.ndarray:
    """Elevation of receiver→satellite unit vectors at home (a few km away the difference is < 0.1°)."""
    down = los_ecef @ frame.c_ecef_ned[:, 2]
    return np.arcsin(np.clip(-down, -1.0, 1.0))


# --------------------------------------------------------------------------- propagation
def transition(T_s: float, nA: Any, nB: Any, live: np.ndarray, n: int = N_STATE) -> np.ndarray:
    """F over a block from the IMU history's (−A, −B) (row-major 9 each; ``history.rotation_blocks``):
    the loose filter's transition (``companion.estimator.model.transition_block``, its GNSS bias
    dropped) on (p, v, a, d); the live clocks moved by the common drift; ``n``: the state's size (with
    the baro offset: it stays)."""
    Fn = np.eye(n)
    F = Fn[:N_STATE, :N_STATE]  # a view
    F.flat[_F_T] = T_s
    h = -0.5 * T_s * T_s
    F.flat[_F_D] = (h, h, h, -T_s, -T_s, -T_s)
    F[0:3, I_A:I_A + 3] = np.reshape(nB, (3, 3))
    F[3:6, I_A:I_A + 3] = np.reshape(nA, (3, 3))
    F[I_CLK:I_DRIFT, I_DRIFT] = T_s * live
    F[I_HEADING, I_YAW_BIAS] = -T_s  # the heading offset integrates minus the yaw rate's bias
    return Fn


def process_noise(T_s: float, nA: Any, live: np.ndarray, q_acc_ne: float, q_acc_d: float,
                  q_rw: float, q_ned: float, q_clock: float, q_isb: float, q_drift: float,
                  q_heading: float = 0.0, q_yaw_bias: float = 0.0, q_baro: float = 0.0, n: int = N_STATE
                  ) -> np.ndarray:
    """Q over a block: the loose filter's (``companion.estimator.model.add_process_noise``: white
    acceleration, here with its own vertical density; body and NED bias random walks, the body one
    through the block's mean rotation) on (p, v, a, d); common clock phase, per-system offset and
    drift random walks on the live clock slots (``live``, float 0/1 (N_CLK,)); the heading offset's
    (the yaw rate's white noise) and the yaw-rate bias random walk integrated into it; with the baro
    offset (``n`` = N_STATE_BARO) its random walk (``q_baro``, m²/s)."""
    T, T2 = T_s, T_s * T_s
    T3, T4, T5 = T2 * T, T2 * T2, T2 * T2 * T
    w, e = q_rw, q_ned
    pp_ne, pp_d = q_acc_ne * T3 / 3.0, q_acc_d * T3 / 3.0
    pv_ne, pv_d = q_acc_ne * T2 / 2.0, q_acc_d * T2 / 2.0
    vv_ne, vv_d = q_acc_ne * T, q_acc_d * T
    pp, pv, vv = (w + e) * T5 / 20.0, (w + e) * T4 / 8.0, (w + e) * T3 / 3.0
    pd, vd = -e * T3 / 6.0, -e * T2 / 2.0
    Qn = np.zeros((n, n))
    Q = Qn[:N_STATE, :N_STATE]  # a view
    Q.flat[_Q_NAV] = (pp_ne + pp, pp_ne + pp, pp_d + pp, pv_ne + pv, pv_ne + pv, pv_d + pv,
                      pv_ne + pv, pv_ne + pv, pv_d + pv, vv_ne + vv, vv_ne + vv, vv_d + vv,
                      w * T, w * T, w * T, e * T, e * T, e * T, pd, pd, pd, pd, pd, pd,
                      vd, vd, vd, vd, vd, vd)
    if w > 0.0:
        R_mean = -np.reshape(nA, (3, 3)) / T_s if T_s > 0 else np.eye(3)
        pa, va = (-w * T3 / 6.0) * R_mean, (-w * T2 / 2.0) * R_mean
        Q[0:3, I_A:I_A + 3] = pa
        Q[I_A:I_A + 3, 0:3] = pa.T
        Q[3:6, I_A:I_A + 3] = va
        Q[I_A:I_A + 3, 3:6] = va.T
    c = q_clock * T + q_drift * T3 / 3.0
    Q[I_CLK:I_DRIFT, I_CLK:I_DRIFT] = np.outer(live, live) * c + np.diag(live * (q_isb * T))
    Q[I_CLK:I_DRIFT, I_DRIFT] = Q[I_DRIFT, I_CLK:I_DRIFT] = live * (q_drift * T2 / 2.0)
    Q[I_DRIFT, I_DRIFT] = q_drift * T
    Q[I_HEADING, I_HEADING] = q_heading * T + q_yaw_bias * T3 / 3.0
    Q[I_HEADING, I_YAW_BIAS] = Q[I_YAW_BIAS, I_HEADING] = -q_yaw_bias * T2 / 2.0
    Q[I_YAW_BIAS, I_YAW_BIAS] = q_yaw_bias * T
    if n > I_BARO:
        Qn[I_BARO, I_BARO] = q_baro * T
    return Qn


def _diag(r0: int, c0: int) -> list[int]:
    return [(r0 + i) * N_STATE + c0 + i for i in range(3)]


_EYE = np.eye(N_STATE)
_F_T = _diag(I_P, I_V)
_F_D = _diag(I_P, I_D) + _diag(I_V, I_D)
_Q_NAV = np.array([*_diag(0, 0), *_diag(0, 3), *_diag(3, 0), *_diag(3, 3), *_diag(I_A, I_A), *_diag(I_D, I_D),
                   *_diag(0, I_D), *_diag(I_D, 0), *_diag(3, I_D), *_diag(I_D, 3)])


def position_dop_ned(elevation_deg: np.ndarray, azimuth_rad: np.ndarray, slot: np.ndarray) -> np.ndarray:
    """The position block's diagonal (3,: N, E, D; HDOP² = q_N + q_E) of (GᵀG)⁻¹ for the satellites at
    ``elevation_deg``, ``azimuth_rad`` with one receiver clock per clock ``slot`` (G's rows: the unit
    line of sight from the satellite to the receiver, then 1 in the satellite's clock column). NaN when
    the geometry does not fix the position (fewer satellites than unknowns, or singular)."""
    el = np.radians(elevation_deg)
    slots, col = np.unique(slot, return_inverse=True)
    G = np.zeros((len(el), 3 + len(slots)))
    G[:, 0] = -np.cos(el) * np.cos(azimuth_rad)
    G[:, 1] = -np.cos(el) * np.sin(azimuth_rad)
    G[:, 2] = np.sin(el)
    G[np.arange(len(el)), 3 + col] = 1.0
    if len(el) < G.shape[1] or np.linalg.matrix_rank(G) < G.shape[1]:
        return np.full(3, np.nan)
    return np.diag(np.linalg.inv(G.T @ G))[:3].copy()
