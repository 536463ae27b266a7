"""Hyper-parameters of the ablation plugins (``fixed-beta``, ``map-beta``, ``windowed-ml``).

They live in their own mission section ``belief_plugins:`` (``--set belief_plugins.FIELD=V``), so
the estimator's ``EstimatorConfig`` stays as it is. A plugin that needs them (or the mission's map)
receives them through ``bind(navigator, mission)``, which every wiring that builds a navigator
from a mission calls (fly / evaluate, the companion's estimator node).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from companion.mission import Mission, build


@dataclass(frozen=True)
class PluginConfig:
    # --- map-beta: β scheduled from the map's clearance d at the estimated position,
    # β(d) = beta_open + (beta_canyon − beta_open) · clip((d_near − d) / ramp, 0, 1)
    map_beta_open: float = 0.9  # belief in open sky
    map_beta_canyon: float = 0.2  # belief deep in a street canyon
    map_d_near_m: float = 15.0  # clearance below which the belief starts to drop
    map_ramp_m: float = 10.0  # the belief reaches beta_canyon at d_near − ramp
    # --- windowed-ml: β = argmin over a grid of the innovation NLL summed over the last N fixes
    window_fixes: int = 40  # N (2 s at 20 Hz)
    window_grid: int = 41  # β grid points in [window_beta_min, window_beta_max]
    window_beta_min: float = 0.0
    window_beta_max: float = 1.0
    window_gain: float = 0.5  # β ← β + gain · (β* − β) per fix (1 = jump to the window optimum)

    def validate(self) -> None:
        for name in ("map_beta_open", "map_beta_canyon", "window_beta_min", "window_beta_max"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name}: must be in [0, 1], got {getattr(self, name)!r}")
        if not (self.map_ramp_m > 0.0 and self.map_d_near_m >= 0.0):
            raise ValueError("map_ramp_m: must be > 0 and map_d_near_m >= 0")
        if self.window_fixes < 1 or self.window_grid < 2:
            raise ValueError("window_fixes: must be >= 1, window_grid >= 2")
        if self.window_beta_max <= self.window_beta_min:
            raise ValueError("window_beta_max: must exceed window_beta_min")
        if not 0.0 < self.window_gain <= 1.0:
            raise ValueError(f"window_gain: must be in (0, 1], got {self.window_gain!r}")


def mission_plugin_config(mission: Mission) -> PluginConfig:
    """``PluginConfig`` defaults overridden by the mission's ``belief_plugins:`` section."""
    return build(PluginConfig, mission.section("belief_plugins"), f"{mission.source}: belief_plugins")


def bind(navigator: Any, mission: Mission) -> Any:
    """Give the navigator's adaptation method the mission (map, plugin section) if it takes one."""
    method = navigator.engine.method
    if hasattr(method, "bind"):
        engine = navigator.engine
        method.bind(mission, mission_plugin_config(mission), lambda: engine.fusions[-1].x)
    return navigator
