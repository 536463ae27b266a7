"""``map-beta``: β scheduled from the map's clearance at the estimated position (an ablation row).

A vehicle that plans on a map knows where the street canyons are; this asks how much of the
belief methods' gain that alone buys. β(d) = β_open + (β_canyon − β_open) · clip((d_near − d) /
ramp, 0, 1) (``PluginConfig``), with d the exact clearance (``World.clearance_m``) of the filter's
latest posterior position; R(β) and Q_b(β) as for the belief methods.

The state is the β in force (a float). At each fix the NEW β is computed from the posterior of
the previous fix (one fix, 50 ms, behind the fix being fused): the engine hands an adaptation
method no position, so its ``MethodContext`` carries a reader of the engine's latest fusion. That
reader sees the history the out-of-sequence buffer rolled back to, so re-fusion reproduces in-order
results. The map (``MethodContext.clearance_m``) is required: without one (e.g. ``replay`` of a
foreign log without ``--mission``) building the method is a one-line ``ConfigError``, never a
silent "open sky everywhere".
"""

from __future__ import annotations

from companion.estimator.belief import InnovationTerms, Vec3
from companion.estimator.config import EstimatorConfig
from companion.estimator.methods import MethodContext, register
from companion.estimator.plugin_config import PluginConfig


def canyon_weight(cfg: PluginConfig, clearance_m: float) -> float:
    """w(d) = clip((d_near − d) / ramp, 0, 1): 0 in open sky, 1 deep in a street canyon."""
    return min(1.0, max(0.0, (cfg.map_d_near_m - clearance_m) / cfg.map_ramp_m))


def scheduled_beta(cfg: PluginConfig, clearance_m: float) -> float:
    """β(d) of the schedule."""
    return cfg.map_beta_open + (cfg.map_beta_canyon - cfg.map_beta_open) * canyon_weight(cfg, clearance_m)


@register("map-beta")
class MapBeta:
    learns_from_rejected = True  # β follows the position whether or not the fix passed the gate

    def __init__(self, cfg: EstimatorConfig, context: MethodContext | None = None) -> None:
        context = context or MethodContext()
        self.cfg = cfg
        self.plugin = context.plugin
        self._clearance = context.require_map("map-beta")
        self._position = context.posterior

    def _beta_here(self) -> float:
        x = self._position()
        return scheduled_beta(self.plugin, float(self._clearance(float(x[0]), float(x[1]))))

    def initial_state(self) -> float:
        return self.plugin.map_beta_open  # no position before the first fix

    def beta(self, state: float) -> float:
        return state

    def measurement_cov(self, state: float, terms: InnovationTerms) -> Vec3:
        f = self.cfg.r_factor(state)
        return (f * terms.r_nominal[0], f * terms.r_nominal[1], f * terms.r_nominal[2])

    def update(self, state: float, terms: InnovationTerms) -> float:
        return self._beta_here()
