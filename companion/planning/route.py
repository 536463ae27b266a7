"""The planner bridge core: A* on the mission's grid, line-of-sight pruning, minimum-jerk timing.

With the planner's ``expected_error_m`` set, each pruned segment's peak speed falls with its exact
clearance (``clearance_speed_m_s``); the path is the same.

The route is flat at ``p_d = -altitude_m`` (no take-off segment: the vehicle starts hovering
at the start point). Waypoints are the exact start, the pruned A* cell centres, and the exact
goal. Pure code, no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from companion.domain.samples import Setpoint
from companion.errors import UserError
from companion.mission.loader import Mission
from companion.mission.world import World
from companion.planning.astar import GridPath, astar
from companion.planning.minjerk import MinJerkTrajectory


class PlanningError(UserError):
    """No route exists for a mission profile (one line naming the mission and profile)."""


@dataclass(frozen=True)
class Route:
    """A planned route: waypoints (N, 3) in NED metres and its minimum-jerk reference."""

    profile_index: int
    grid_path: GridPath  # the unpruned A* result (cells, eq.-3 cost), for figures and tests
    trajectory: MinJerkTrajectory

    @property
    def waypoints_ned_m(self) -> np.ndarray:
        return self.trajectory.waypoints

    @property
    def duration_s(self) -> float:
        """Motion time from ``t_start_s`` to arrival at the goal."""
        return self.trajectory.duration_s

    @property
    def t_start_s(self) -> float:
        return self.trajectory.t_start_s

    @property
    def length_m(self) -> float:
        return float(np.linalg.norm(np.diff(self.waypoints_ned_m, axis=0), axis=1).sum())

    def reference(self, t_s: float | np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(p_ned_m, v_ned_m_s, a_ned_m_s2) at vehicle time ``t_s``; vectorised over (K,) times."""
        return self.trajectory.reference(t_s)

    def setpoint(self, t_us: int) -> Setpoint:
        p, v, a = self.reference(t_us * 1e-6)
        return Setpoint(t_us=int(t_us), p_ned_m=p, v_ned_m_s=v, a_ned_m_s2=a)


def plan_route(mission: Mission, profile_index: int, t_start_s: float = 0.0) -> Route:
    """Plan profile ``profile_index`` of ``mission``; raises PlanningError if no path exists."""
    if not 0 <= profile_index < len(mission.profiles):
        raise PlanningError(
            f"{mission.source}: no profile {profile_index} (the mission has {len(mission.profiles)})"
        )
    profile = mission.profiles[profile_index]
    world, planner = mission.world, mission.planner
    start_ne_m, goal_ne_m = np.array(profile.start_ne_m), np.array(profile.goal_ne_m)
    path = astar(world.blocked(planner.clearance_margin_m), world.edt_m,
                 world.cell_of(*start_ne_m), world.cell_of(*goal_ne_m), planner, world.resolution_m)
    if path is None:
        raise PlanningError(f"{mission.source}: profiles[{profile_index}]: no path from start to goal")
    points_ne_m = np.vstack([start_ne_m, world.cell_centre_ne_m(path.cells[1:-1]), goal_ne_m])
    pruned_ne_m = prune_line_of_sight(points_ne_m, world, planner.los_margin_m)
    waypoints = np.column_stack([pruned_ne_m, np.full(len(pruned_ne_m), -mission.altitude_m)])
    flight = mission.flight
    speed_m_s: float | np.ndarray = flight.speed_max_m_s
    if planner.expected_error_m > 0 and len(pruned_ne_m) > 1:
        clearance_m = np.array([float(world.segment_clearance_m(a, b))
                                for a, b in zip(pruned_ne_m[:-1], pruned_ne_m[1:], strict=True)])
        speed_m_s = clearance_speed_m_s(clearance_m, planner.expected_error_m, flight.speed_max_m_s,
                                        flight.speed_min_m_s)
    trajectory = MinJerkTrajectory.through(waypoints, speed_m_s, flight.acc_max_m_s2, t_start_s)
    return Route(profile_index, path, trajectory)


def clearance_speed_m_s(clearance_m: np.ndarray, expected_error_m: float, speed_max_m_s: float,
                        speed_min_m_s: float) -> np.ndarray:
    """Peak speed of each segment from its clearance: ``speed_max · clearance / expected_error``,
    within [``speed_min_m_s``, ``speed_max_m_s``] (full speed where the clearance exceeds the
    expected error; an error of 0 means no limit)."""
    clearance_m = np.asarray(clearance_m, dtype=float)
    if expected_error_m <= 0:
        return np.full(clearance_m.shape, float(speed_max_m_s))
    return np.clip(speed_max_m_s * clearance_m / expected_error_m, speed_min_m_s, speed_max_m_s)


def prune_line_of_sight(points_ne_m: np.ndarray, world: World, margin_m: float) -> np.ndarray:
    """Keep the fewest points: from each kept point jump to the last one of the run of points
    reachable in a straight line at least ``margin_m`` (exact) from every building.

    If not even the next point is reachable that way (a grid step hugging the margin), the
    next point is kept anyway: the grid path itself respects the planner's cell margin.
    Coincident consecutive points are dropped.
    """
    kept = [0]
    while kept[-1] < len(points_ne_m) - 1:
        i = kept[-1]
        clear = np.atleast_1d(world.segment_clearance_m(points_ne_m[i], points_ne_m[i + 1:])) >= margin_m
        run = len(clear) if clear.all() else int(np.argmin(clear))
        kept.append(i + max(run, 1))
    out = points_ne_m[kept]
    keep = np.r_[True, np.linalg.norm(np.diff(out, axis=0), axis=1) > 0]
    return out[keep]
