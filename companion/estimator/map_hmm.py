"""``map-hmm``: the map's clearance as the prior of a two-level trust HMM, innovations as evidence.

``map-beta`` uses only the map; ``hmm-trust`` only the innovations. This rule combines them. The
GNSS is *clean* (trust β_c = ``map_beta_open``) or *degraded* (β_d = ``map_beta_canyon``), each
with the trust model's σ_b(β) and R(β). The map says how likely each is at a place: the prior
probability of *degraded* is ε + (1 − 2ε) w(d), with the map schedule's weight w(d) = clip((d_near − d)
/ ramp, 0, 1) at the clearance d of the filter's latest posterior position (``map_beta``'s reader,
one fix behind) and ε = ``mhmm_prior_floor``: the map is never certain, so evidence can always
overrule it.
Per fix, over the interval T since the last one:

1. predict: the level is kept with probability e = exp(−T / D) (``mhmm_dwell_s``) and otherwise
   re-drawn from the map's prior at the current place: π⁻ = e π + (1 − e) (1 − w, w);
2. update with the innovation likelihoods, tempered by κ (``mhmm_evidence``, 0–1):
   π⁺_j ∝ π⁻_j N(y; 0, S_j)^κ, S_j = s0 + (1 − α(T)²) σ_b(β_j)² + r(β_j) R_nom per NED axis.
   κ < 1 is a power likelihood: it counts each fix as κ of an independent observation, because
   the innovations of a 3-10 s multipath bias are correlated over many fixes;
3. β = π⁺_c β_c + π⁺_d β_d, fused with R(β) and σ_b(β) as every belief method.

κ = 0 and ε = 0 is ``map-beta`` with its β smoothed over D (after a time ≫ D at one place, β = the
schedule's β(d) exactly; tested); κ = 1 is ``hmm-trust``'s two-level chain with the map's prior in
place of uniform jumps. Recovery is bounded: after the prediction each level keeps at least
(1 − e) × its map prior, at least (1 − e) ε. The map is required (``MethodContext.clearance_m``;
without one, building the method is a ``ConfigError``). State: the posterior (π_c, π_d), immutable.
"""

from __future__ import annotations

import math

from companion.estimator.belief import InnovationTerms, Vec3
from companion.estimator.config import EstimatorConfig
from companion.estimator.hmm_trust import ALL_AXES, Level, interval_s, log_likelihoods
from companion.estimator.map_beta import canyon_weight
from companion.estimator.methods import MethodContext, register
from companion.estimator.plugin_config import PluginConfig

State = tuple[float, float]  # posterior (clean, degraded)


def map_levels(cfg: EstimatorConfig, plugin: PluginConfig) -> tuple[Level, Level]:
    """(clean, degraded) at the map schedule's open-sky and canyon trust."""
    return tuple(Level(b, cfg.sigma_bias_m(b), cfg.r_factor(b), plugin.mhmm_dwell_s)  # type: ignore[return-value]
                 for b in (plugin.map_beta_open, plugin.map_beta_canyon))


def map_posterior(pi: State, prior_degraded: float, terms: InnovationTerms, levels: tuple[Level, Level],
                  cfg: EstimatorConfig, evidence: float) -> State:
    """π⁺ after one fix: the map-prior prediction over the fix's interval, then the tempered Bayes
    update (in logs: a level the prediction left at probability 0 stays there, nothing divides by 0)."""
    e = math.exp(-interval_s(terms, cfg) / levels[0].dwell_s)
    pc = e * pi[0] + (1.0 - e) * (1.0 - prior_degraded)
    pd = e * pi[1] + (1.0 - e) * prior_degraded
    if evidence == 0.0 or pc <= 0.0 or pd <= 0.0:
        return (pc / (pc + pd), pd / (pc + pd))
    lc, ld = log_likelihoods(terms, levels, ALL_AXES)
    a, b = math.log(pc) + evidence * lc, math.log(pd) + evidence * ld
    top = max(a, b)
    wc, wd = math.exp(a - top), math.exp(b - top)
    return (wc / (wc + wd), wd / (wc + wd))


@register("map-hmm")
class MapHmm:
    learns_from_rejected = True  # a gated-out fix is evidence about the trust level too

    def __init__(self, cfg: EstimatorConfig, context: MethodContext | None = None) -> None:
        context = context or MethodContext()
        self.cfg = cfg
        self.plugin = context.plugin
        self.levels = map_levels(cfg, context.plugin)
        self._clearance = context.require_map("map-hmm")
        self._position = context.posterior

    def _prior_degraded(self) -> float:
        x = self._position()
        eps = self.plugin.mhmm_prior_floor
        w = canyon_weight(self.plugin, float(self._clearance(float(x[0]), float(x[1]))))
        return eps + (1.0 - 2.0 * eps) * w

    def initial_state(self) -> State:
        return (1.0, 0.0)  # no position before the first fix: open sky

    def beta(self, state: State) -> float:
        return state[0] * self.levels[0].beta + state[1] * self.levels[1].beta

    def measurement_cov(self, state: State, terms: InnovationTerms) -> Vec3:
        f = self.cfg.r_factor(self.beta(self.update(state, terms)))
        return (f * terms.r_nominal[0], f * terms.r_nominal[1], f * terms.r_nominal[2])

    def update(self, state: State, terms: InnovationTerms) -> State:
        return map_posterior(state, self._prior_degraded(), terms, self.levels, self.cfg,
                             self.plugin.mhmm_evidence)
