"""The mission file's sections as frozen dataclasses: the ONE place where their values live.

Each field carries its unit in its name; a mission YAML overrides only what it changes.
Range checks live in ``validate`` (``schema.build`` prefixes the field path to the message);
checks that need several sections (a start point against the buildings) live in the loader.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field


@dataclass(frozen=True)
class Home:
    """Geodetic origin of the local NED frame (WGS-84)."""

    lat_deg: float
    lon_deg: float
    alt_m: float  # ellipsoidal height of the home point

    def validate(self) -> None:
        if not -90.0 <= self.lat_deg <= 90.0:
            raise ValueError(f"lat_deg: must be in [-90, 90], got {self.lat_deg}")
        if not -180.0 <= self.lon_deg <= 180.0:
            raise ValueError(f"lon_deg: must be in [-180, 180], got {self.lon_deg}")


MAX_GRID_CELLS = 4_000_000  # occupancy-grid cells (4 km x 4 km at 2 m): grids, EDT and A* take seconds
MAX_BUILDINGS = 10_000


def _check_rect(north_min_m: float, east_min_m: float, north_max_m: float, east_max_m: float) -> None:
    if north_max_m <= north_min_m:
        raise ValueError(f"north_max_m ({north_max_m}) must be > north_min_m ({north_min_m})")
    if east_max_m <= east_min_m:
        raise ValueError(f"east_max_m ({east_max_m}) must be > east_min_m ({east_min_m})")


@dataclass(frozen=True)
class Bounds:
    """The mapped area, an axis-aligned rectangle in local north/east metres."""

    north_min_m: float
    east_min_m: float
    north_max_m: float
    east_max_m: float

    def validate(self) -> None:
        _check_rect(self.north_min_m, self.east_min_m, self.north_max_m, self.east_max_m)

    def contains(self, north_m: float, east_m: float) -> bool:
        return (self.north_min_m <= north_m <= self.north_max_m
                and self.east_min_m <= east_m <= self.east_max_m)


@dataclass(frozen=True)
class Building:
    """An axis-aligned rectangular building footprint (local north/east metres)."""

    north_min_m: float
    east_min_m: float
    north_max_m: float
    east_max_m: float
    # Roof height above home. The world is 2-D (the paper's occupancy grid), so every
    # building must be taller than the flight altitude; the height is kept for figures.
    height_m: float = 40.0

    def validate(self) -> None:
        _check_rect(self.north_min_m, self.east_min_m, self.north_max_m, self.east_max_m)
        if self.height_m <= 0:
            raise ValueError(f"height_m: must be > 0, got {self.height_m}")


@dataclass(frozen=True)
class WorldConfig:
    """The city: bounds, buildings and the planner's occupancy-grid resolution."""

    bounds: Bounds
    buildings: tuple[Building, ...]
    resolution_m: float = 2.0  # occupancy-grid cell size

    def validate(self) -> None:
        if self.resolution_m <= 0:
            raise ValueError(f"resolution_m: must be > 0, got {self.resolution_m}")
        b = self.bounds
        span_m = min(b.north_max_m - b.north_min_m, b.east_max_m - b.east_min_m)
        if self.resolution_m > span_m:
            raise ValueError(f"resolution_m ({self.resolution_m}) exceeds the bounds' size ({span_m})")
        cells = math.ceil((b.north_max_m - b.north_min_m) / self.resolution_m) * math.ceil(
            (b.east_max_m - b.east_min_m) / self.resolution_m)
        if cells > MAX_GRID_CELLS:
            raise ValueError(f"the map needs {cells:,} grid cells at resolution_m {self.resolution_m:g}; "
                             f"the limit is {MAX_GRID_CELLS:,} (shrink bounds or coarsen resolution_m)")
        if len(self.buildings) > MAX_BUILDINGS:
            raise ValueError(f"{len(self.buildings):,} buildings; the limit is {MAX_BUILDINGS:,}")
        for k, bld in enumerate(self.buildings):
            inside = (b.north_min_m <= bld.north_min_m and bld.north_max_m <= b.north_max_m
                      and b.east_min_m <= bld.east_min_m and bld.east_max_m <= b.east_max_m)
            if not inside:
                raise ValueError(f"buildings[{k}]: extends outside bounds")


@dataclass(frozen=True)
class FlightConfig:
    """Flight altitude and the reference trajectory's limits."""

    altitude_m: float = 20.0  # height above home; the route flies at p_d = -altitude_m
    speed_max_m_s: float = 4.0  # peak speed of each minimum-jerk segment
    acc_max_m_s2: float = 1.5  # peak acceleration of each minimum-jerk segment
    # the slowest a segment is flown where its clearance is below planner.expected_error_m (the peak
    # speed falls in proportion to clearance / expected error, not below this); unused when that is 0
    speed_min_m_s: float = 1.0

    def validate(self) -> None:
        for name in ("altitude_m", "speed_max_m_s", "acc_max_m_s2", "speed_min_m_s"):
            value = getattr(self, name)
            if value <= 0:
                raise ValueError(f"{name}: must be > 0, got {value}")
        if self.speed_min_m_s > self.speed_max_m_s:
            raise ValueError(f"speed_min_m_s ({self.speed_min_m_s}) must be <= "
                             f"speed_max_m_s ({self.speed_max_m_s})")


@dataclass(frozen=True)
class PlannerConfig:
    """Modified A* (eq. 2-3) weights and the clearance rules.

    Increment for a move of length L_m into cell n with heading change Δψ:
    ``w_tra·L_m + w_turn_m_rad·Δψ + w_clr·L_m·max(0, 1 - d_obs(n)/clearance_cost_range_m)``,
    heuristic ``w_tra·‖p_n - p_goal‖`` (admissible, consistent).
    """

    w_tra: float = 1.0  # weight of the traversal cost (metres travelled)
    w_turn_m_rad: float = 2.0  # cost of turning, metres-equivalent per radian of heading change
    w_clr: float = 3.0  # weight of the clearance cost (per metre travelled at zero clearance)
    clearance_cost_range_m: float = 10.0  # clearance beyond which the clearance cost vanishes
    clearance_margin_m: float = 4.0  # cells with EDT clearance d_obs below this are blocked
    los_margin_m: float = 3.0  # line-of-sight pruning keeps segments at least this clear (exact)
    # The horizontal navigation error the route is flown for (e.g. the companion's typical reported
    # accuracy in the scenario); 0: off. When set, each pruned segment's peak speed is scaled by its
    # exact clearance / this error (at most flight.speed_max_m_s, at least flight.speed_min_m_s). The
    # path itself (A*, margins) is unchanged: reaching the clearance cost out to the error made routes
    # weave into crossings (the default city's profile 3 at 16 m: three waypoints, 5.3 m from a wall,
    # instead of its straight street's 8.0 m).
    expected_error_m: float = 0.0

    def validate(self) -> None:
        if self.w_tra <= 0:
            raise ValueError(f"w_tra: must be > 0, got {self.w_tra}")
        for name in ("w_turn_m_rad", "w_clr"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name}: must be >= 0, got {getattr(self, name)}")
        for name in ("clearance_cost_range_m", "clearance_margin_m", "los_margin_m"):
            if getattr(self, name) <= 0:
                raise ValueError(f"{name}: must be > 0, got {getattr(self, name)}")
        if not self.expected_error_m >= 0.0:
            raise ValueError(f"expected_error_m: must be >= 0, got {self.expected_error_m}")
        if self.los_margin_m > self.clearance_margin_m:
            raise ValueError(f"los_margin_m ({self.los_margin_m}) must be <= "
                             f"clearance_margin_m ({self.clearance_margin_m})")


@dataclass(frozen=True)
class Profile:
    """One evaluation mission: start and goal in local north/east metres."""

    start_ne_m: tuple[float, float]
    goal_ne_m: tuple[float, float]
    name: str = ""

    def validate(self) -> None:
        if math.dist(self.start_ne_m, self.goal_ne_m) == 0.0:
            raise ValueError("start_ne_m and goal_ne_m coincide")


# Sections kept as raw mappings for their owners to validate (``Mission.section(name)``).
OVERRIDE_SECTIONS: tuple[str, ...] = (
    "vehicle", "autopilot", "imu", "gnss", "estimator", "ahrs", "belief_plugins", "receiver",
)



@dataclass(frozen=True)
class MissionFile:
    """The whole mission file; unknown top-level keys are refused."""

    name: str
    home: Home
    world: WorldConfig
    profiles: tuple[Profile, ...]
    flight: FlightConfig = field(default_factory=FlightConfig)
    planner: PlannerConfig = field(default_factory=PlannerConfig)
    scenario: str = "paper"  # sensor realism, one of SCENARIOS (paper = the paper's idealised sensors)
