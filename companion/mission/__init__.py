"""Mission and map schema shared by the vehicle and the planner (one loader, imported by both)."""

from companion.mission.schema import ConfigError, build, load_yaml

__all__ = ["ConfigError", "build", "load_yaml"]
