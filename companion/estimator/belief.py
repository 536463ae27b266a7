"""The belief loss ℓ(β) (the paper's eq. 16, in a form whose minimum is at consistency) and its
analytic derivative ∂ℓ/∂β, as pure functions.

At a fix, everything but the belief is fixed: the innovation ``y``, the posterior of the
previous fusion propagated over the interval T, the nominal R. The belief enters the
innovation covariance twice, through ``R(β)`` and through the bias process noise of the last
interval (we include that path; the older posteriors' dependence on earlier beliefs is
truncated, as in every online gradient):

    S(β) = S₀ + q_b σ_b(β)² I + r(β) R_nom        (diagonal: the axes are independent)
    S₀   = H (F P⁺ Fᵀ + Q_pv) Hᵀ,  q_b = 1 − α(T)²,  σ_b(β) = σ_max (1 − β) + ε,
    r(β) = k_R^(1−β)
    Ṡ    = ∂S/∂β = −2 q_b σ_b σ_max I − ln(k_R) r(β) R_nom

Loss (minimum where S matches the innovation, i.e. at statistical consistency):

    gaussian:  ℓ = ½ log det S + ½ NIS
    student-t: ℓ = ½ log det S + ((ν+m)/2) log(1 + NIS/ν)      (ν = χ²₀.₉₅ by default)
    both:      + λ ‖Δp(β)‖,  Δp = [K(β) y]_p, the position jump the fix causes

For one axis the Gaussian term is minimal at s = y²; the Student-t term at NIS = m. We take Δp
as the jump p̂_k|k − p̂_k|k−1 rather than p̂_k|k − p̂_k−1|k−1 of eq. 16: the propagated part of
the latter does not depend on β and mostly measures flight speed. The derivatives are

    ∂½log det S/∂β = ½ tr(S⁻¹Ṡ),   ∂NIS/∂β = −yᵀS⁻¹ṠS⁻¹y,
    ∂Δp/∂β = −(P⁻Hᵀ)_p S⁻¹ Ṡ S⁻¹ y     ((P⁻Hᵀ)_p does not depend on β: Q_b sits in the b-b block)

S is diagonal (``model.py``), so everything below is a sum over the three axes of scalars.
``paper_loss_grad`` is the loss exactly as printed (eq. 16, log(1 + NIS/χ²) + λ‖Δp‖), kept
only for comparison: it decreases monotonically as trust falls, so it has no interior minimum.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from companion.estimator.config import EstimatorConfig

Vec3 = tuple[float, float, float]


class InnovationTerms(NamedTuple):
    """What a fix offers to the adaptation rules, per NED axis (m, m²)."""

    y: Vec3  # innovation z − (p⁻ + b⁻)
    s0: Vec3  # β-independent part of diag(H P⁻ Hᵀ)
    q_bias_unit: float  # 1 − α(T)²: H Q_b Hᵀ = this · σ_b(β)² I
    r_nominal: Vec3  # nominal R (variances)
    pht_p: Vec3  # position rows of P⁻ Hᵀ: P⁻_pp + P⁻_pb (β-independent)
    bias_scale: float = 1.0  # the receiver's scale of the bias range: σ_b(β) × this (config.bias_scale)
    # second moment of the GNSS-bias estimate at the fix, b̂⁻² + P⁻_bb per axis (m²): the bias-level term
    bias_m2: Vec3 = (0.0, 0.0, 0.0)

    def hph(self, sigma_bias_m: float) -> Vec3:
        """diag(H P⁻ Hᵀ) for a bias std σ_b (before the receiver's scale)."""
        sb = sigma_bias_m * self.bias_scale
        q = self.q_bias_unit * sb * sb
        return (self.s0[0] + q, self.s0[1] + q, self.s0[2] + q)


def s_of_beta(beta: float, t: InnovationTerms, cfg: EstimatorConfig) -> tuple[Vec3, Vec3]:
    """(diag S(β), diag ∂S/∂β)."""
    f = t.bias_scale
    sb = cfg.sigma_bias_m(beta) * f
    r = cfg.r_factor(beta)
    q = t.q_bias_unit * sb * sb
    hph = (t.s0[0] + q, t.s0[1] + q, t.s0[2] + q)
    dq = -2.0 * t.q_bias_unit * sb * cfg.sigma_bias_max_m * f
    dr = -math.log(cfg.r_inflation_max) * r
    S = (hph[0] + r * t.r_nominal[0], hph[1] + r * t.r_nominal[1], hph[2] + r * t.r_nominal[2])
    dS = (dq + dr * t.r_nominal[0], dq + dr * t.r_nominal[1], dq + dr * t.r_nominal[2])
    return S, dS


def _terms(beta: float, t: InnovationTerms, cfg: EstimatorConfig
           ) -> tuple[float, float, float, float, float, float]:
    """(log det S, its β-derivative, NIS, ∂NIS/∂β, λ‖Δp‖, its β-derivative): sums over the three
    axes, written out (the engine calls this at every fix)."""
    (s0, s1, s2), (ds0, ds1, ds2) = s_of_beta(beta, t, cfg)
    y0, y1, y2 = t.y
    p0, p1, p2 = t.pht_p
    w0, w1, w2 = y0 / s0, y1 / s1, y2 / s2
    log = math.log
    logdet = 0.0 + log(s0) + log(s1) + log(s2)
    d_logdet = 0.0 + ds0 / s0 + ds1 / s1 + ds2 / s2
    nis = 0.0 + y0 * w0 + y1 * w1 + y2 * w2
    d_nis = 0.0 - w0 * w0 * ds0 - w1 * w1 * ds1 - w2 * w2 * ds2
    j0, j1, j2 = p0 * w0, p1 * w1, p2 * w2  # position jump of each axis
    dp2 = 0.0 + j0 * j0 + j1 * j1 + j2 * j2
    d_dp2 = (0.0 + 2.0 * j0 * (-p0 * w0 * ds0 / s0) + 2.0 * j1 * (-p1 * w1 * ds1 / s1)
             + 2.0 * j2 * (-p2 * w2 * ds2 / s2))
    lam = cfg.lambda_smooth_1_m
    n = math.sqrt(dp2)
    smooth, d_smooth = (lam * n, 0.5 * lam * d_dp2 / n) if n > 0.0 else (0.0, 0.0)
    return logdet, d_logdet, nis, d_nis, smooth, d_smooth


def bias_level(beta: float, t: InnovationTerms, cfg: EstimatorConfig) -> tuple[float, float]:
    """(ℓ_b(β), ∂ℓ_b/∂β): the bias-level term, λ_b Σ_axes [log σ + m_i / (2σ²)] with σ = σ_b(β) × the
    receiver's scale and m_i = b̂⁻² + P⁻_bb the second moment of the bias estimate. It is the negative
    log-likelihood of the bias the filter holds under the stationary range β allows (minimal at
    σ² = mean m: the expectation-maximisation update of a prior variance). A one-step innovation
    shows the bias's change over one fix interval, not its level; this term shows the level. Where
    the bias is unobservable (no receiver velocity) its estimate stays near 0 with P⁻_bb near σ²:
    the term then pushes nowhere. 0 when ``lambda_bias_level`` is 0."""
    w = cfg.lambda_bias_level
    if w == 0.0:
        return 0.0, 0.0
    f = t.bias_scale
    sigma = cfg.sigma_bias_m(beta) * f
    m = t.bias_m2[0] + t.bias_m2[1] + t.bias_m2[2]
    inv2 = 1.0 / (sigma * sigma)
    return (w * (3.0 * math.log(sigma) + 0.5 * m * inv2),
            w * (3.0 - m * inv2) / sigma * (-cfg.sigma_bias_max_m * f))


def loss_grad(beta: float, t: InnovationTerms, cfg: EstimatorConfig) -> tuple[float, float, float]:
    """(ℓ(β), ∂ℓ/∂β, NIS) for the consistency loss selected by ``cfg.loss``, plus the bias-level term."""
    logdet, d_logdet, nis, d_nis, smooth, d_smooth = _terms(beta, t, cfg)
    if cfg.loss == "gaussian":
        fit, d_fit = 0.5 * nis, 0.5 * d_nis
    else:
        nu, m = cfg.student_dof, 3.0
        fit = 0.5 * (nu + m) * math.log1p(nis / nu)
        d_fit = 0.5 * (nu + m) * d_nis / (nu + nis)
    level, d_level = bias_level(beta, t, cfg)
    return 0.5 * logdet + fit + smooth + level, 0.5 * d_logdet + d_fit + d_smooth + d_level, nis


def loss_params(cfg: EstimatorConfig) -> tuple[float, float, float, float, float, float, float]:
    """The configuration's numbers ``loss_grad`` reads, as the C core's ``_core.loss_grad(beta, t, params)``
    takes them (the same computation, operation for operation: the methods' path at every fix; tested
    bit for bit against ``loss_grad``): σ_b,max, σ_b floor, R inflation max, λ, Student-t (1) or Gaussian
    (0), ν, λ_b."""
    return (cfg.sigma_bias_max_m, cfg.sigma_bias_floor_m, cfg.r_inflation_max, cfg.lambda_smooth_1_m,
            0.0 if cfg.loss == "gaussian" else 1.0, cfg.student_dof, cfg.lambda_bias_level)


def paper_loss_grad(beta: float, t: InnovationTerms, cfg: EstimatorConfig) -> tuple[float, float, float]:
    """(ℓ, ∂ℓ/∂β, NIS) of eq. 16 as printed: log(1 + NIS/χ²₀.₉₅) + λ‖Δp‖ (no interior minimum)."""
    _, _, nis, d_nis, smooth, d_smooth = _terms(beta, t, cfg)
    c = cfg.chi2_095
    return math.log1p(nis / c) + smooth, d_nis / (c + nis) + d_smooth, nis


def sigmoid(theta: float) -> float:
    """β = σ(θ) (eq. 15)."""
    return 1.0 / (1.0 + math.exp(-theta))
