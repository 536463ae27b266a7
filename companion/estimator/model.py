"""The linear 9-state model x = [p, v, b] (NED; m, m/s, m) of eq. 12-14, as pure functions.

The discretisation is the exact one of the continuous-time model (white acceleration noise of
density ``σ_a²``, first-order Gauss-Markov bias with time constant ``τ_b``):

    F(T) = [[I, T I, 0], [0, I, 0], [0, 0, α(T) I]],   α(T) = exp(−T/τ_b)
    Q(T) = blkdiag(σ_a² [[T³/3 I, T²/2 I], [T²/2 I, T I]],  (1 − α(T)²) σ_b² I)

For a 5 ms step this is eq. 12-13 with ``Δt = T``. Because it is exact, ``F(T₂)F(T₁) = F(T₁+T₂)``
and ``F(T₂) Q(T₁) F(T₂)ᵀ + Q(T₂) = Q(T₁+T₂)`` while σ_b is constant: a block of n predictions
between two fusions (β, hence σ_b, changes only at fusions) collapses into one step of length
T = n Δt, whatever the delay — this is what makes out-of-sequence fusion cost O(1) in time.

The three axes are independent (F, Q, H and the diagonal R act per axis, P₀ is diagonal), so
P stays block-diagonal: the filter keeps, per axis, the six distinct entries of the 3×3
covariance of (p, v, b) and runs on plain floats (``*_axes`` functions; ~20× cheaper than 9×9
numpy on this size). The 9×9 numpy functions are the reference the fast ones are tested against.
"""

from __future__ import annotations

import math

import numpy as np

from companion.estimator.config import EstimatorConfig

# Per-axis covariance: (pp, pv, pb, vv, vb, bb) of (p, v, b) on one axis; a filter covariance is
# one per NED axis. States are 9-tuples (pN, pE, pD, vN, vE, vD, bN, bE, bD).
AxisCov = tuple[float, float, float, float, float, float]
Cov = tuple[AxisCov, AxisCov, AxisCov]
State = tuple[float, ...]

N_STATE = 9
H = np.hstack([np.eye(3), np.zeros((3, 3)), np.eye(3)])  # z = p + b + ν
_I3 = np.eye(3)


def bias_decay(T_s: float, cfg: EstimatorConfig) -> float:
    """α(T) = exp(−T/τ_b)."""
    return math.exp(-T_s / cfg.bias_tau_s)


def transition(T_s: float, cfg: EstimatorConfig) -> np.ndarray:
    """F(T) of eq. 12 for an interval of T seconds."""
    F = np.eye(N_STATE)
    F[0:3, 3:6] = T_s * _I3
    F[6:9, 6:9] = bias_decay(T_s, cfg) * _I3
    return F


def process_noise_pv(T_s: float, cfg: EstimatorConfig) -> np.ndarray:
    """Q(T) without the bias block (the part that does not depend on β)."""
    q = cfg.sigma_acc_m_s2**2
    Q = np.zeros((N_STATE, N_STATE))
    Q[0:3, 0:3] = q * T_s**3 / 3.0 * _I3
    Q[0:3, 3:6] = Q[3:6, 0:3] = q * T_s**2 / 2.0 * _I3
    Q[3:6, 3:6] = q * T_s * _I3
    return Q


def bias_noise_unit(T_s: float, cfg: EstimatorConfig) -> float:
    """1 − α(T)²: the bias block of Q(T) is this times σ_b(β)² I (eq. 13)."""
    return 1.0 - bias_decay(T_s, cfg) ** 2


def process_noise(T_s: float, sigma_bias_m: float, cfg: EstimatorConfig) -> np.ndarray:
    """Q(T) of eq. 13 for a bias std σ_b (m)."""
    Q = process_noise_pv(T_s, cfg)
    Q[6:9, 6:9] = bias_noise_unit(T_s, cfg) * sigma_bias_m**2 * _I3
    return Q


def predict_cov(P: np.ndarray, T_s: float, sigma_bias_m: float, cfg: EstimatorConfig) -> np.ndarray:
    """P ← F P Fᵀ + Q over T seconds."""
    F = transition(T_s, cfg)
    return F @ P @ F.T + process_noise(T_s, sigma_bias_m, cfg)


def hmh(M: np.ndarray) -> np.ndarray:
    """H M Hᵀ for H = [I 0 I] without the products."""
    return M[0:3, 0:3] + M[0:3, 6:9] + M[6:9, 0:3] + M[6:9, 6:9]


def update(
    x: np.ndarray, P: np.ndarray, z: np.ndarray, R: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """Kalman update with z = p + b + ν, ν ~ N(0, R). Returns (x⁺, P⁺, y, S, NIS)."""
    y = z - (x[0:3] + x[6:9])
    PHt = P[:, 0:3] + P[:, 6:9]
    S = hmh(P) + R
    S_inv = np.linalg.inv(S)
    K = PHt @ S_inv
    x_post = x + K @ y
    P_post = P - K @ PHt.T
    P_post = 0.5 * (P_post + P_post.T)
    return x_post, P_post, y, S, float(y @ S_inv @ y)


def initial_cov(cfg: EstimatorConfig, r_m2: tuple[float, float, float] | None = None) -> np.ndarray:
    """P₀ at the first fix: position as good as the fix (its R: ``r_m2``, default the config's
    nominal R), velocity and bias from the config."""
    r = np.diag(cfg.r_nominal_m2()) if r_m2 is None else np.asarray(r_m2, dtype=float)
    v, b = np.full(3, cfg.sigma_velocity0_m_s**2), np.full(3, cfg.sigma_bias0_m**2)
    return np.diag(np.concatenate([r, v, b]))


# ---------------------------------------------------------------- per-axis fast path (floats)
def predict_axes(P: Cov, T_s: float, alpha: float, q_acc_m2_s3: float, q_bias_m2: float) -> Cov:
    """F P Fᵀ + Q per axis; ``q_bias_m2`` is the whole bias-block noise (1 − α²) σ_b²."""
    qpp = q_acc_m2_s3 * T_s**3 / 3.0
    qpv = q_acc_m2_s3 * T_s**2 / 2.0
    qvv = q_acc_m2_s3 * T_s
    a2 = alpha * alpha
    out = []
    for pp, pv, pb, vv, vb, bb in P:
        out.append((
            pp + 2.0 * T_s * pv + T_s * T_s * vv + qpp,
            pv + T_s * vv + qpv,
            alpha * (pb + T_s * vb),
            vv + qvv,
            alpha * vb,
            a2 * bb + q_bias_m2,
        ))
    return (out[0], out[1], out[2])


def hph_axes(P: Cov) -> tuple[float, float, float]:
    """Diagonal of H P Hᵀ (var(p + b)) per axis."""
    return tuple(c[0] + 2.0 * c[2] + c[5] for c in P)  # type: ignore[return-value]


def update_axes(x: State, P: Cov, z: tuple[float, float, float], r_m2: tuple[float, float, float]
                ) -> tuple[State, Cov, float]:
    """Kalman update with z = p + b + ν, ν ~ N(0, diag r), per axis. Returns (x⁺, P⁺, NIS)."""
    xs = list(x)
    out = []
    nis = 0.0
    for i in range(3):
        pp, pv, pb, vv, vb, bb = P[i]
        kp, kv, kb = pp + pb, pv + vb, pb + bb  # P Hᵀ
        s = kp + kb + r_m2[i]
        y = z[i] - (x[i] + x[6 + i])
        g = y / s
        xs[i] += kp * g
        xs[3 + i] += kv * g
        xs[6 + i] += kb * g
        nis += y * g
        out.append((pp - kp * kp / s, pv - kp * kv / s, pb - kp * kb / s,
                    vv - kv * kv / s, vb - kv * kb / s, bb - kb * kb / s))
    return tuple(xs), (out[0], out[1], out[2]), nis


def cov_to_matrix(P: Cov) -> np.ndarray:
    """The 9×9 covariance of [p, v, b] (NED) from the per-axis form."""
    M = np.zeros((N_STATE, N_STATE))
    for i, (pp, pv, pb, vv, vb, bb) in enumerate(P):
        idx = [i, 3 + i, 6 + i]
        M[np.ix_(idx, idx)] = [[pp, pv, pb], [pv, vv, vb], [pb, vb, bb]]
    return M


def matrix_to_cov(M: np.ndarray) -> Cov:
    """The per-axis form of a 9×9 covariance (cross-axis terms must be zero)."""
    out = []
    for i in range(3):
        a, b, c = i, 3 + i, 6 + i
        out.append(tuple(float(M[u, v]) for u, v in ((a, a), (a, b), (a, c), (b, b), (b, c), (c, c))))
    return (out[0], out[1], out[2])  # type: ignore[return-value]


def initial_cov_axes(cfg: EstimatorConfig, r_m2: tuple[float, float, float] | None = None) -> Cov:
    return matrix_to_cov(initial_cov(cfg, r_m2))


def reset_to_fix(x: State, P: Cov, z: tuple[float, float, float], r_m2: tuple[float, float, float],
                 bias_var_m2: float) -> tuple[State, Cov]:
    """Position and GNSS bias reset to the fix ``z`` (glitch recovery), velocity kept.

    The bias restarts at 0 with variance ``bias_var_m2``; since z = p + b + ν, the position is
    z with variance R + var(b) and covariance −var(b) with the bias (H P Hᵀ = R: the reset
    trusts the fix exactly as much as its R says). Velocity keeps its (grown) variance and loses
    its correlation with the reset states.
    """
    out = []
    for i in range(3):
        vv = P[i][3]
        out.append((r_m2[i] + bias_var_m2, 0.0, -bias_var_m2, vv, 0.0, bias_var_m2))
    return (z[0], z[1], z[2], x[3], x[4], x[5], 0.0, 0.0, 0.0), (out[0], out[1], out[2])
