"""Mission and map schema shared by the vehicle and the planner (one loader, imported by both)."""

from companion.mission.config import (
    OVERRIDE_SECTIONS,
    Bounds,
    Building,
    FlightConfig,
    Home,
    PlannerConfig,
    Profile,
    WorldConfig,
)
from companion.mission.loader import BUILTIN_MISSIONS, Mission, build_mission, load_mission, with_scenario
from companion.mission.scenarios import SCENARIOS
from companion.mission.schema import ConfigError, build, load_yaml
from companion.mission.world import World

__all__ = [
    "BUILTIN_MISSIONS",
    "OVERRIDE_SECTIONS",
    "Bounds",
    "Building",
    "ConfigError",
    "FlightConfig",
    "Home",
    "Mission",
    "SCENARIOS",
    "PlannerConfig",
    "Profile",
    "World",
    "WorldConfig",
    "build",
    "build_mission",
    "load_mission",
    "load_yaml",
    "with_scenario",
]
