"""The linear 12-state model x = [p, v, b, a] (NED; m, m/s, m, m/s²) of eq. 12-14, as pure functions.

``b`` is the GNSS multipath bias of the paper; ``a`` is an acceleration-input bias (ours, issue
#11: IMU error states): the filter's input is the measured NED acceleration ``ã = a_true + a``,
so ``v̇ = ã − a``. ``a`` is a random walk of density ``σ_w`` (m/s² per √s) and absorbs the
accelerometer bias and the slowly varying attitude error × g (docs/estimator.md says why it is
kept in NED, not body, axes). With ``σ_a0 = σ_w = 0`` it is never excited and the model is
exactly the paper's 9-state one.

The discretisation is the exact one of the continuous-time model (white acceleration noise of
density ``σ_a²``, first-order Gauss-Markov bias with time constant ``τ_b``, random-walk ``a``):

    F(T) = [[I, T I, 0, −T²/2 I], [0, I, 0, −T I], [0, 0, α(T) I, 0], [0, 0, 0, I]],  α(T) = exp(−T/τ_b)
    Q(T) = σ_a² [[T³/3, T²/2], [T²/2, T]] on (p, v)  +  (1 − α(T)²) σ_b² on b
         + σ_w² [[T⁵/20, T⁴/8, −T³/6], [T⁴/8, T³/3, −T²/2], [−T³/6, −T²/2, T]] on (p, v, a)

For a 5 ms step this is eq. 12-13 with ``Δt = T``. Because it is exact, ``F(T₂)F(T₁) = F(T₁+T₂)``
and ``F(T₂) Q(T₁) F(T₂)ᵀ + Q(T₂) = Q(T₁+T₂)`` while σ_b is constant: a block of n predictions
between two fusions (β, hence σ_b, changes only at fusions) collapses into one step of length
T = n Δt, whatever the delay — this is what makes out-of-sequence fusion cost O(1) in time.

The three axes are independent (F, Q, H and the diagonal R act per axis, P₀ is diagonal), so
P stays block-diagonal: the filter keeps, per axis, the ten distinct entries of the 4×4
covariance of (p, v, b, a) and runs on plain floats (``*_axes`` functions; ~20× cheaper than
12×12 numpy on this size). The 12×12 numpy functions are the reference the fast ones are
tested against.
"""

from __future__ import annotations

import math

import numpy as np

from companion.estimator.config import EstimatorConfig

# Per-axis covariance: (pp, pv, pb, pa, vv, vb, va, bb, ba, aa) of (p, v, b, a) on one axis; a
# filter covariance is one per NED axis. States are 12-tuples (p NED, v NED, b NED, a NED).
AxisCov = tuple[float, float, float, float, float, float, float, float, float, float]
Cov = tuple[AxisCov, AxisCov, AxisCov]
State = tuple[float, ...]

N_STATE = 12
H = np.hstack([np.eye(3), np.zeros((3, 3)), np.eye(3), np.zeros((3, 3))])  # z = p + b + ν
_I3 = np.eye(3)
_PAIRS = ((0, 0), (0, 1), (0, 2), (0, 3), (1, 1), (1, 2), (1, 3), (2, 2), (2, 3), (3, 3))


def bias_decay(T_s: float, cfg: EstimatorConfig) -> float:
    """α(T) = exp(−T/τ_b)."""
    return math.exp(-T_s / cfg.bias_tau_s)


def transition(T_s: float, cfg: EstimatorConfig) -> np.ndarray:
    """F(T) of eq. 12 (with the acceleration bias) for an interval of T seconds."""
    F = np.eye(N_STATE)
    F[0:3, 3:6] = T_s * _I3
    F[0:3, 9:12] = -0.5 * T_s * T_s * _I3
    F[3:6, 9:12] = -T_s * _I3
    F[6:9, 6:9] = bias_decay(T_s, cfg) * _I3
    return F


def input_matrix(T_s: float) -> np.ndarray:
    """B(T): how a NED acceleration held over T enters x (x ← F x + B ã)."""
    return np.vstack([0.5 * T_s * T_s * _I3, T_s * _I3, np.zeros((6, 3))])


def process_noise_pv(T_s: float, cfg: EstimatorConfig) -> np.ndarray:
    """Q(T) without the GNSS-bias block (the part that does not depend on β)."""
    q = cfg.sigma_acc_m_s2**2
    w = cfg.sigma_acc_bias_rw_m_s2_sqrt_s**2
    Q = np.zeros((N_STATE, N_STATE))
    Q[0:3, 0:3] = (q * T_s**3 / 3.0 + w * T_s**5 / 20.0) * _I3
    Q[0:3, 3:6] = Q[3:6, 0:3] = (q * T_s**2 / 2.0 + w * T_s**4 / 8.0) * _I3
    Q[3:6, 3:6] = (q * T_s + w * T_s**3 / 3.0) * _I3
    Q[0:3, 9:12] = Q[9:12, 0:3] = -w * T_s**3 / 6.0 * _I3
    Q[3:6, 9:12] = Q[9:12, 3:6] = -w * T_s**2 / 2.0 * _I3
    Q[9:12, 9:12] = w * T_s * _I3
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
    """H M Hᵀ for H = [I 0 I 0] without the products."""
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
    nominal R), velocity and biases from the config."""
    r = np.diag(cfg.r_nominal_m2()) if r_m2 is None else np.asarray(r_m2, dtype=float)
    v, b = np.full(3, cfg.sigma_velocity0_m_s**2), np.full(3, cfg.sigma_bias0_m**2)
    a = np.full(3, cfg.sigma_acc_bias0_m_s2**2)
    return np.diag(np.concatenate([r, v, b, a]))


# ---------------------------------------------------------------- per-axis fast path (floats)
def predict_axes(P: Cov, T_s: float, alpha: float, q_acc_m2_s3: float, q_bias_m2: float,
                 q_rw_m2_s5: float = 0.0) -> Cov:
    """F P Fᵀ + Q per axis; ``q_bias_m2`` is the whole GNSS-bias noise (1 − α²) σ_b², ``q_rw_m2_s5``
    the acceleration-bias random-walk density σ_w²."""
    T2 = T_s * T_s
    h = 0.5 * T2
    qpp = q_acc_m2_s3 * T2 * T_s / 3.0 + q_rw_m2_s5 * T2 * T2 * T_s / 20.0
    qpv = q_acc_m2_s3 * h + q_rw_m2_s5 * T2 * T2 / 8.0
    qvv = q_acc_m2_s3 * T_s + q_rw_m2_s5 * T2 * T_s / 3.0
    qpa = -q_rw_m2_s5 * T2 * T_s / 6.0
    qva = -q_rw_m2_s5 * h
    qaa = q_rw_m2_s5 * T_s
    a2 = alpha * alpha
    out = []
    for pp, pv, pb, pa, vv, vb, va, bb, ba, aa in P:
        # rows of F P: p-row = P_p + T P_v − h P_a, v-row = P_v − T P_a
        rpp, rpv, rpb, rpa = pp + T_s * pv - h * pa, pv + T_s * vv - h * va, pb + T_s * vb - h * ba, \
            pa + T_s * va - h * aa
        rvv, rvb, rva = vv - T_s * va, vb - T_s * ba, va - T_s * aa
        out.append((
            rpp + T_s * rpv - h * rpa + qpp,
            rpv - T_s * rpa + qpv,
            alpha * rpb,
            rpa + qpa,
            rvv - T_s * rva + qvv,
            alpha * rvb,
            rva + qva,
            a2 * bb + q_bias_m2,
            alpha * ba,
            aa + qaa,
        ))
    return (out[0], out[1], out[2])


def predict_var_axes(P: Cov, T_s: float, alpha: float, q_acc_m2_s3: float, q_bias_m2: float,
                     q_rw_m2_s5: float = 0.0) -> tuple[float, ...]:
    """The variances of p, v and b (N, E, D each: 9 numbers) of ``predict_axes``, computed alone
    (the output path needs no more)."""
    T2 = T_s * T_s
    h = 0.5 * T2
    qpp = q_acc_m2_s3 * T2 * T_s / 3.0 + q_rw_m2_s5 * T2 * T2 * T_s / 20.0
    qvv = q_acc_m2_s3 * T_s + q_rw_m2_s5 * T2 * T_s / 3.0
    a2 = alpha * alpha
    (pp0, pv0, _, pa0, vv0, _, va0, bb0, _, aa0), (pp1, pv1, _, pa1, vv1, _, va1, bb1, _, aa1), \
        (pp2, pv2, _, pa2, vv2, _, va2, bb2, _, aa2) = P
    rva0, rva1, rva2 = va0 - T_s * aa0, va1 - T_s * aa1, va2 - T_s * aa2
    rpa0, rpa1, rpa2 = pa0 + T_s * va0 - h * aa0, pa1 + T_s * va1 - h * aa1, pa2 + T_s * va2 - h * aa2
    return (
        pp0 + T_s * pv0 - h * pa0 + T_s * (pv0 + T_s * vv0 - h * va0) - h * rpa0 + qpp,
        pp1 + T_s * pv1 - h * pa1 + T_s * (pv1 + T_s * vv1 - h * va1) - h * rpa1 + qpp,
        pp2 + T_s * pv2 - h * pa2 + T_s * (pv2 + T_s * vv2 - h * va2) - h * rpa2 + qpp,
        vv0 - T_s * va0 - T_s * rva0 + qvv,
        vv1 - T_s * va1 - T_s * rva1 + qvv,
        vv2 - T_s * va2 - T_s * rva2 + qvv,
        a2 * bb0 + q_bias_m2, a2 * bb1 + q_bias_m2, a2 * bb2 + q_bias_m2,
    )


def hph_axes(P: Cov) -> tuple[float, float, float]:
    """Diagonal of H P Hᵀ (var(p + b)) per axis."""
    return tuple(c[0] + 2.0 * c[2] + c[7] for c in P)  # type: ignore[return-value]


def update_axes(x: State, P: Cov, z: tuple[float, float, float], r_m2: tuple[float, float, float]
                ) -> tuple[State, Cov, float]:
    """Kalman update with z = p + b + ν, ν ~ N(0, diag r), per axis. Returns (x⁺, P⁺, NIS)."""
    xs = list(x)
    out = []
    nis = 0.0
    for i in range(3):
        pp, pv, pb, pa, vv, vb, va, bb, ba, aa = P[i]
        kp, kv, kb, ka = pp + pb, pv + vb, pb + bb, pa + ba  # P Hᵀ
        s = kp + kb + r_m2[i]
        y = z[i] - (x[i] + x[6 + i])
        g = y / s
        xs[i] += kp * g
        xs[3 + i] += kv * g
        xs[6 + i] += kb * g
        xs[9 + i] += ka * g
        nis += y * g
        u = 1.0 / s
        out.append((pp - kp * kp * u, pv - kp * kv * u, pb - kp * kb * u, pa - kp * ka * u,
                    vv - kv * kv * u, vb - kv * kb * u, va - kv * ka * u,
                    bb - kb * kb * u, ba - kb * ka * u, aa - ka * ka * u))
    return tuple(xs), (out[0], out[1], out[2]), nis


def cov_to_matrix(P: Cov) -> np.ndarray:
    """The 12×12 covariance of [p, v, b, a] (NED) from the per-axis form."""
    M = np.zeros((N_STATE, N_STATE))
    for i, c in enumerate(P):
        idx = (i, 3 + i, 6 + i, 9 + i)
        for value, (u, v) in zip(c, _PAIRS, strict=True):
            M[idx[u], idx[v]] = M[idx[v], idx[u]] = value
    return M


def matrix_to_cov(M: np.ndarray) -> Cov:
    """The per-axis form of a 12×12 covariance (cross-axis terms must be zero)."""
    out = []
    for i in range(3):
        idx = (i, 3 + i, 6 + i, 9 + i)
        out.append(tuple(float(M[idx[u], idx[v]]) for u, v in _PAIRS))
    return (out[0], out[1], out[2])  # type: ignore[return-value]


def initial_cov_axes(cfg: EstimatorConfig, r_m2: tuple[float, float, float] | None = None) -> Cov:
    return matrix_to_cov(initial_cov(cfg, r_m2))


def reset_to_fix(x: State, P: Cov, z: tuple[float, float, float], r_m2: tuple[float, float, float],
                 bias_var_m2: float) -> tuple[State, Cov]:
    """Position and GNSS bias reset to the fix ``z`` (glitch recovery); velocity and the
    acceleration bias kept.

    The bias restarts at 0 with variance ``bias_var_m2``; since z = p + b + ν, the position is
    z with variance R + var(b) and covariance −var(b) with the bias (H P Hᵀ = R: the reset
    trusts the fix exactly as much as its R says). Velocity and acceleration bias keep their
    (grown) covariance and lose their correlation with the reset states.
    """
    out = []
    for i in range(3):
        vv, va, aa = P[i][4], P[i][6], P[i][9]
        out.append((r_m2[i] + bias_var_m2, 0.0, -bias_var_m2, 0.0, vv, 0.0, va, bias_var_m2, 0.0, aa))
    return (z[0], z[1], z[2], x[3], x[4], x[5], 0.0, 0.0, 0.0, x[9], x[10], x[11]), (out[0], out[1], out[2])
