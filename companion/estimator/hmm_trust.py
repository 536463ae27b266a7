"""``hmm-trust``: the GNSS belief as a probability — an HMM over discrete trust levels.

The paper calls its β an "explicit belief" but updates it by a gradient step on a loss. This rule
makes the belief a probability literally. The GNSS is in one of L trust levels; level j is a pair
(σ_b,j, k_j): the multipath-bias process noise std over the interval and the measurement-noise
factor R_j = k_j R_nom. Levels (``PluginConfig.hmm_*``):

    clean     β = hmm_beta_clean (1)   σ_b(β) (ε at β = 1)   k = r_inflation_max^(1−β)   (R(β), Q_b(β))
    degraded  β = hmm_beta_degraded    σ_b(β)                k = r_inflation_max^(1−β)   of the trust model)
    outlier   β = 0                    σ_b(0)                k = hmm_outlier_r_factor      (NLOS steps,
                                                                                       heavy tails)

(``hmm_levels: 2`` drops the outlier level.) With ``hmm_split_vertical`` there are two such chains,
one on the horizontal axes and one on the vertical (a reflection lengthens the path, so NLOS
errors are mostly vertical): each axis is fused with its own chain's R, and β is the horizontal
chain's. Per fix, over the interval T since the last one:

1. predict with a stated Markov chain: level j is kept with probability exp(−T / D_j) (its mean
   dwell time D_j in seconds: ``hmm_dwell_s`` for clean and degraded, ``hmm_outlier_dwell_s`` for
   the outlier level) and otherwise left for one of the other L − 1 levels uniformly:
   A_ij = e_i if i = j else (1 − e_i) / (L − 1), e_i = exp(−T / D_i);  π⁻ = Aᵀ π;
2. update with the innovation likelihood of each level, per NED axis (S is diagonal):
   S_j = s0 + (1 − α(T)²) σ_b,j² + k_j R_nom,  π⁺_j ∝ π⁻_j Π_axes N(y; 0, S_j);
3. fuse the fix with the mixture's moment-matched noise R = Σ_j π⁺_j k_j R_nom (so an NLOS step
   seen as an outlier is down-weighted at once, on the very fix that shows it);
4. β = the posterior mean trust Σ_j π⁺_j β_j (= P(clean) when the other levels have β = 0); it sets
   σ_b(β) for the next interval as every belief method's β does.

Recovery is bounded by construction: after the prediction every level keeps at least
min_i (1 − e_i) / (L − 1) of probability, so a run of bad fixes can never drive P(clean) to 0, and
with uninformative fixes the posterior relaxes to the chain's stationary law (π_j ∝ D_j for short
intervals; ``stationary``) at the rate of its second eigenvalue (``relaxation_factor``). The
initial belief is that law.

T is not handed to an adaptation method; it is recovered exactly from the bias decay the engine
used, q = 1 − exp(−2T/τ): T = −(τ/2) ln(1 − q). State: one posterior π per chain (tuples), immutable.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from companion.estimator.belief import InnovationTerms, Vec3
from companion.estimator.config import EstimatorConfig
from companion.estimator.methods import MethodContext, register
from companion.estimator.plugin_config import PluginConfig

_LOG_2PI = math.log(2.0 * math.pi)
ALL_AXES = (0, 1, 2)
SPLIT_AXES = ((0, 1), (2,))  # hmm_split_vertical: horizontal (N, E) and vertical (D) chains

State = tuple[tuple[float, ...], ...]  # one posterior over the levels per chain


class Level(NamedTuple):
    """One trust level: its trust β (reported), bias std σ_b (m), R factor k and dwell time (s)."""

    beta: float
    sigma_bias_m: float
    r_factor: float
    dwell_s: float


def levels_of(cfg: EstimatorConfig, plugin: PluginConfig) -> tuple[Level, ...]:
    """The trust levels of the module docstring, from the estimator's trust model and the plugin's knobs."""
    levels = [Level(b, cfg.sigma_bias_m(b), cfg.r_factor(b), plugin.hmm_dwell_s)
              for b in (plugin.hmm_beta_clean, plugin.hmm_beta_degraded)]
    if plugin.hmm_levels == 3:
        levels.append(Level(0.0, cfg.sigma_bias_m(0.0), plugin.hmm_outlier_r_factor,
                            plugin.hmm_outlier_dwell_s))
    return tuple(levels)


def interval_s(terms: InnovationTerms, cfg: EstimatorConfig) -> float:
    """The prediction interval T (s) from q = 1 − exp(−2T/τ)."""
    q = min(terms.q_bias_unit, 1.0 - 1e-300)
    return -0.5 * cfg.bias_tau_s * math.log1p(-q)


def predict(pi: tuple[float, ...], levels: tuple[Level, ...], T_s: float) -> tuple[float, ...]:
    """π⁻ = Aᵀ π for the interval T (stay e_i = exp(−T/D_i), leave uniformly to the others)."""
    n = len(levels)
    stay = [math.exp(-T_s / lv.dwell_s) for lv in levels]
    leave = [pi[i] * (1.0 - stay[i]) / (n - 1) for i in range(n)]
    total_leave = sum(leave)
    return tuple(pi[j] * stay[j] + total_leave - leave[j] for j in range(n))


def log_likelihoods(terms: InnovationTerms, levels: tuple[Level, ...],
                    axes: tuple[int, ...] = ALL_AXES) -> tuple[float, ...]:
    """log N(y; 0, S_j) summed over ``axes`` (NED indices), per level."""
    out = []
    for lv in levels:
        sb = lv.sigma_bias_m * terms.bias_scale
        q = terms.q_bias_unit * sb * sb
        ll = 0.0
        for i in axes:
            s = terms.s0[i] + q + lv.r_factor * terms.r_nominal[i]
            ll -= 0.5 * (_LOG_2PI + math.log(s) + terms.y[i] * terms.y[i] / s)
        out.append(ll)
    return tuple(out)


def posterior(pi: tuple[float, ...], terms: InnovationTerms, levels: tuple[Level, ...],
              cfg: EstimatorConfig, axes: tuple[int, ...] = ALL_AXES) -> tuple[float, ...]:
    """π⁺ after the fix whose ``terms`` are given (prediction over its interval, then Bayes on ``axes``)."""
    prior = predict(pi, levels, interval_s(terms, cfg))
    ll = log_likelihoods(terms, levels, axes)
    top = max(ll)
    w = [p * math.exp(v - top) for p, v in zip(prior, ll, strict=True)]
    total = sum(w)
    return tuple(v / total for v in w)


def stationary(levels: tuple[Level, ...], T_s: float | None = None) -> tuple[float, ...]:
    """The chain's stationary law for fixes every ``T_s``: π_j ∝ 1 / (1 − exp(−T/D_j)) (balance of
    uniform departures); ``None``: its limit for short intervals, π_j ∝ D_j (the initial state)."""
    w = [lv.dwell_s if T_s is None else 1.0 / (1.0 - math.exp(-T_s / lv.dwell_s)) for lv in levels]
    total = sum(w)
    return tuple(v / total for v in w)


def relaxation_factor(levels: tuple[Level, ...], T_s: float) -> float:
    """Per-step contraction toward the stationary law when all levels share one dwell time D:
    λ = 1 − L/(L − 1) · (1 − exp(−T/D)) (the second eigenvalue of A)."""
    d = {lv.dwell_s for lv in levels}
    if len(d) != 1:
        raise ValueError("relaxation_factor: defined here for one shared dwell time")
    n = len(levels)
    return 1.0 - n / (n - 1) * (1.0 - math.exp(-T_s / d.pop()))


@register("hmm-trust")
class HmmTrust:
    learns_from_rejected = True  # a gated-out fix is evidence about the trust level too

    def __init__(self, cfg: EstimatorConfig, context: MethodContext | None = None) -> None:
        self.cfg = cfg
        self.plugin = plugin = (context or MethodContext()).plugin
        self.levels = levels_of(self.cfg, plugin)
        self.chains = SPLIT_AXES if plugin.hmm_split_vertical else (ALL_AXES,)

    def initial_state(self) -> State:
        return tuple(stationary(self.levels) for _ in self.chains)

    def beta(self, state: State) -> float:
        """The first chain's (all axes, or horizontal) posterior mean trust."""
        return sum(p * lv.beta for p, lv in zip(state[0], self.levels, strict=True))

    def measurement_cov(self, state: State, terms: InnovationTerms) -> Vec3:
        r = list(terms.r_nominal)
        for pi, axes in zip(self.update(state, terms), self.chains, strict=True):
            k = sum(p * lv.r_factor for p, lv in zip(pi, self.levels, strict=True))
            for i in axes:
                r[i] *= k
        return (r[0], r[1], r[2])

    def update(self, state: State, terms: InnovationTerms) -> State:
        return tuple(posterior(pi, terms, self.levels, self.cfg, axes)
                     for pi, axes in zip(state, self.chains, strict=True))
