"""Within-epoch evidence for the per-satellite belief: each satellite against the epoch's own robust
solution of position and clocks, leaving that satellite out.

The pre-fit innovation y = z − h(x⁻) of every satellite carries the prediction's own error (position
and clock), which all the satellites of the epoch share, and the clock of the prediction already holds
the common part of the reflections' delays. Re-solving position (about the prediction) and each
system's clock from this epoch's satellites is meant to remove both (on the canyon's tuning flights it
did not help: the epoch's own solution absorbs more of the reflections than the prediction does;
docs/tight.md): a linear least-squares step from the prediction with design ``G`` = [H's position
columns, one column per clock]

    δx̂ = A⁻¹ Gᵀ W y,   A = Gᵀ W G + Λ,   W = diag(w)

where Λ is the prior on the correction (``position_prior``): the prediction's position known to P_pos +
σ² per axis (``belief_snapshot_sigma_m``; σ = ∞: the epoch alone) and the clocks either free (re-solved from
the epoch) or as predicted (their P). Its residuals e = y − G δx̂ and the leverages h_i = w_i g_i A⁻¹ g_iᵀ
give, exactly, each satellite's residual against the solution of the OTHER satellites (the hat matrix's
leave-one-out identity)

    ỹ_i = e_i / (1 − h_i),   with variance q_i / (1 − h_i) of that solution there (q_i = g_i A⁻¹ g_iᵀ)

so a reflected satellite shows its whole delay and a clean one is not blamed for the others'. The
weights are the satellites' current beliefs' (1/R(β)), reweighted ``iterations`` times as a Student-t
M-estimator does ((ν + 1)/(ν + ẽ²/R), ẽ the residual with an early residual scaled by
``early_factor``: NLOS only delays, so an early satellite is not suspect, and the clocks settle on the
earliest consistent ones). A satellite alone on its clock (h = 1) keeps its pre-fit innovation.
"""

from __future__ import annotations

import numpy as np

LEVERAGE_MAX = 0.999  # above this a satellite decides its own fit (alone on its clock): pre-fit kept


def weighted_fit(G: np.ndarray, y: np.ndarray, w: np.ndarray, prior_info: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(residuals e, q_i = g_i A⁻¹ g_iᵀ, leverages h = w q) of the regularised weighted fit (module doc)."""
    A = G.T @ (G * w[:, None]) + prior_info
    Ai = np.linalg.inv(A)
    dx = Ai @ (G.T @ (w * y))
    q = np.einsum("ij,jk,ik->i", G, Ai, G)
    return y - G @ dx, q, w * q


def leave_one_out(G: np.ndarray, y: np.ndarray, r: np.ndarray, s0: np.ndarray, prior_info: np.ndarray,
                  iterations: int = 0, nu: float = 2.0, early_factor: float = 1.0
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(ỹ, s̃0): each satellite's residual against the (robust) fit of the others, and that fit's variance
    at the satellite (module doc). ``r`` (m,) the satellites' variances, ``s0`` their pre-fit variances
    (kept with y where a satellite is alone on its clock)."""
    w0 = 1.0 / r
    w = w0
    for _ in range(iterations):
        e, _, _ = weighted_fit(G, y, w, prior_info)
        e = np.where(e < 0.0, early_factor * e, e)
        w = w0 * np.minimum((nu + 1.0) / (nu + e * e * w0), 1.0 + 1.0 / nu)
    e, q, h = weighted_fit(G, y, w, prior_info)
    ok = h < LEVERAGE_MAX
    one_minus = np.where(ok, 1.0 - h, 1.0)
    return np.where(ok, e / one_minus, y), np.where(ok, q / one_minus, s0)


def position_prior(P_pc_m2: np.ndarray, sigma_m: float, clocks_free: bool = True) -> np.ndarray:
    """Λ: the prior information on the correction of (position, clocks), ``P_pc_m2`` the predicted covariance
    of those: (P_pos + σ² I)⁻¹ on the position (0 for σ = ∞) and none on the clocks (``clocks_free``), or
    (P_pc + diag(σ² I, 0))⁻¹ (the clocks as predicted, the position's prior widened by σ)."""
    n = P_pc_m2.shape[0]
    if clocks_free:
        lam = np.zeros((n, n))
        if np.isfinite(sigma_m):
            lam[0:3, 0:3] = np.linalg.inv(P_pc_m2[0:3, 0:3] + np.eye(3) * sigma_m**2)
        return lam
    if not np.isfinite(sigma_m):
        lam = np.zeros((n, n))
        lam[3:, 3:] = np.linalg.inv(P_pc_m2[3:, 3:])
        return lam
    widen = np.zeros((n, n))
    widen[0:3, 0:3] = np.eye(3) * sigma_m**2
    return np.linalg.inv(P_pc_m2 + widen)


def epoch_fix(H: np.ndarray, y: np.ndarray, r: np.ndarray, slot: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray] | None:
    """The epoch's own position about the prediction, as the filter weighed its satellites: the weighted
    least-squares correction δp (N, E, D; m) of position (``H``'s first three columns) and one clock per
    clock slot present (``slot``) from the pre-fit innovations ``y`` with weights 1/``r``, and its
    variances diag((Gᵀ W G)⁻¹) of δp (m²). A linearised single-point solution: the prediction plus δp
    is the satellites' position to first order whatever the prediction (its error drops out), so a
    series of them is a series of fixes independent of the filter (the reported accuracy's
    ``consistency.Scatter``). None without a redundant satellite (a solution nothing checks: one wrong
    range moves it unseen) or with a singular geometry."""
    slots = np.unique(slot)
    k = 3 + len(slots)
    if len(y) <= k:
        return None
    G = np.empty((len(y), k))
    G[:, 0:3] = H[:, 0:3]
    G[:, 3:] = slot[:, None] == slots[None, :]
    w = 1.0 / r
    Gw = G.T * w
    rhs = np.zeros((k, 4))
    rhs[:, 0] = Gw @ y
    rhs[0:3, 1:4] = np.eye(3)
    try:
        sol = np.linalg.solve(Gw @ G, rhs)
    except np.linalg.LinAlgError:
        return None
    var = np.diag(sol[0:3, 1:4]).copy()
    if not (np.isfinite(sol[0:3, 0]).all() and (var > 0.0).all() and np.isfinite(var).all()):
        return None
    return sol[0:3, 0].copy(), var


def delay_bias(H: np.ndarray, r: np.ndarray, slot: np.ndarray) -> np.ndarray | None:
    """The epoch's own position's correction (N, E, D; m) were every satellite late by its own σ = √``r``
    (``epoch_fix`` with y = √r): the bias one-signed errors of that size leave in a snapshot. A reflected
    signal only ever arrives late, so a street's errors have a mean; the part common to all satellites goes
    to the clocks, what differs between them (larger at low elevation, on one side of the street) moves the
    position and averages out over no window. The reported accuracy's delay term (``TightConfig.
    accuracy_delay_fraction``, docs/tight.md "Reported accuracy"). None as ``epoch_fix``."""
    fix = epoch_fix(H, np.sqrt(r), r, slot)
    return None if fix is None else fix[0]


def epoch_velocity(sat_pos_ecef_m: np.ndarray, sat_vel_ecef_m_s: np.ndarray, r_ecef_m: np.ndarray,
                   c_ecef_ned: np.ndarray, rate_m_s: np.ndarray, r_rate_m2_s2: np.ndarray
                   ) -> np.ndarray | None:
    """The epoch's own velocity (N, E, D; m/s) from its pseudorange rates alone: the weighted least squares
    of rate − l·v_sat = −l·v + clock drift over the satellites with a finite rate (l the unit line of sight
    from ``r_ecef_m``, a position within metres is enough; weights 1/``r_rate_m2_s2``). Independent of the
    pseudoranges' errors: the motion between the epochs' snapshot positions (``epoch_fix``). None with
    fewer than 5 rates or a singular geometry."""
    ok = np.isfinite(rate_m_s)
    if int(ok.sum()) < 5:
        return None
    d = sat_pos_ecef_m[ok] - r_ecef_m
    los = d / np.sqrt(np.einsum("ij,ij->i", d, d))[:, None]
    y = rate_m_s[ok] - np.einsum("ij,ij->i", los, sat_vel_ecef_m_s[ok])
    G = np.empty((len(y), 4))
    G[:, 0:3] = -(los @ c_ecef_ned)
    G[:, 3] = 1.0
    w = 1.0 / r_rate_m2_s2[ok]
    Gw = G.T * w
    try:
        v = np.linalg.solve(Gw @ G, Gw @ y)
    except np.linalg.LinAlgError:
        return None
    return v[0:3] if np.isfinite(v).all() else None
