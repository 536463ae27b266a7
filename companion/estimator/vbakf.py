"""Variational-Bayes adaptive Kalman update (Särkkä & Nummenmaa 2009): an extra baseline.

The measurement noise covariance ``R`` is unknown and slowly varying. Its posterior is kept
as an inverse-Wishart density ``IW(ν, V)`` (full-matrix form of the paper's per-axis
inverse-Gamma; with diagonal ``V`` the two coincide). Per fix:

- predict (forgetting, ``0 < ρ ≤ 1``): ``ν⁻ = ρ ν``, ``V⁻ = ρ V``, so old residuals fade
  with an effective memory of ``1 / (1 − ρ)`` fixes;
- update, a few fixed-point iterations of the mean-field VB solution:
  ``R̂ = E[R⁻¹]⁻¹ = V / ν`` → Kalman update of ``(x, P)`` with ``R̂`` →
  ``ν = ν⁻ + 1``, ``V = V⁻ + (z − H x)(z − H x)ᵀ + H P Hᵀ``.

In steady state ``V / ν`` is the exponentially weighted mean of ``e eᵀ + H P Hᵀ``, i.e. an
unbiased estimate of a constant ``R``. Pure numpy, no I/O. Registered as the estimator method
``vbakf``: the belief stays at ``beta_fixed`` (as for ``naive``/``adaptive``) and R is learned.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from companion.estimator.belief import InnovationTerms, Vec3
from companion.estimator.config import EstimatorConfig
from companion.estimator.methods import register


@dataclass(frozen=True)
class VbConfig:
    """Hyper-parameters of the VB noise-covariance learner (values: ``EstimatorConfig.vb_*``)."""

    forgetting: float  # ρ per fix [-]
    iterations: int  # fixed-point iterations per fix [-]
    prior_dof: float  # ν of the initial IW density [fixes of evidence]

    @classmethod
    def of(cls, cfg: EstimatorConfig) -> VbConfig:
        return cls(cfg.vb_forgetting, cfg.vb_iterations, cfg.vb_prior_dof)


@dataclass(frozen=True)
class NoisePosterior:
    """``R ~ IW(ν, V)``; the point estimate used by the filter is ``V / ν``."""

    dof: float  # ν
    scale: np.ndarray  # V, (m, m), m² units of the measurement

    @classmethod
    def prior(cls, R0: np.ndarray, cfg: VbConfig) -> NoisePosterior:
        return cls(cfg.prior_dof, cfg.prior_dof * np.asarray(R0, dtype=float))

    @property
    def R_hat(self) -> np.ndarray:
        return self.scale / self.dof

    def predict(self, cfg: VbConfig) -> NoisePosterior:
        return NoisePosterior(cfg.forgetting * self.dof, cfg.forgetting * self.scale)


def vb_iterate(
    y: np.ndarray, hph: np.ndarray, noise: NoisePosterior, cfg: VbConfig, diagonal: bool = False
) -> tuple[np.ndarray, NoisePosterior]:
    """The VB fixed point in measurement space, for a fix with innovation ``y`` and
    predicted ``H P⁻ Hᵀ = hph``; ``noise`` is the predicted (forgotten) posterior.

    With ``S = H P⁻ Hᵀ + R̂`` the Kalman update gives the posterior residual
    ``z − H x⁺ = R̂ S⁻¹ y`` and ``H P⁺ Hᵀ = H P⁻ Hᵀ − H P⁻ Hᵀ S⁻¹ H P⁻ Hᵀ``, so no state is
    needed. Returns the ``R̂`` to fuse this fix with (the last iteration's) and the new posterior.
    ``diagonal`` keeps the scale diagonal (independent per-axis inverse-Gamma posteriors).
    """
    dof = noise.dof + 1.0
    scale = noise.scale
    R = scale / dof
    for _ in range(cfg.iterations):
        R = scale / dof
        S = hph + R
        e = R @ np.linalg.solve(S, y)
        hph_post = hph - hph @ np.linalg.solve(S, hph)
        scale = noise.scale + np.outer(e, e) + hph_post
        scale = np.diag(np.diag(scale)) if diagonal else 0.5 * (scale + scale.T)
    return R, NoisePosterior(dof, scale)


def vb_update(
    x: np.ndarray,
    P: np.ndarray,
    z: np.ndarray,
    H: np.ndarray,
    noise: NoisePosterior,
    cfg: VbConfig,
) -> tuple[np.ndarray, np.ndarray, NoisePosterior]:
    """One VB measurement update of a linear-Gaussian state ``(x, P)``; ``noise`` is predicted.

    Returns the posterior state, its covariance (Joseph form) and the new noise posterior.
    """
    PHt = P @ H.T
    R, posterior = vb_iterate(z - H @ x, H @ PHt, noise, cfg)
    K = np.linalg.solve(H @ PHt + R, PHt.T).T
    IKH = np.eye(P.shape[0]) - K @ H
    return x + K @ (z - H @ x), IKH @ P @ IKH.T + K @ R @ K.T, posterior


@register("vbakf")
class VariationalBayesAKF:
    """The ``vbakf`` method: R learned by ``vb_iterate``; β held at ``beta_fixed`` (no belief).

    The filter runs its three NED axes independently (diagonal R and H P Hᵀ), so the scale
    is kept diagonal: exactly Särkkä & Nummenmaa's per-axis inverse-Gamma posteriors. The
    state is the ``NoisePosterior`` after the last fix (immutable, as the OOSM buffer needs).
    """

    def __init__(self, cfg: EstimatorConfig) -> None:
        self.cfg = cfg
        self.vb = VbConfig.of(cfg)
        self.sigma_bias_m = cfg.sigma_bias_m(cfg.beta_fixed)

    def initial_state(self) -> NoisePosterior:
        return NoisePosterior.prior(np.diag(np.diag(self.cfg.r_nominal_m2())), self.vb)

    def beta(self, state: NoisePosterior) -> float:
        return self.cfg.beta_fixed

    def _solve(self, state: NoisePosterior, terms: InnovationTerms) -> tuple[np.ndarray, NoisePosterior]:
        hph = np.diag(terms.hph(self.sigma_bias_m))
        R, post = vb_iterate(np.asarray(terms.y), hph, state.predict(self.vb), self.vb, diagonal=True)
        return np.diag(R), post

    def measurement_cov(self, state: NoisePosterior, terms: InnovationTerms) -> Vec3:
        r = self._solve(state, terms)[0]
        return (float(r[0]), float(r[1]), float(r[2]))

    def update(self, state: NoisePosterior, terms: InnovationTerms) -> NoisePosterior:
        return self._solve(state, terms)[1]
