"""``fixed-beta``: the belief filter with its adaptation switched off (an ablation row).

β is held at ``EstimatorConfig.beta_fixed`` and sets both R(β) = R_nom · r_inflation_max^(1−β) and
Q_b(β) exactly as the belief methods' β does; only the update rule differs. (``naive`` differs:
it fuses with R_nom whatever β.) So second-order minus fixed-beta measures what ADAPTING β buys.
"""

from __future__ import annotations

from companion.estimator.belief import InnovationTerms, Vec3
from companion.estimator.config import EstimatorConfig
from companion.estimator.methods import register


@register("fixed-beta")
class FixedBeta:
    def __init__(self, cfg: EstimatorConfig) -> None:
        self.cfg = cfg
        self._beta = cfg.beta_fixed
        self._factor = cfg.r_factor(cfg.beta_fixed)

    def initial_state(self) -> None:
        return None

    def beta(self, state: None) -> float:
        return self._beta

    def measurement_cov(self, state: None, terms: InnovationTerms) -> Vec3:
        f = self._factor
        return (f * terms.r_nominal[0], f * terms.r_nominal[1], f * terms.r_nominal[2])

    def update(self, state: None, terms: InnovationTerms) -> None:
        return None
