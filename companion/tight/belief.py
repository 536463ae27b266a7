"""The paper's belief, one per satellite: β_s = σ(θ_s) sets that satellite's pseudorange variance

    R_s(β_s) = R_nom,s · k^(1 − β_s)          (k = ``r_inflation_max``: R_nom at full trust, k R_nom at none)

monotone decreasing in β_s and bounded. θ_s learns from the satellite's consistency: its pre-fit
innovation y_s against its predicted variance S_s(β) = s0_s + R_s(β) (s0 = (H P⁻ Hᵀ)_ss), under a
Student-t negative log-likelihood (1 degree of freedom, ν = ``student_dof``)

    ℓ_s(β) = ½ log S_s + (ν + 1)/2 · log(1 + y_s² / (ν S_s))  +  κ/2 (θ_s − θ_prior,s)²

whose data term is minimal at S_s = y_s² (consistency: it has an interior optimum, which the loss as
printed in the paper has not), plus a prior pulling θ_s towards what C/N0 and elevation (and a map's
line of sight) expect. With ∂S/∂β = −ln k · R_s(β):

    ∂ℓ/∂S = ½/S − ½ (ν + 1) y² / (S (ν S + y²)),    ∇θ ℓ = ∂ℓ/∂S · ∂S/∂β · β(1 − β) + κ (θ − θ_prior)

and the update is the paper's dual-timescale damped Newton step (eq. 18-21) per satellite:

    H_f ← α_f H_f + g²,  H_s ← α_s H_s + g²,  H = ω H_f + (1 − ω) H_s,  θ ← θ − η g / (H + λ)

A reflected satellite's innovation is larger than S says: ∂ℓ/∂S < 0 there, so θ falls (R grows
until S ≈ y²); a clean one's is smaller: θ rises to the cap.

NLOS only delays a signal, and the common part of the reflections' delays goes into the receiver clock,
so the clean satellites look early: the consistency sees ỹ = y where y ≥ 0 and ``belief_early_factor`` · y
where y < 0 (``consistency_innovation``) in place of y, in the step and in the joint consistency's median;
the gate sees y. Vectorised over satellites. The
filter runs these as one C call (``_tight.belief_step``: gradient, step, clamp, R(β), gate), equal to
the numpy forms here (tested); these stay the reference and serve the tests and the evaluation.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from companion.tight.config import TightConfig


def sigmoid(theta: np.ndarray) -> np.ndarray:
    return 1.0 / (1.0 + np.exp(-theta))


def r_of_beta(beta: np.ndarray, r_nominal: np.ndarray, cfg: TightConfig) -> np.ndarray:
    """R_s(β) = R_nom · k^(1 − β)."""
    return r_nominal * cfg.r_inflation_max ** (1.0 - beta)


def loss_grad_theta(theta: np.ndarray, y: np.ndarray, s0: np.ndarray, r_nominal: np.ndarray,
                    theta_prior: np.ndarray, cfg: TightConfig) -> tuple[np.ndarray, np.ndarray]:
    """(ℓ_s(θ_s), ∂ℓ_s/∂θ_s) per satellite (see the module doc)."""
    beta = sigmoid(theta)
    r = r_of_beta(beta, r_nominal, cfg)
    S = s0 + r
    nu = cfg.student_dof
    y2 = y * y
    loss = 0.5 * np.log(S) + 0.5 * (nu + 1.0) * np.log1p(y2 / (nu * S))
    loss = loss + 0.5 * cfg.prior_weight * (theta - theta_prior) ** 2
    dl_ds = 0.5 / S - 0.5 * (nu + 1.0) * y2 / (S * (nu * S + y2))
    ds_dbeta = -np.log(cfg.r_inflation_max) * r
    g = dl_ds * ds_dbeta * beta * (1.0 - beta) + cfg.prior_weight * (theta - theta_prior)
    return loss, g


def grad_theta(theta: np.ndarray, y: np.ndarray, s0: np.ndarray, r_nominal: np.ndarray,
               theta_prior: np.ndarray, cfg: TightConfig) -> np.ndarray:
    """∂ℓ_s/∂θ_s alone (``loss_grad_theta``'s second value, without the loss: the filter's path)."""
    beta = 1.0 / (1.0 + np.exp(-theta))
    r = r_nominal * cfg.r_inflation_max ** (1.0 - beta)
    S = s0 + r
    y2 = y * y
    nu = cfg.student_dof
    dl_ds = 0.5 / S - 0.5 * (nu + 1.0) * y2 / (S * (nu * S + y2))
    return dl_ds * (-math.log(cfg.r_inflation_max)) * r * beta * (1.0 - beta) + cfg.prior_weight * (
        theta - theta_prior)


def consistency_innovation(y: np.ndarray, cfg: TightConfig) -> np.ndarray:
    """ỹ: an early innovation (y < 0: the signal arrived before the prediction, which a reflection cannot
    do) times ``belief_early_factor``, a late one as it is: what the belief's consistency is judged on."""
    return np.where(y < 0.0, cfg.belief_early_factor * y, y)


CHI2_1_MEDIAN = 0.454936  # the median of χ²(1): a consistent epoch's median of y²/S


def epoch_scale(theta: np.ndarray, y: np.ndarray, s0: np.ndarray, r_nominal: np.ndarray,
                cfg: TightConfig) -> float:
    """Joint consistency: the epoch's median y²/(s0 + R(β)) over χ²(1)'s median, at least 1 (1 with fewer
    than 4 satellites). Above 1 the epoch as a whole disagrees with the prediction — the state is off, not
    every satellite — and the belief's step judges each satellite with S scaled by it: the gradient is
    ``grad_theta(θ, y, scale · s0, scale · R_nom, …)``; the fused R(β) and the gate are not scaled."""
    if len(y) < 4:
        return 1.0
    r = r_of_beta(sigmoid(theta), r_nominal, cfg)
    return max(1.0, float(np.median(y * y / (s0 + r))) / CHI2_1_MEDIAN)


def second_order_step(theta: np.ndarray, h_fast: np.ndarray, h_slow: np.ndarray, g: np.ndarray,
                      cfg: TightConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(θ, H_fast, H_slow) after the damped Newton step along g (eq. 18-21), per satellite."""
    h_fast = cfg.alpha_fast * h_fast + g * g
    h_slow = cfg.alpha_slow * h_slow + g * g
    h = cfg.omega_fast * h_fast + (1.0 - cfg.omega_fast) * h_slow
    return theta - cfg.eta * g / (h + cfg.lambda_reg), h_fast, h_slow


def theta_prior(cn0_dbhz: np.ndarray, elevation_deg: np.ndarray, cfg: TightConfig) -> np.ndarray:
    """Prior logit from C/N0 and elevation (a missing C/N0 counts as the midpoint), unclamped: the
    filter adds the map's term (``map_theta``) and clamps to [``theta_min``, ``theta_max``]."""
    cn0 = np.where(np.isfinite(cn0_dbhz), cn0_dbhz, cfg.prior_cn0_mid_dbhz)
    return cfg.prior_cn0_per_db * (cn0 - cfg.prior_cn0_mid_dbhz) + cfg.prior_el_per_deg * (
        elevation_deg - cfg.prior_el_mid_deg)


LineOfSight = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
# candidate positions: a 5 × 5 grid at −2σ … 2σ along the principal axes of the horizontal covariance,
# Gaussian weights exp(−½ |offset/σ|²) (the height is the estimate's: a flying vehicle's is the best known)
_GRID_SIGMA = np.array([(i, j) for i in (-2.0, -1.0, 0.0, 1.0, 2.0) for j in (-2.0, -1.0, 0.0, 1.0, 2.0)])
_GRID_LOG_WEIGHT = -0.5 * (_GRID_SIGMA**2).sum(axis=1)


def blocked_probability(line_of_sight: LineOfSight, p_ned_m: np.ndarray, P_pos_m2: np.ndarray,
                        azimuth_rad: np.ndarray, elevation_rad: np.ndarray, p_los: np.ndarray | None = None,
                        sigma_floor_m: float = 0.0) -> np.ndarray:
    """(n,) probability that the map hides each satellite from a position known as N(p, P) (horizontal
    P widened by ``sigma_floor_m`` per axis): the map's verdicts at candidate positions around p, weighted
    by that Gaussian and, with ``p_los`` (n,) (each satellite's probability of a line of sight from its
    signal alone: C/N0 and elevation), by how well each candidate's pattern of hidden and seen
    satellites explains the signals (shadow matching: Π_s p_los,s where seen, 1 − p_los,s where hidden).
    A precise position gives the map's verdict (0 or 1); an uncertain one a fraction, pulled toward the
    candidate positions whose shadows the signals agree with, so a wrong estimate does not make the map
    confirm itself."""
    Ph = 0.5 * (P_pos_m2[0:2, 0:2] + P_pos_m2[0:2, 0:2].T) + np.eye(2) * sigma_floor_m**2
    lam, vec = np.linalg.eigh(Ph)
    axes = vec * np.sqrt(np.maximum(lam, 0.0))  # columns: 1σ along each principal axis
    pts = np.repeat(np.asarray(p_ned_m, dtype=float)[None, :], len(_GRID_SIGMA), axis=0)
    pts[:, 0:2] += _GRID_SIGMA @ axes.T
    hidden = np.asarray(line_of_sight(pts, azimuth_rad, elevation_rad), dtype=bool)
    log_w = _GRID_LOG_WEIGHT
    if p_los is not None and len(p_los):
        log_w = log_w + shadow_log_likelihood(hidden, p_los)
    w = np.exp(log_w - log_w.max())
    return (w / w.sum()) @ hidden


def shadow_log_likelihood(hidden: np.ndarray, p_los: np.ndarray, tempering: float = 1.0) -> np.ndarray:
    """(K,) log-likelihood of K candidate positions' map verdicts ``hidden`` (K, n) given each signal's
    probability of a line of sight ``p_los`` (n,), clipped to [1e-3, 1 − 1e-3]: Σ_s log(1 − q_s) where
    hidden, log q_s where seen, times ``tempering`` (shadow matching: ``blocked_probability``'s candidate
    weights and ``shadow.shadow_fix``'s posterior)."""
    q = np.clip(p_los, 1e-3, 1.0 - 1e-3)
    ll = np.where(hidden, np.log1p(-q), np.log(q)).sum(axis=1)
    return ll if tempering == 1.0 else tempering * ll


def map_theta(p_blocked: np.ndarray, cfg: TightConfig) -> np.ndarray:
    """The map's term of the prior logit: ``prior_map_nlos`` where it hides the satellite,
    ``prior_map_los`` where it shows it, blended by the probability ``p_blocked``."""
    return cfg.prior_map_nlos * p_blocked + cfg.prior_map_los * (1.0 - p_blocked)
