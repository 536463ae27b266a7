"""Planner bridge core: modified A* (eq. 1-3), line-of-sight pruning, minimum-jerk reference (eq. 5)."""

from companion.planning.astar import GridPath, astar
from companion.planning.minjerk import MinJerkTrajectory, segment_duration_s
from companion.planning.route import PlanningError, Route, plan_route, prune_line_of_sight

__all__ = [
    "GridPath",
    "MinJerkTrajectory",
    "PlanningError",
    "Route",
    "astar",
    "plan_route",
    "prune_line_of_sight",
    "segment_duration_s",
]
