"""The one place a ``Navigator`` is assembled from a mission: every flight, node, replay and bench calls it.

``companion.estimator`` knows no missions (it is pure numerics); this module reads the mission's
sections and hands the estimator what it needs at construction, as navlie's filters get their
models handed in:

* ``mission_estimator_config(mission)``: ``EstimatorConfig`` defaults, then the mission's scenario's
  estimator settings, then the mission's own ``estimator:`` section;
* ``mission_plugin_config(mission)``: ``PluginConfig`` defaults, then ``belief_plugins:``;
* ``navigator_for(mission, method, config=, frame=)``: the navigator with both, the mission's map
  (``World.clearance_m``, which ``map-beta`` and ``map-hmm`` need) and its home as the frame.

* ``mission_clearance(mission, frame)``: the map's clearance (distance to the nearest building) in ``frame``;
* ``mission_city(mission)``: the map's buildings as boxes (``companion.mission.city3d.City``);
* ``tight_navigator_for(mission, method, config=, frame=, city=)``: the tightly coupled navigator with
  the map's line of sight as the per-satellite belief's prior (``city``: another map, e.g. an
  imperfect one; the mission's by default; None for a mission without one).

A ``frame`` other than the mission's (e.g. the companion's ``--home`` beside an autopilot) gets the
map moved into it (``City.shifted``, a translated clearance): positions are the navigator's.

Without a mission (a foreign log, an autopilot we do not plan for) there is no map: ``map-beta`` and
``map-hmm`` then refuse to start with a one-line ``ConfigError``.
"""

from __future__ import annotations

import numpy as np

from companion.domain.geodesy import LocalNedFrame
from companion.estimator import DEFAULT_METHOD, EstimatorConfig, MethodContext, Navigator, check_method
from companion.estimator.methods import Clearance
from companion.estimator.plugin_config import PluginConfig
from companion.gnss.ephemeris import EphemerisStore
from companion.mission import Mission, build
from companion.mission.city3d import City
from companion.tight import DEFAULT_WEIGHTING, TightConfig, TightNavigator, check_weighting

_MISSION_HOME = LocalNedFrame(0.0, 0.0, 0.0)  # sentinel: "the mission's home" (compared by identity)


def mission_estimator_config(mission: Mission) -> EstimatorConfig:
    """``EstimatorConfig`` defaults, then the mission's scenario's ``estimator`` settings (what the
    filter is told about the simulated IMU: ``companion.mission.scenarios``), then the mission's own
    ``estimator:`` section (fly, the SITL estimator node, ``replay --mission``: a replayed SITL log
    runs the filter the live one ran)."""
    return build(EstimatorConfig, mission.settings("estimator"), f"{mission.source}: estimator")


def mission_plugin_config(mission: Mission) -> PluginConfig:
    """``PluginConfig`` defaults overridden by the mission's ``belief_plugins:`` section."""
    return build(PluginConfig, mission.section("belief_plugins"), f"{mission.source}: belief_plugins")


def navigator_for(mission: Mission | None, method: str = DEFAULT_METHOD, *,
                  config: EstimatorConfig | None = None,
                  frame: LocalNedFrame | None = _MISSION_HOME) -> Navigator:
    """A ``Navigator`` running ``method`` (checked: one line naming the methods when unknown).

    ``mission``: the estimator config (unless ``config`` is given: e.g. ArduPilot's real sensors, not
    our simulated ones), the plugin parameters, the map, and the frame (unless ``frame`` is given).
    ``None``: ``config`` or the ``EstimatorConfig`` defaults, default plugin parameters, no map, and
    ``frame`` (default None = home at the first good fix).
    """
    check_method(method)
    if mission is None:
        context = MethodContext()
        home = None if frame is _MISSION_HOME else frame
    else:
        home = mission.frame if frame is _MISSION_HOME else frame
        context = MethodContext(plugin=mission_plugin_config(mission),
                                clearance_m=mission_clearance(mission, home))
        config = config if config is not None else mission_estimator_config(mission)
    return Navigator(config, method=method, frame=home, context=context)


def _origin_in_mission(mission: Mission, frame: LocalNedFrame | None) -> np.ndarray | None:
    """Where ``frame``'s origin lies in the mission's frame (NED); None for the mission's own frame (or
    None: home at the first fix, where the map is taken as the mission's)."""
    if frame is None or frame is mission.frame:
        return None
    o = mission.frame.to_ned_m(frame.home_lat_deg, frame.home_lon_deg, frame.home_alt_m)
    return None if not np.any(o) else o


def mission_clearance(mission: Mission, frame: LocalNedFrame | None) -> Clearance:
    """The mission's clearance map (``World.clearance_m``, vectorised) for positions in ``frame``."""
    o = _origin_in_mission(mission, frame)
    if o is None:
        return mission.world.clearance_m
    world, dn, de = mission.world, float(o[0]), float(o[1])
    return lambda north_m, east_m: world.clearance_m(np.add(north_m, dn), np.add(east_m, de))


def mission_city(mission: Mission) -> City:
    """The mission's buildings as boxes with their heights (the 3-D city the receiver sees)."""
    heights = [b.height_m for b in mission.world.config.buildings]
    return City(mission.world.rects_m, np.asarray(heights, dtype=float))


_MISSION_CITY = City(np.zeros((0, 4)), np.zeros(0))  # sentinel: "the mission's map" (compared by identity)


def tight_navigator_for(mission: Mission | None, method: str = DEFAULT_WEIGHTING, *,
                        config: TightConfig | None = None, frame: LocalNedFrame | None = _MISSION_HOME,
                        ephemerides: EphemerisStore | None = None,
                        city: City | None = _MISSION_CITY) -> TightNavigator:
    """A ``TightNavigator`` running ``method`` (checked) with ``config`` (default ``TightConfig()``).

    ``mission``: its home as the frame (unless ``frame`` is given) and its map's line of sight as the
    belief's prior (``city``: another map instead, or None for none). ``None``: no map, ``frame`` (default
    None = the first single-point solution)."""
    check_weighting(method)
    if mission is None:
        home = None if frame is _MISSION_HOME else frame
        los = None if city is _MISSION_CITY or city is None else city.line_of_sight_blocked
    else:
        home = mission.frame if frame is _MISSION_HOME else frame
        c = mission_city(mission) if city is _MISSION_CITY else city
        o = _origin_in_mission(mission, home)
        c = c if c is None or o is None else c.shifted(o)
        los = None if c is None else c.line_of_sight_blocked
    return TightNavigator(config, method, home, ephemerides, line_of_sight=los)
