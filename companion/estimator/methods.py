"""GNSS trust adaptation strategies, selectable by name (``naive``, ``adaptive``, ...).

A strategy is a small object following the ``Adaptation`` protocol. The filter asks it, at each
fix, for the belief β (which sets Q_b(β) over the interval just predicted) and for the
measurement covariance R to fuse with, then hands it the fix's ``InnovationTerms`` and gets a
NEW state back. States must be immutable values (tuples, frozen dataclasses, arrays never
written again): the out-of-sequence buffer keeps the state after every fix and rolls back to
it, so a strategy must never keep mutable history on ``self``.

Adding a method (e.g. a variational-Bayes adaptive KF) without touching this file: in its own
module ``companion/estimator/vb.py``::

    from companion.estimator.methods import register

    @register("variational-bayes")
    class VariationalBayes:
        def __init__(self, cfg, context): ...  # context (if needed): MethodContext (plugins, map, posterior)
        def initial_state(self): ...
        def beta(self, state): ...
        def measurement_cov(self, state, terms): ...
        def update(self, state, terms): ...

then add ``vb`` to ``PLUGINS`` in ``companion/estimator/__init__.py`` so it is imported and
appears in ``METHODS``; ``Navigator(cfg, method="variational-bayes")`` then works everywhere.

What a method needs beyond ``EstimatorConfig`` is handed in at construction, in a ``MethodContext``
(to a constructor with a ``context`` parameter; the methods that need nothing more take ``cfg`` alone):
the plugin parameters (``PluginConfig``, the mission's ``belief_plugins:`` section), the map (a
clearance function; ``companion.wiring.navigator_for`` passes the mission's) and a reader of the
filter's latest posterior state (set by ``FusionEngine``). Nothing is patched in afterwards.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple, Protocol

from companion.errors import ConfigError, not_one_of
from companion.estimator._core import belief_update as _belief_update
from companion.estimator._core import loss_grad as _loss_grad
from companion.estimator.belief import InnovationTerms, Vec3, loss_params, paper_loss_grad, sigmoid
from companion.estimator.config import EstimatorConfig
from companion.estimator.plugin_config import PluginConfig

DEFAULT_METHOD = "second-order"  # the paper's method: what every command and node runs unless told

Clearance = Callable[[float, float], Any]  # (north_m, east_m) -> distance to the nearest building (m)


def _no_posterior() -> Sequence[float]:
    raise ConfigError("this adaptation method reads the filter's posterior: build it through FusionEngine")


@dataclass(frozen=True)
class MethodContext:
    """What an adaptation method may need beyond ``EstimatorConfig``, handed in at construction."""

    plugin: PluginConfig = field(default_factory=PluginConfig)  # the ablation plugins' parameters
    clearance_m: Clearance | None = None  # the map (``World.clearance_m``); None: no map
    # the filter's latest posterior state x (``FusionEngine`` sets it: its newest fusion, which
    # out-of-sequence re-fusion rolls back with the rest of the history)
    posterior: Callable[[], Sequence[float]] = _no_posterior

    def require_map(self, method: str) -> Clearance:
        """The map, or a one-line error: a map method without a map must not fly "open sky everywhere"."""
        if self.clearance_m is None:
            raise ConfigError(f"estimator method {method!r} needs the mission's map: give a mission "
                              "(e.g. replay --mission NAME), or choose a method without a map")
        return self.clearance_m


class Adaptation(Protocol):
    """One GNSS trust adaptation rule. ``state`` values are immutable."""

    def initial_state(self) -> Any: ...

    def beta(self, state: Any) -> float:
        """Belief in [0, 1] in force until the next fix (sets σ_b(β) and is reported)."""
        ...

    def measurement_cov(self, state: Any, terms: InnovationTerms) -> Vec3:
        """R to fuse this fix with: per-axis variances (m², NED; R is diagonal)."""
        ...

    def update(self, state: Any, terms: InnovationTerms) -> Any:
        """The state after this fix."""
        ...

    # Optional class attribute ``learns_from_rejected: bool`` (default False): whether ``update``
    # is also called for a fix the innovation gate rejected (the filter state is not updated).


Factory = Callable[..., Adaptation]  # (cfg) or (cfg, context)
REGISTRY: dict[str, Factory] = {}


def register(name: str) -> Callable[[Factory], Any]:
    """Class decorator: make a strategy selectable as ``name``."""

    def deco(factory: Factory) -> Any:
        if name in REGISTRY:
            raise ValueError(f"adaptation method {name!r} registered twice")
        REGISTRY[name] = factory
        return factory

    return deco


def check_method(name: str, what: str = "--method") -> str:
    """``name`` if it is a registered method, else a one-line ``ConfigError`` naming every method and
    the nearest (``what``: where the name came from). The one check every command and node calls."""
    if name not in REGISTRY:
        raise not_one_of(what, name, tuple(REGISTRY))
    return name


def make(name: str, cfg: EstimatorConfig, context: MethodContext | None = None) -> Adaptation:
    """Build the strategy called ``name``; unknown names are a user error naming the choices. The
    context goes to the constructors that take one (a ``context`` parameter)."""
    factory = REGISTRY[check_method(name, "estimator: unknown method")]
    if "context" in inspect.signature(factory).parameters:
        return factory(cfg, context or MethodContext())
    return factory(cfg)


@register("naive")
class Naive:
    """Fixed R = R_nom and fixed Q (β held at ``beta_fixed``)."""

    def __init__(self, cfg: EstimatorConfig) -> None:
        self.cfg = cfg

    def initial_state(self) -> None:
        return None

    def beta(self, state: None) -> float:
        return self.cfg.beta_fixed

    def measurement_cov(self, state: None, terms: InnovationTerms) -> Vec3:
        return terms.r_nominal

    def update(self, state: None, terms: InnovationTerms) -> None:
        return None


@register("adaptive")
class InnovationAdaptive(Naive):
    """Innovation-based adaptive EKF (Mohamed & Schwarz 1999): R̂ = C_ν − H P⁻ Hᵀ.

    ``C_ν`` is the mean of y yᵀ over the last N innovations (the current one included). The
    filter's axes are independent and R is diagonal, so the diagonal of R̂ is estimated; each
    variance is floored at ``adaptive_r_floor`` × the smallest nominal variance, which keeps R̂
    positive definite. Until N innovations exist, R = R_nom. The state is the tuple of the last
    N innovations.
    """

    def __init__(self, cfg: EstimatorConfig) -> None:
        super().__init__(cfg)
        sigma_min_m = min(cfg.sigma_gnss_horizontal_m, cfg.sigma_gnss_vertical_m)
        self.floor_m2 = cfg.adaptive_r_floor * sigma_min_m**2

    def initial_state(self) -> tuple[Vec3, ...]:  # type: ignore[override]
        return ()

    def _window(self, state: tuple[Vec3, ...], y: Vec3) -> tuple[Vec3, ...]:
        return (*state, y)[-self.cfg.adaptive_window_fixes :]

    def measurement_cov(self, state: tuple[Vec3, ...], terms: InnovationTerms) -> Vec3:  # type: ignore[override]
        window = self._window(state, terms.y)
        n = len(window)
        if n < self.cfg.adaptive_window_fixes:
            return terms.r_nominal
        hph = terms.hph(self.cfg.sigma_bias_m(self.cfg.beta_fixed))
        c = [sum(y[i] * y[i] for y in window) / n for i in range(3)]
        return (max(c[0] - hph[0], self.floor_m2), max(c[1] - hph[1], self.floor_m2),
                max(c[2] - hph[2], self.floor_m2))

    def update(self, state: tuple[Vec3, ...], terms: InnovationTerms) -> tuple[Vec3, ...]:  # type: ignore[override]
        return self._window(state, terms.y)


class BeliefState(NamedTuple):
    theta: float  # belief logit (eq. 15)
    h_fast: float  # curvature accumulators (eq. 18)
    h_slow: float
    beta: float  # σ(θ), kept so it is computed once per fix


class _Belief:
    """Sigmoid belief β = σ(θ) driving R(β) and Q_b(β); subclasses choose the θ step."""

    learns_from_rejected = True  # a fix failing the innovation gate still updates β (engine.py)

    def __init__(self, cfg: EstimatorConfig) -> None:
        self.cfg = cfg
        self._loss_params = loss_params(cfg)  # belief.loss_grad's numbers, for the C core's

    def _state(self, theta: float, h_fast: float, h_slow: float) -> BeliefState:
        theta = min(self.cfg.theta_max, max(self.cfg.theta_min, theta))
        return BeliefState(theta, h_fast, h_slow, sigmoid(theta))

    def initial_state(self) -> BeliefState:
        return self._state(self.cfg.theta0, self.cfg.h_fast0, self.cfg.h_slow0)

    def beta(self, state: BeliefState) -> float:
        return state.beta

    def measurement_cov(self, state: BeliefState, terms: InnovationTerms) -> Vec3:
        f = self.cfg.r_factor(state.beta)
        return (f * terms.r_nominal[0], f * terms.r_nominal[1], f * terms.r_nominal[2])

    def grad_theta(self, state: BeliefState, terms: InnovationTerms) -> float:
        """∇θ ℓ = ∂ℓ/∂β · β(1 − β) (chain rule through eq. 15; ``belief.loss_grad``'s ∂ℓ/∂β, in C)."""
        beta = state.beta
        return _loss_grad(beta, terms, self._loss_params)[1] * beta * (1.0 - beta)

    def step(self, state: BeliefState, g: float) -> tuple[float, float, float]:
        """(θ, H_fast, H_slow) after a step along ∇θ ℓ = g."""
        raise NotImplementedError

    def update(self, state: BeliefState, terms: InnovationTerms) -> BeliefState:
        return self._state(*self.step(state, self.grad_theta(state, terms)))


@register("first-order")
class FirstOrder(_Belief):
    """Plain gradient step θ ← θ − η₁ ∇θ ℓ (the ablation baseline)."""

    def __init__(self, cfg: EstimatorConfig) -> None:
        super().__init__(cfg)
        self._step = (1.0, cfg.eta_first_order, cfg.theta_min, cfg.theta_max)

    def step(self, state: BeliefState, g: float) -> tuple[float, float, float]:
        return state.theta - self.cfg.eta_first_order * g, state.h_fast, state.h_slow

    def update(self, state: BeliefState, terms: InnovationTerms) -> BeliefState:
        """``_Belief.update`` with this step, in C (``_core.belief_update``: the same operations)."""
        return _belief_update(state, terms, self._loss_params, self._step)  # type: ignore[return-value]


@register("second-order")
class SecondOrder(_Belief):
    """Dual-timescale damped Newton step (eq. 18-21)."""

    def __init__(self, cfg: EstimatorConfig) -> None:
        super().__init__(cfg)
        self._step = (2.0, cfg.eta, cfg.theta_min, cfg.theta_max, cfg.alpha_fast, cfg.alpha_slow,
                      cfg.omega_fast, cfg.lambda_reg)

    def step(self, state: BeliefState, g: float) -> tuple[float, float, float]:
        c = self.cfg
        h_fast = c.alpha_fast * state.h_fast + g * g
        h_slow = c.alpha_slow * state.h_slow + g * g
        h = c.omega_fast * h_fast + (1.0 - c.omega_fast) * h_slow
        return state.theta - c.eta * g / (h + c.lambda_reg), h_fast, h_slow

    def update(self, state: BeliefState, terms: InnovationTerms) -> BeliefState:
        """``_Belief.update`` with this step, in C (``_core.belief_update``: the same operations)."""
        return _belief_update(state, terms, self._loss_params, self._step)  # type: ignore[return-value]


@register("paper-literal")
class PaperLiteral(SecondOrder):
    """FOR COMPARISON ONLY: eq. 16 and eq. 17 exactly as printed (loss without interior
    minimum, gradient sign flipped), with the second-order step. It drifts to β → 1 whatever
    the GNSS quality."""

    update = _Belief.update  # its own gradient, in Python

    def grad_theta(self, state: BeliefState, terms: InnovationTerms) -> float:
        beta = state.beta
        return -paper_loss_grad(beta, terms, self.cfg)[1] * beta * (1.0 - beta)
