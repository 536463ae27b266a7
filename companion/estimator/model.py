"""The linear 15-state model x = [p, v, b, a, d] of eq. 12-14 with IMU error states.

``p``, ``v`` (NED; m, m/s) and the GNSS multipath bias ``b`` (NED, m) are the paper's; ``a`` is
the accelerometer bias in BODY axes (FRD, m/s²; issue #11: IMU error states), a random walk of
density ``σ_w`` (m/s² per √s), and ``d`` a NED acceleration error (m/s²), a random walk of
density ``σ_d``: the autopilot's attitude error × g (1° of tilt reads as 0.17 m/s² horizontal,
fixed in NED, not in the body). The IMU measures ``f̃ = f + a`` in body axes, so with the
autopilot's attitude ``R(t) = R_ned_frd``

    v̇ = R(t) (f̃ − a) + g − d = ã(t) − R(t) a − d,       ã = R f̃ + g (what ``history.py`` integrates)

With both priors and densities 0, ``a`` and ``d`` are never excited and the model is exactly the
paper's 9-state one.

Over an interval [t_a, t_b] (T = t_b − t_a) with the rotation prefix integrals of
``history.py``, ``A = ∫ R ds`` and ``B = ∫ (t_b − s) R(s) ds`` (both 3×3), the transition is
exact for any attitude history:

    F = [[I, T I, 0, −B, −T²/2 I], [0, I, 0, −A, −T I], [0, 0, α(T) I, 0, 0], [0, 0, 0, I, 0],
         [0, 0, 0, 0, I]],   α(T) = exp(−T/τ_b)

Process noise (white acceleration of density σ_q² in NED, first-order Gauss-Markov GNSS bias,
random-walk ``a`` and ``d``):

    Q = σ_q² [[T³/3, T²/2], [T²/2, T]] ⊗ I on (p, v)  +  (1 − α(T)²) σ_b² I on b
      + σ_w² [[T⁵/20 I, T⁴/8 I, −T³/6 R̄], [T⁴/8 I, T³/3 I, −T²/2 R̄], [·, ·, T I]] on (p, v, a)
      + σ_d² [[T⁵/20, T⁴/8, −T³/6], [T⁴/8, T³/3, −T²/2], [·, ·, T]] ⊗ I on (p, v, d)

All terms but the third are exact. The random-walk term is exact for a constant attitude (R̄ = R);
over a block whose attitude changes we use the block's mean rotation R̄ = A / T (deterministic:
a function of the block's end points only). This is the documented approximation: it is PSD for
every attitude history (the set of matrices M for which the block is PSD is convex and holds
every rotation, so it holds their mean R̄), it equals the exact value for a constant attitude,
and the exact p-p, p-v and v-v terms are bounded by the isotropic ones we use (‖∫R‖ ≤ T). Blocks
are the intervals between fusions (50 ms at 20 Hz), and σ_w² T³ is tiny there, so the
difference is far below the other noise terms.

The covariance is a 15×15 numpy array: a body-frame bias couples the NED axes through R(t), so
the per-axis float form of the NED-bias model no longer applies. With the identity attitude
everything reduces to the per-axis model of the first wave (tested).
"""

from __future__ import annotations

import math

import numpy as np

from companion.estimator import _core
from companion.estimator.config import EstimatorConfig

State = tuple[float, ...]  # [p NED, v NED, b NED, a FRD, d NED] (m, m/s, m, m/s², m/s²)
Cov = np.ndarray  # (15, 15), never written after it is stored (out-of-sequence roll-back keeps it)
Rot9 = tuple[float, float, float, float, float, float, float, float, float]  # row-major R_ned_frd

N_STATE = 15
H = np.hstack([np.eye(3), np.zeros((3, 3)), np.eye(3), np.zeros((3, 6))])  # z = p + b + ν
IDENTITY9: Rot9 = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
_I3 = np.eye(3)
_EYE = np.eye(N_STATE)


def _flat(row0: int, col0: int) -> list[int]:
    """Flat indices (15×15) of the diagonal of the 3×3 block at (row0, col0)."""
    return [(row0 + i) * N_STATE + col0 + i for i in range(3)]


# the diagonal-per-axis Q terms: pp, pv, vp, vv, bb, aa, dd, pd, dp, vd, dv (three axes each)
_Q_FLAT = np.array([*_flat(0, 0), *_flat(0, 3), *_flat(3, 0), *_flat(3, 3), *_flat(6, 6), *_flat(9, 9),
                    *_flat(12, 12), *_flat(0, 12), *_flat(12, 0), *_flat(3, 12), *_flat(12, 3)])
_F_T_FLAT = np.array(_flat(0, 3))  # F[p, v] = T I
_F_ALPHA_FLAT = np.array(_flat(6, 6))  # F[b, b] = α I
_F_D_FLAT = np.array(_flat(0, 12) + _flat(3, 12))  # F[p, d] = −T²/2 I, F[v, d] = −T I


def bias_decay(T_s: float, cfg: EstimatorConfig) -> float:
    """α(T) = exp(−T/τ_b)."""
    return math.exp(-T_s / cfg.bias_tau_s)


def bias_share_of_noise_m2(sigma_bias_m: float, T_s: float, tau_s: float) -> float:
    """The variance a Gauss-Markov bias of std ``sigma_bias_m`` and correlation time ``tau_s`` adds to the
    receiver-noise statistic (the second difference of fixes ``T_s`` apart, normalised to one fix's white
    noise: ``(z₂ − 2 z₁ + z₀) / √6``): ``σ² (1 − α)(3 − α) / 3`` with ``α = e^(−T/τ)``, exact at a regular
    fix rate (the statistic of ``FusionEngine``; tests/test_estimator_flyaway.py checks it on a simulated
    bias)."""
    a = math.exp(-T_s / tau_s)
    return sigma_bias_m * sigma_bias_m * (1.0 - a) * (3.0 - a) / 3.0


def rot_matrix(r9: Rot9 | np.ndarray) -> np.ndarray:
    return np.asarray(r9, dtype=float).reshape(3, 3)


def transition_block(T_s: float, A: np.ndarray, B: np.ndarray, alpha: float) -> np.ndarray:
    """F over a block with rotation integrals A = ∫R, B = ∫(t_b − s) R (3×3 each)."""
    F = _EYE.copy()
    F.flat[_F_T_FLAT] = T_s
    F.flat[_F_ALPHA_FLAT] = alpha
    h = -0.5 * T_s * T_s
    F.flat[_F_D_FLAT] = (h, h, h, -T_s, -T_s, -T_s)
    F[0:3, 9:12] = -B
    F[3:6, 9:12] = -A
    return F


def add_process_noise(P: np.ndarray, T_s: float, R_mean: np.ndarray, q_acc_m2_s3: float, q_bias_m2: float,
                      q_rw_m2_s5: float, q_ned_m2_s5: float) -> None:
    """P += Q (in place, on a fresh array) for a block of T s whose mean rotation is ``R_mean``;
    ``q_bias_m2`` is the whole GNSS-bias noise (1 − α²) σ_b², ``q_rw_m2_s5`` and ``q_ned_m2_s5``
    the densities σ_w² (body accelerometer bias) and σ_d² (NED acceleration error)."""
    T2 = T_s * T_s
    q, w, e = q_acc_m2_s3, q_rw_m2_s5, q_ned_m2_s5
    pp = q * T2 * T_s / 3.0 + (w + e) * T2 * T2 * T_s / 20.0
    pv = q * T2 / 2.0 + (w + e) * T2 * T2 / 8.0
    vv = q * T_s + (w + e) * T2 * T_s / 3.0
    aa, dd, pd, vd = w * T_s, e * T_s, -e * T2 * T_s / 6.0, -e * T2 / 2.0
    P.flat[_Q_FLAT] += (pp, pp, pp, pv, pv, pv, pv, pv, pv, vv, vv, vv, q_bias_m2, q_bias_m2, q_bias_m2,
                        aa, aa, aa, dd, dd, dd, pd, pd, pd, pd, pd, pd, vd, vd, vd, vd, vd, vd)
    if w > 0.0:
        pa = (-w * T2 * T_s / 6.0) * R_mean
        va = (-w * T2 / 2.0) * R_mean
        P[0:3, 9:12] += pa
        P[9:12, 0:3] += pa.T
        P[3:6, 9:12] += va
        P[9:12, 3:6] += va.T


def predict_block(P: np.ndarray, T_s: float, A: np.ndarray, B: np.ndarray, alpha: float, q_acc_m2_s3: float,
                  q_bias_m2: float, q_rw_m2_s5: float, q_ned_m2_s5: float) -> np.ndarray:
    """F P Fᵀ + Q over a block (a new array)."""
    F = transition_block(T_s, A, B, alpha)
    out = F @ P @ F.T
    R_mean = A / T_s if T_s > 0.0 else _I3
    add_process_noise(out, T_s, R_mean, q_acc_m2_s3, q_bias_m2, q_rw_m2_s5, q_ned_m2_s5)
    return out


# -------------------------------------------- constant-attitude reference forms (tests, streams)
def transition(T_s: float, cfg: EstimatorConfig, r9: Rot9 = IDENTITY9) -> np.ndarray:
    """F(T) for an attitude held constant at ``r9`` over T (A = T R, B = T²/2 R)."""
    R = rot_matrix(r9)
    return transition_block(T_s, T_s * R, 0.5 * T_s * T_s * R, bias_decay(T_s, cfg))


def input_matrix(T_s: float) -> np.ndarray:
    """B(T): how a NED acceleration ã held over T enters x (x ← F x + B ã)."""
    return np.vstack([0.5 * T_s * T_s * _I3, T_s * _I3, np.zeros((N_STATE - 6, 3))])


def process_noise(T_s: float, sigma_bias_m: float, cfg: EstimatorConfig,
                  r9: Rot9 = IDENTITY9) -> np.ndarray:
    """Q(T) of eq. 13 (with the accelerometer-bias random walk) for a bias std σ_b, attitude ``r9``."""
    Q = np.zeros((N_STATE, N_STATE))
    q_b = (1.0 - bias_decay(T_s, cfg) ** 2) * sigma_bias_m**2
    w, e = cfg.sigma_acc_bias_rw_m_s2_sqrt_s**2, cfg.sigma_acc_ned_rw_m_s2_sqrt_s**2
    add_process_noise(Q, T_s, rot_matrix(r9), cfg.sigma_acc_m_s2**2, q_b, w, e)
    return Q


def predict_cov(P: np.ndarray, T_s: float, sigma_bias_m: float, cfg: EstimatorConfig,
                r9: Rot9 = IDENTITY9) -> np.ndarray:
    """P ← F P Fᵀ + Q over T seconds at a constant attitude."""
    F = transition(T_s, cfg, r9)
    return F @ P @ F.T + process_noise(T_s, sigma_bias_m, cfg, r9)


def hmh(M: np.ndarray) -> np.ndarray:
    """H M Hᵀ for H = [I 0 I 0] without the products."""
    return M[0:3, 0:3] + M[0:3, 6:9] + M[6:9, 0:3] + M[6:9, 6:9]


def update(
    x: np.ndarray, P: np.ndarray, z: np.ndarray, R: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """Reference Kalman update with z = p + b + ν, ν ~ N(0, R). Returns (x⁺, P⁺, y, S, NIS)."""
    y = z - (x[0:3] + x[6:9])
    PHt = P[:, 0:3] + P[:, 6:9]
    S = hmh(P) + R
    S_inv = np.linalg.inv(S)
    K = PHt @ S_inv
    x_post = x + K @ y
    P_post = P - K @ PHt.T
    P_post = 0.5 * (P_post + P_post.T)
    return x_post, P_post, y, S, float(y @ S_inv @ y)


def initial_cov(cfg: EstimatorConfig, r_m2: tuple[float, float, float] | None = None,
                bias_scale: float = 1.0) -> np.ndarray:
    """P₀ at the first fix: position as good as the fix (its R: ``r_m2``, default the config's
    nominal R), velocity and biases from the config (the GNSS bias's std × ``bias_scale``, the
    receiver's scale of the bias range: ``EstimatorConfig.bias_scale``)."""
    r = np.diag(cfg.r_nominal_m2()) if r_m2 is None else np.asarray(r_m2, dtype=float)
    v, b = np.full(3, cfg.sigma_velocity0_m_s**2), np.full(3, (cfg.sigma_bias0_m * bias_scale) ** 2)
    a = np.full(3, cfg.sigma_acc_bias0_m_s2**2)
    d = np.full(3, cfg.sigma_acc_ned0_m_s2**2)
    return np.diag(np.concatenate([r, v, b, a, d]))


# ------------------------------------------------------------------- the engine's fast forms
# The engine's hot path is C (``_core.c``), equal to the reference forms above to rounding
# (tested here and in tests/test_estimator_core.py):
#
# ``BlockPropagator(q_acc_m2_s3, q_rw_m2_s5, q_ned_m2_s5, q_hold_white_m2_s3=0, q_hold_rw_m2_s5=0,
# q_coast=0)``
# (the densities σ_q² and σ_j² of the held-time noise and the scale of a coast's dropped acceleration,
# 1 or 0, ``history.py``, "Held time"; the paths given the block's integrals add it, ``predict`` and
# ``variances`` do not):
#   ``predict(P, T, nA, nB, alpha, q_b)``: ``predict_block`` (F P Fᵀ + Q, a new array) from the
#     block's −A, −B (row-major lists of 9, ``history.rotation_blocks``), using F's sparsity (a row
#     of F for p or v has 6 or 5 non-zero entries) instead of two dense 15×15 products;
#   ``variances(P, T, nA, nB, alpha, q_b)``: the variances of p, v and b (9) of ``predict``
#     alone: each a quadratic form on the 6×6 block of P that row of F touches;
#   ``predict_from(x, P, a, b, T, alpha, q_b)`` -> (x⁻, P⁻, H P⁻ Hᵀ (3×3 nested tuples), the
#     position diagonal of P⁻ Hᵀ): the mean (``history.mean_between``) and ``predict`` from the
#     integrals ``a``, ``b`` of the block's ends, with the innovation terms, in one call;
#   ``output_from(x, P, a, b, T, alpha, q_b)`` -> (x, the 9 variances): the same for the output.
BlockPropagator = _core.Propagator
# Row-major inverse of a symmetric positive-definite 3×3 (closed form; the upper triangle is read).
inv3 = _core.inv3


def update_fast(x: State, P: np.ndarray, y: tuple[float, float, float],
                r_m2: tuple[float, float, float]) -> tuple[State, np.ndarray, float]:
    """Kalman update with z = p + b + ν, ν ~ N(0, diag r), innovation ``y``: (x⁺, P⁺, NIS), by the
    core (``_core.update``, which forms P Hᵀ and H P Hᵀ itself). K S Kᵀ is symmetric but its
    rounding is not: left alone, the asymmetry grows fusion after fusion over a long flight, so P⁺
    is symmetrised ((A + Aᵀ)/2, exactly symmetric)."""
    return _core.update(x, P, y, r_m2)


def reset_to_fix(x: State, P: np.ndarray, z: tuple[float, float, float], r_m2: tuple[float, float, float],
                 bias_var_m2: float, v_ned_m_s: tuple[float, float, float] | None = None,
                 rv_m2: tuple[float, float, float] = (math.nan,) * 3, vel_var_min_m2_s2: float = 0.0,
                 imu_var_m2_s4: tuple[float, float] = (0.0, 0.0)) -> tuple[State, np.ndarray]:
    """Reset to the fix ``z`` after the filter lost it (glitch recovery, the fly-away guard), as
    EKF2 and EKF3 reset position and velocity together.

    * position = z, GNSS bias 0 with variance ``bias_var_m2``: since z = p + b + ν, the position has
      variance R + var(b) and covariance −var(b) with the bias (H P Hᵀ = R: the reset trusts the fix
      exactly as much as its R says);
    * velocity = the receiver's ``v_ned_m_s`` with its variance ``rv_m2`` for each component it
      reports (finite); a component it does not report keeps the estimate (the caller zeroes one
      outside the vehicle's envelope, as EKF2 resets to zero without a velocity source), its
      variance at least ``vel_var_min_m2_s2``;
    * the IMU error states keep their means, their variances at least their priors
      ``imu_var_m2_s4`` = (accelerometer bias, NED acceleration error): a reset says the model failed,
      so what was learned through it is re-opened.

    The reset states lose every correlation (with each other and the rest)."""
    out = np.zeros((N_STATE, N_STATE))
    v = list(x[3:6])
    diag = P.diagonal()
    for i in range(3):
        out[i, i] = r_m2[i] + bias_var_m2
        out[i, 6 + i] = out[6 + i, i] = -bias_var_m2
        out[6 + i, 6 + i] = bias_var_m2
        given = v_ned_m_s is not None and math.isfinite(v_ned_m_s[i]) and rv_m2[i] > 0.0
        if given:
            v[i] = float(v_ned_m_s[i])  # type: ignore[index]
        out[3 + i, 3 + i] = rv_m2[i] if given else max(float(diag[3 + i]), vel_var_min_m2_s2)
        out[9 + i, 9 + i] = max(float(diag[9 + i]), imu_var_m2_s4[0])
        out[12 + i, 12 + i] = max(float(diag[12 + i]), imu_var_m2_s4[1])
    return (z[0], z[1], z[2], v[0], v[1], v[2], 0.0, 0.0, 0.0, *x[9:]), out


def scale_bias_prior(P: np.ndarray, f: float, bias_var_m2: float) -> np.ndarray:
    """``reset_to_fix``'s covariance with the bias variance ``bias_var_m2`` raised to f² times it (a
    new array): position variance R + f² var(b), covariance −f² var(b), bias f² var(b)."""
    out = P.copy()
    f2 = f * f
    for i in range(3):
        out[i, i] += (f2 - 1.0) * bias_var_m2
        out[i, 6 + i] *= f2
        out[6 + i, i] *= f2
        out[6 + i, 6 + i] *= f2
    return out
