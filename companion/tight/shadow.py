"""Shadow matching: the map's line of sight as a horizontal position measurement (opt-in,
``TightConfig.shadow_matching``; docs/tight.md "Shadow matching").

At an epoch, candidate positions lie on a grid around the filter's **predicted** horizontal position (the
predicted height): along the principal axes of the horizontal covariance widened by ``shadow_sigma_floor_m``
per axis, ``shadow_spacing_m`` apart, half-widths ``shadow_grid_sigmas`` σ clamped to
[``shadow_half_width_min_m``, ``shadow_half_width_max_m``] (at most (2 max / spacing + 1)² candidates, one
vectorised line-of-sight call over candidates × satellites). Each candidate k is scored by how well the
map's verdicts there explain the signals: with q_s = P(line of sight | C/N0, elevation) (the belief's prior,
``belief.sigmoid(theta_prior)``, the same probability ``belief.blocked_probability`` weighs its candidates
with, recalibrated: ``p_los``),

    log L_k = τ Σ_s [hidden_ks log(1 − q_s) + (1 − hidden_ks) log q_s]        (τ = ``shadow_tempering``)

under a FLAT prior over the grid (the filter's Gaussian would count its information twice). The
candidates' posterior has a mean m and a covariance C (+ spacing²/12 per axis for the grid's
resolution). The grid is centred on the prediction, so a posterior as wide as the grid says nothing: the
flat grid's own covariance C₀ is divided out along each principal axis u of C (variance v, the grid's
v₀ = uᵀ C₀ u): only axes with v < ``shadow_max_variance_ratio`` · v₀ are kept, as the measurement

    uᵀ p = v_u (uᵀ m / v − uᵀ m₀ / v₀),    v_u = 1 / (1 / v − 1 / v₀)   (the Gaussian quotient)

with variance max(``shadow_variance_scale`` · v_u, ``shadow_sigma_min_m``²) (the satellites' verdicts are
not independent: the posterior is optimistic). A street gives one such axis, across it: along it every
candidate sees the same sky. The filter gates the measurement against its prediction and fuses it (engine).

A function of the predicted state and the epoch only: a late epoch re-fused gives the same result.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from companion.tight.belief import LineOfSight, shadow_log_likelihood, sigmoid
from companion.tight.config import TightConfig


class ShadowFix(NamedTuple):
    """Rows of a horizontal position measurement: z = H p_NE, each row a unit vector (N, E)."""

    H: np.ndarray  # (r, 2), r = 1 or 2
    z: np.ndarray  # (r,)
    R: np.ndarray  # (r,) variances (the rows are orthogonal: independent)
    mean: np.ndarray  # (2,) the candidates' posterior mean (diagnostics)
    cov: np.ndarray  # (2, 2) their posterior covariance with the resolution term


def grid(p_ne_m: np.ndarray, P_ne_m2: np.ndarray, cfg: TightConfig) -> tuple[np.ndarray, np.ndarray]:
    """(K, 2) candidate positions around ``p_ne_m`` and the flat grid's covariance (2, 2)."""
    Ph = 0.5 * (P_ne_m2 + P_ne_m2.T) + np.eye(2) * cfg.shadow_sigma_floor_m**2
    lam, vec = np.linalg.eigh(Ph)
    sigma = np.sqrt(np.maximum(lam, 0.0))
    half = np.minimum(np.maximum(cfg.shadow_grid_sigmas * sigma, cfg.shadow_half_width_min_m),
                      cfg.shadow_half_width_max_m)
    d = cfg.shadow_spacing_m
    n = np.floor(half / d).astype(int)
    a = np.arange(-n[0], n[0] + 1) * d
    b = np.arange(-n[1], n[1] + 1) * d
    A, B = np.meshgrid(a, b, indexing="ij")
    off = np.column_stack((A.ravel(), B.ravel()))
    pts = np.asarray(p_ne_m, dtype=float)[None, 0:2] + off @ vec.T
    # the flat grid's covariance: per axis (n_i (n_i + 1) / 3) d² (a uniform lattice of 2 n_i + 1 points)
    var0 = n * (n + 1) / 3.0 * d * d + d * d / 12.0
    return pts, vec @ np.diag(var0) @ vec.T


def p_los(theta_prior: np.ndarray, cfg: TightConfig) -> np.ndarray:
    """Each signal's probability of a line of sight: the belief's C/N0 + elevation prior logit recalibrated
    as σ(a θ + b) (``shadow_logit_scale``, ``shadow_logit_offset``): the prior is a weighting, not a
    probability (in the simulated canyon 18 % of the signals are in line of sight where its σ(θ) averages
    ~0.6; a logistic fit on the tuning flights gives a and b)."""
    return sigmoid(cfg.shadow_logit_scale * theta_prior + cfg.shadow_logit_offset)


def posterior(pts: np.ndarray, log_l: np.ndarray, spacing_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Mean (2,) and covariance (2, 2) of the candidates under a flat prior, + the grid's resolution."""
    w = np.exp(log_l - log_l.max())
    w /= w.sum()
    mean = w @ pts
    d = pts - mean
    cov = (d * w[:, None]).T @ d + np.eye(2) * spacing_m**2 / 12.0
    return mean, 0.5 * (cov + cov.T)


def shadow_fix(line_of_sight: LineOfSight, p_ned_m: np.ndarray, P_pos_m2: np.ndarray, azimuth_rad: np.ndarray,
               elevation_rad: np.ndarray, theta_prior: np.ndarray, cfg: TightConfig) -> ShadowFix | None:
    """The shadow-matching measurement at the predicted position ``p_ned_m`` (3,) with covariance
    ``P_pos_m2`` (3, 3) for the epoch's satellites (azimuth, elevation, the unclamped C/N0 + elevation prior
    logit ``theta_prior``), or None (fewer than ``shadow_min_satellites``, or no axis better known than the
    grid)."""
    if len(azimuth_rad) < cfg.shadow_min_satellites:
        return None
    pts, C0 = grid(p_ned_m[0:2], P_pos_m2[0:2, 0:2], cfg)
    cand = np.empty((len(pts), 3))
    cand[:, 0:2] = pts
    cand[:, 2] = p_ned_m[2]
    hidden = np.asarray(line_of_sight(cand, azimuth_rad, elevation_rad), dtype=bool)
    mean, cov = posterior(pts, shadow_log_likelihood(hidden, p_los(theta_prior, cfg), cfg.shadow_tempering),
                          cfg.shadow_spacing_m)
    m0 = np.asarray(p_ned_m[0:2], dtype=float)
    lam, vec = np.linalg.eigh(cov)
    rows, zs, rs = [], [], []
    for i in range(2):
        u = vec[:, i]
        v, v0 = float(lam[i]), float(u @ C0 @ u)
        if not v < cfg.shadow_max_variance_ratio * v0:
            continue
        vu = 1.0 / (1.0 / v - 1.0 / v0)
        rows.append(u)
        zs.append(vu * (float(u @ mean) / v - float(u @ m0) / v0))
        rs.append(max(cfg.shadow_variance_scale * vu, cfg.shadow_sigma_min_m**2))
    if not rows:
        return None
    return ShadowFix(np.array(rows), np.array(zs), np.array(rs), mean, cov)


def innovation(fix: ShadowFix, p_ne_m: np.ndarray, P_ne_m2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(y, S) of the fix against a horizontal position N(p, P): y = z − H p, S = H P Hᵀ + diag(R)."""
    y = fix.z - fix.H @ p_ne_m[0:2]
    return y, fix.H @ P_ne_m2[0:2, 0:2] @ fix.H.T + np.diag(fix.R)


def passes_gate(fix: ShadowFix, p_ne_m: np.ndarray, P_ne_m2: np.ndarray, gate_sigma: float) -> bool:
    """The innovation gate against the prediction: yᵀ S⁻¹ y ≤ gate² × rows (as the odometry's)."""
    y, S = innovation(fix, p_ne_m, P_ne_m2)
    return bool(float(y @ np.linalg.solve(S, y)) <= gate_sigma**2 * len(y)) and math.isfinite(float(y @ y))
