"""The belief-adaptive EKF (eq. 12-21, Algorithm 1): numpy and a small C core, no I/O.

    from companion.estimator import EstimatorConfig, Navigator, METHODS
    nav = Navigator(EstimatorConfig(), method="second-order", frame=None)

Modules: ``config`` (parameters), ``model`` (the linear 15-state model), ``history`` (held IMU
inputs with prefix integrals), ``belief`` (loss and ∂ℓ/∂β), ``methods`` (adaptation strategies
and their registry), ``engine`` (filter + out-of-sequence fusion), ``navigator`` (front end);
``_core`` (C, ``_core.c``, built by ``make venv``): the numeric hot path of ``history`` and
``model``. Nothing here reads missions, YAML, MAVLink or Zenoh (an import-linter contract):
``companion.wiring.navigator_for`` assembles a navigator from a mission.
"""

import importlib

from companion.estimator.config import EstimatorConfig
from companion.estimator.methods import DEFAULT_METHOD, REGISTRY, MethodContext, check_method, register
from companion.estimator.navigator import Navigator

# Modules that register extra adaptation methods (see ``methods``' docstring), by name.
PLUGINS: tuple[str, ...] = ("vbakf", "fixed_beta", "map_beta", "windowed_ml", "hmm_trust", "map_hmm")
for _plugin in PLUGINS:
    importlib.import_module(f"companion.estimator.{_plugin}")

METHODS: tuple[str, ...] = tuple(REGISTRY)

__all__ = ["DEFAULT_METHOD", "METHODS", "EstimatorConfig", "MethodContext", "Navigator", "check_method",
           "register"]
