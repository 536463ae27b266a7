"""A small mission fixture for the vehicle tests (same attributes as ``companion.mission.Mission``).

Buildings are axis-aligned rectangles; ``clearance_m`` is the exact Euclidean distance to the
nearest one (0 inside), as the mission contract specifies.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from companion.domain.geodesy import LocalNedFrame
from companion.mission.scenarios import scenario_sections


@dataclass(frozen=True)
class RectWorld:
    buildings: tuple[tuple[float, float, float, float], ...] = ()  # (n_min, e_min, n_max, e_max) m

    def clearance_m(self, north_m: float, east_m: float) -> float:
        best = math.inf
        for n0, e0, n1, e1 in self.buildings:
            dn = max(n0 - north_m, 0.0, north_m - n1)
            de = max(e0 - east_m, 0.0, east_m - e1)
            best = min(best, math.hypot(dn, de))
        return best

    def collides(self, north_m: float, east_m: float) -> bool:
        return self.clearance_m(north_m, east_m) <= 0.0


@dataclass(frozen=True)
class Profile:
    start_ne_m: tuple[float, float]
    goal_ne_m: tuple[float, float]


@dataclass(frozen=True)
class FixtureMission:
    world: RectWorld = field(default_factory=RectWorld)
    profiles: tuple[Profile, ...] = (Profile((0.0, 0.0), (60.0, 0.0)),)
    altitude_m: float = 30.0
    name: str = "fixture"
    frame: LocalNedFrame = LocalNedFrame(47.3769, 8.5417, 408.0)
    sections: dict[str, Any] = field(default_factory=dict)

    scenario: str = "paper"

    def section(self, name: str) -> Any:
        return self.sections.get(name, {})

    def settings(self, name: str) -> Any:
        """As ``Mission.settings``: the scenario's fields under the fixture's own section."""
        own = self.section(name)
        if not isinstance(own, dict):
            return own  # left to the config builder's one-line error (a mission file is checked at load)
        return {**scenario_sections(self.scenario).get(name, {}), **own}
