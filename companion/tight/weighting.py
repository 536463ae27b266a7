"""How each satellite is weighted in a tightly coupled update: the rows to beat and the per-satellite
belief, selectable by name (``WEIGHTINGS``).

A weighting sees one epoch's ``SatTerms`` (per satellite: the pre-fit innovation, the β-independent
part of its innovation variance, the nominal variance, the prior logit) and a ``solve(r, used)``
callback (the filter's update with those variances and satellites; it returns the post-fit
residuals and the innovation covariance), and returns the variances to fuse with, the satellites to
use and its new state. States are immutable (the out-of-sequence history keeps them).

* ``naive``: one σ for every satellite (``sigma_uniform_m``): fixed weights;
* ``cn0-elevation``: the single-point solution's σ model (C/N0 and elevation) — every row below
  starts from it;
* ``fde``: that, with the χ² test of the epoch's normalised innovations; while it fails, the
  satellite with the largest normalised innovation is excluded (RAIM/FDE in the filter);
* ``student-t``: a heavy-tailed (Student-t, ν = ``student_dof``) update by iteratively reweighted
  least squares: each satellite's variance is divided by its weight (ν + 1)/(ν + e²/R) from its
  post-fit residual e;
* ``first-order`` / ``second-order``: the per-satellite belief (``belief.py``), R_s(β_s) = R_nom,s ·
  k^(1 − β_s), β_s learned from each satellite's consistency with the paper's first-order or
  second-order (damped Newton, dual-timescale) rule.

Every row tests each satellite against the innovation gate (``gate_sigma``) with its variance.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple, Protocol

import numpy as np

from companion.errors import not_one_of
from companion.gnss.spp import chi2_threshold
from companion.tight import _tight, belief, snapshot
from companion.tight.config import TightConfig


class SatTerms(NamedTuple):
    """One epoch's pseudorange terms, per satellite (arrays (m,))."""

    key: np.ndarray  # int: system × 1000 + PRN
    y: np.ndarray  # pre-fit innovation z − h(x⁻) (m)
    s0: np.ndarray  # (H P⁻ Hᵀ)_ii (m²)
    r_nominal: np.ndarray  # a-priori variance from the σ model (m²)
    theta_prior: np.ndarray  # prior belief logit from C/N0, elevation (and the map)
    r_model: np.ndarray | None = None  # the C/N0 + elevation σ model's variance (the belief's robust fix)
    # the snapshot's design G (m, 3 + clocks: snapshot.design) and the predicted position's covariance
    # and clocks (3 + clocks, 3 + clocks), given when belief_innovation is "snapshot"
    geometry: np.ndarray | None = None
    p_pos_m2: np.ndarray | None = None


class Weighed(NamedTuple):
    r: np.ndarray  # variances to fuse with (m,)
    used: np.ndarray  # bool (m,)
    state: Any  # the new state
    beta: np.ndarray  # belief per satellite in [0, 1] (1 for the rows without one)


Solve = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]  # (r, used) -> (post-fit e, S)


class Weighting(Protocol):
    # the nominal variance: "uniform" (sigma_uniform_m²), "model" (C/N0 + elevation), "los" (a
    # line-of-sight signal's: C/N0 only; the belief and its prior carry the rest)
    nominal: str
    uses_prior: bool  # reads SatTerms.theta_prior (the engine adds the map's term only then)

    def initial_state(self) -> Any: ...

    def weigh(self, state: Any, t: SatTerms, solve: Solve) -> Weighed:
        """The variances to fuse with, the satellites to use, the new state and the beliefs."""
        ...


REGISTRY: dict[str, Callable[[TightConfig], Weighting]] = {}


def register(name: str) -> Callable[[Any], Any]:
    def deco(cls: Any) -> Any:
        REGISTRY[name] = cls
        return cls

    return deco


def check_weighting(name: str, what: str = "--method (tight coupling)") -> str:
    """``name`` if it is a tight-coupling row, else a one-line ``ConfigError`` naming them."""
    if name not in REGISTRY:
        raise not_one_of(what, name, tuple(REGISTRY))
    return name


def make(name: str, cfg: TightConfig) -> Weighting:
    return REGISTRY[check_weighting(name)](cfg)


def gate(t: SatTerms, r: np.ndarray, cfg: TightConfig) -> np.ndarray:
    """Satellites whose pre-fit innovation is within ``gate_sigma`` of √(s0 + r)."""
    return t.y * t.y <= cfg.gate_sigma**2 * (t.s0 + r)


@register("naive")
class Fixed:
    """Fixed weights: σ = ``sigma_uniform_m`` for every satellite."""

    nominal = "uniform"
    uses_prior = False  # the per-satellite prior (C/N0, elevation, map) is read

    def __init__(self, cfg: TightConfig) -> None:
        self.cfg = cfg

    def initial_state(self) -> None:
        return None

    def weigh(self, state: Any, t: SatTerms, solve: Solve) -> Weighed:
        return Weighed(t.r_nominal, gate(t, t.r_nominal, self.cfg), state, np.ones(len(t.y)))


@register("cn0-elevation")
class SigmaModel(Fixed):
    """The C/N0 + elevation σ model (``companion.gnss.spp.sigma_model_m``'s ``cn0-elevation``)."""

    nominal = "model"


@register("fde")
class Fde(SigmaModel):
    """χ² test of the normalised innovations yᵀ S⁻¹ y; the worst satellite out while it fails."""

    def weigh(self, state: Any, t: SatTerms, solve: Solve) -> Weighed:
        c = self.cfg
        used = gate(t, t.r_nominal, c)
        for _ in range(c.fde_max_exclusions):
            idx = np.flatnonzero(used)
            if len(idx) < 5:
                break
            _, S_used = solve(t.r_nominal, used)  # the filter's S (not diagonal: the common position)
            w = np.linalg.solve(S_used, t.y[idx])
            stat = float(t.y[idx] @ w)
            if stat <= chi2_threshold(c.fde_p_false_alarm, len(idx)):
                break
            norm = np.abs(w) / np.sqrt(np.diag(np.linalg.inv(S_used)))  # standardised innovations
            used = used.copy()
            used[idx[int(np.argmax(norm))]] = False
        return Weighed(t.r_nominal, used, state, np.ones(len(t.y)))


@register("student-t")
class StudentT(SigmaModel):
    """Iteratively reweighted update with Student-t weights (ν + 1) / (ν + e² / R_nom)."""

    def weigh(self, state: Any, t: SatTerms, solve: Solve) -> Weighed:
        r = student_t_variances(t, t.r_nominal, solve, self.cfg)
        return Weighed(r, gate(t, t.r_nominal, self.cfg), state, np.ones(len(t.y)))


BeliefMap = dict[int, tuple[float, float, float]]  # key -> (θ, H_fast, H_slow), never mutated


@register("second-order")
class SatelliteBelief(SigmaModel):
    """A belief per satellite, learned by the paper's second-order rule (``belief.py``)."""

    nominal = "los"
    uses_prior = True
    first_order = False

    def __init__(self, cfg: TightConfig) -> None:
        super().__init__(cfg)
        if cfg.belief_sigma_model == "cn0-elevation":  # the single-point solution's σ model as R_nom
            self.nominal = "model"
        self.r_scale = cfg.belief_sigma_scale**2  # R_nom: a line-of-sight signal's, below the σ model

    def initial_state(self) -> BeliefMap:  # type: ignore[override]
        return {}

    def _gather(self, state: BeliefMap, t: SatTerms) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(θ, H_fast, H_slow) per satellite: its own, or a new satellite's (its prior, 1, 1)."""
        lo, hi = self.cfg.theta_min, self.cfg.theta_max
        get, flat = state.get, list[float]()
        for k, p in zip(t.key.tolist(), t.theta_prior.tolist(), strict=True):
            flat += get(k) or (min(max(p, lo), hi), 1.0, 1.0)
        a = np.array(flat).reshape(-1, 3)  # one flat list: numpy's shape discovery of nested rows costs more
        return a[:, 0], a[:, 1], a[:, 2]

    def weigh(self, state: BeliefMap, t: SatTerms, solve: Solve) -> Weighed:
        c = self.cfg
        if self.r_scale != 1.0:  # R_nom below the σ model (the range rates' variances follow R / the model's)
            t = t._replace(r_nominal=t.r_nominal * self.r_scale)
        theta, hf, hs = self._gather(state, t)
        y, s0 = t.y, t.s0
        if c.belief_innovation == "leave-one-out" and len(y) > 1:
            y, s0 = leave_one_out(t, t.r_nominal * c.r_inflation_max ** (1.0 - 1.0 / (1.0 + np.exp(-theta))),
                                  solve)
        elif c.belief_innovation == "robust" and len(y) > 1:
            r_model = t.r_model if t.r_model is not None else t.r_nominal
            y, s0 = leave_one_out(t, student_t_variances(t, r_model, solve, c), solve)
        elif c.belief_innovation == "snapshot" and t.geometry is not None and len(y) > t.geometry.shape[1]:
            G = t.geometry
            assert t.p_pos_m2 is not None
            r_b = belief.r_of_beta(belief.sigmoid(theta), t.r_nominal, c)  # each satellite's R(β)
            y_s, s0_s = snapshot.leave_one_out(
                G, y, r_b, s0, snapshot.position_prior(t.p_pos_m2, c.belief_snapshot_sigma_m,
                                                    c.belief_snapshot_clocks_free),
                c.belief_snapshot_iterations, c.student_dof, c.belief_early_factor)
            b = c.belief_snapshot_blend
            y, s0 = (1.0 - b) * y + b * y_s, (1.0 - b) * s0 + b * s0_s
        # belief.consistency_innovation (early innovations scaled), belief.epoch_scale (joint consistency),
        # belief.grad_theta, the (second- or first-order) step, the clamp, R(β) and the gate, in C
        # (``_tight.belief_step``; equal to belief.py's numpy forms, tested)
        theta, hf, hs, beta, r, used = _tight.belief_step(
            theta, hf, hs, y, s0, t.r_nominal, t.theta_prior, c.eta, c.lambda_reg, c.alpha_fast,
            c.alpha_slow, c.omega_fast, c.student_dof, c.r_inflation_max, c.prior_weight, c.theta_min,
            c.theta_max, c.gate_sigma**2, self.first_order, c.belief_epoch_scale, c.belief_early_factor)
        # every row's gate: the pre-fit innovation against its variance
        used = gate(t, r, c) if y is not t.y else used > 0.0
        new = dict(state)
        rows = zip(theta.tolist(), hf.tolist(), hs.tolist(), strict=True)
        new.update(zip(t.key.tolist(), rows, strict=True))
        r_fuse = r
        nu = c.student_dof
        for _ in range(c.belief_student_iterations):  # the epoch's heavy tail on top of the beliefs
            e, _ = solve(r_fuse, used)
            r_fuse = r / np.minimum((nu + 1.0) / (nu + e * e / r), 1.0 + 1.0 / nu)
        return Weighed(r_fuse, used, new, beta)


def student_t_variances(t: SatTerms, r_nominal: np.ndarray, solve: Solve, cfg: TightConfig) -> np.ndarray:
    """The student-t row's variances: ``student_iterations`` reweighted updates from ``r_nominal``."""
    nu = cfg.student_dof
    used = gate(t, r_nominal, cfg)
    r = r_nominal
    for _ in range(cfg.student_iterations):
        e, _ = solve(r, used)
        r = r_nominal / np.minimum((nu + 1.0) / (nu + e * e / r_nominal), 1.0 + 1.0 / nu)
    return r


def leave_one_out(t: SatTerms, r: np.ndarray, solve: Solve) -> tuple[np.ndarray, np.ndarray]:
    """Each satellite's innovation against the prediction corrected by every OTHER satellite of the
    epoch (variances ``r``), and its variance without the satellite's own R: with S = H P Hᵀ + diag(r)
    over all of them, ỹ_s = (S⁻¹ y)_s / (S⁻¹)_ss and 1/(S⁻¹)_ss = H_s P₋ₛ H_sᵀ + r_s (the Schur
    complement), so s̃0_s = 1/(S⁻¹)_ss − r_s. A satellite that has just been reflected shows its whole
    error (the others do not follow it), and a clean one is not blamed for the state's error."""
    _, S = solve(r, np.ones(len(t.y), dtype=bool))
    Si = np.linalg.inv(S)
    d = np.diag(Si).copy()
    return (Si @ t.y) / d, np.maximum(1.0 / d - r, 0.0)


@register("first-order")
class SatelliteBeliefFirstOrder(SatelliteBelief):
    """The same belief with the plain gradient step θ ← θ − η ∇θ ℓ."""

    first_order = True


WEIGHTINGS: tuple[str, ...] = tuple(REGISTRY)
DEFAULT_WEIGHTING = "second-order"
