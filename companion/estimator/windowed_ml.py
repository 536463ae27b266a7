"""``windowed-ml``: the belief as the maximum-likelihood trust level over a window of fixes.

The paper's rule takes one (damped Newton) step along the gradient of ONE fix's loss. This rule
asks, at every fix, which β would have explained the last N innovations best: with each stored
fix's own β-independent terms (``InnovationTerms``: S(β) = S₀ + q_b σ_b(β)² + r(β) R_nom), it
evaluates the innovation negative log-likelihood of ``EstimatorConfig.loss`` (Gaussian or
Student-t, ν = ``student_dof``; the consistency part of the belief loss, without the smoothness
term; with the bias-level term when ``lambda_bias_level`` > 0) summed over the window on a grid
of β, takes the minimiser β*, and moves β ← β + gain · (β* − β). A window is a likelihood, not a
gradient: no step size to tune against the loss's scale, no oscillation from a curvature
estimate, and it cannot run away on one outlier.

State: (β, the last N fixes' terms) — an immutable tuple, as the out-of-sequence buffer needs.
Hyper-parameters: ``PluginConfig.window_*`` (mission section ``belief_plugins:``, in its ``MethodContext``).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from companion.estimator.belief import InnovationTerms, Vec3
from companion.estimator.config import EstimatorConfig
from companion.estimator.methods import MethodContext, register


class WindowState(NamedTuple):
    beta: float
    window: tuple[InnovationTerms, ...]


def window_nll(betas: np.ndarray, window: tuple[InnovationTerms, ...], cfg: EstimatorConfig) -> np.ndarray:
    """Σ over the window of the innovation NLL at each β of ``betas`` (G,) → (G,)."""
    y = np.array([t.y for t in window])  # (N, 3)
    s0 = np.array([t.s0 for t in window])
    r_nom = np.array([t.r_nominal for t in window])
    q_unit = np.array([t.q_bias_unit * t.bias_scale * t.bias_scale for t in window])  # (N,): σ_b scaled
    sb = cfg.sigma_bias_max_m * (1.0 - betas) + cfg.sigma_bias_floor_m  # (G,)
    r = cfg.r_inflation_max ** (1.0 - betas)  # (G,)
    q_b = (q_unit[None, :] * (sb * sb)[:, None])[:, :, None]  # (G, N, 1)
    S = s0[None] + q_b + r[:, None, None] * r_nom[None]  # (G, N, 3)
    logdet = np.log(S).sum(axis=2)
    nis = (y[None] ** 2 / S).sum(axis=2)
    if cfg.loss == "gaussian":
        fit = 0.5 * nis
    else:
        nu = cfg.student_dof
        fit = 0.5 * (nu + 3.0) * np.log1p(nis / nu)
    total = (0.5 * logdet + fit).sum(axis=1)
    if cfg.lambda_bias_level > 0.0:  # the bias-level term (belief.bias_level), summed over the window
        sigma = sb[:, None] * np.array([t.bias_scale for t in window])[None, :]  # (G, N)
        m = np.array([sum(t.bias_m2) for t in window])  # (N,)
        level = 3.0 * np.log(sigma) + 0.5 * m[None, :] / sigma**2
        total = total + cfg.lambda_bias_level * level.sum(axis=1)
    return np.asarray(total)


@register("windowed-ml")
class WindowedMl:
    learns_from_rejected = True  # a gated-out fix is evidence about the trust level too
    def __init__(self, cfg: EstimatorConfig, context: MethodContext | None = None) -> None:
        self.cfg = cfg
        self.plugin = plugin = (context or MethodContext()).plugin
        self.grid = np.linspace(plugin.window_beta_min, plugin.window_beta_max, plugin.window_grid)

    def initial_state(self) -> WindowState:
        return WindowState(1.0 / (1.0 + math.exp(-self.cfg.theta0)), ())

    def beta(self, state: WindowState) -> float:
        return state.beta

    def measurement_cov(self, state: WindowState, terms: InnovationTerms) -> Vec3:
        f = self.cfg.r_factor(state.beta)
        return (f * terms.r_nominal[0], f * terms.r_nominal[1], f * terms.r_nominal[2])

    def update(self, state: WindowState, terms: InnovationTerms) -> WindowState:
        window = (*state.window, terms)[-self.plugin.window_fixes:]
        best = float(self.grid[int(np.argmin(window_nll(self.grid, window, self.cfg)))])
        return WindowState(state.beta + self.plugin.window_gain * (best - state.beta), window)
