"""plan_route on the shipped cities: every profile plans, pruned segments stay clear, reference holds."""

import numpy as np
import pytest

from companion.domain.samples import Setpoint
from companion.mission import Bounds, Building, World, WorldConfig, load_mission
from companion.planning import PlanningError, plan_route, prune_line_of_sight

DEFAULT = load_mission("default")


@pytest.fixture(scope="module")
def routes():
    return [plan_route(DEFAULT, k) for k in range(len(DEFAULT.profiles))]


@pytest.mark.parametrize("k", range(10))
def test_every_default_profile_plans_a_clear_route(routes, k):
    route = routes[k]
    wp = route.waypoints_ned_m
    prof = DEFAULT.profiles[k]
    np.testing.assert_array_equal(wp[0, :2], prof.start_ne_m)
    np.testing.assert_array_equal(wp[-1, :2], prof.goal_ne_m)
    assert np.all(wp[:, 2] == -DEFAULT.altitude_m)
    # line-of-sight pruned path: every straight segment keeps the exact LOS margin
    seg_clear = DEFAULT.world.segment_clearance_m(wp[:-1, :2], wp[1:, :2])
    assert seg_clear.min() >= DEFAULT.planner.los_margin_m
    assert 150.0 <= route.length_m <= 400.0
    assert route.length_m <= route.grid_path.cost  # pruning only shortens the grid path


def test_profiles_mix_canyons_and_open_space(routes):
    """Some routes are mostly canyon (< 10 m from a wall), some spend a third of their time in the open."""
    canyon, open_sky = 0, 0
    for route in routes:
        p, _, _ = route.reference(np.linspace(0.0, route.duration_s, 400))
        d = DEFAULT.world.clearance_m(p[:, 0], p[:, 1])
        canyon += np.mean(d < 10.0) > 0.8
        open_sky += np.mean(d > 15.0) > 0.3
    assert canyon >= 5 and open_sky >= 3


def test_reference_and_setpoint_hold_start_and_goal():
    m = load_mission("test")
    route = plan_route(m, 1, t_start_s=3.0)
    p, v, _ = route.reference(np.array([0.0, 2.9, 3.0 + route.duration_s, 1e6]))
    np.testing.assert_array_equal(p[0], route.waypoints_ned_m[0])
    np.testing.assert_array_equal(p[1], route.waypoints_ned_m[0])
    np.testing.assert_allclose(p[2:], route.waypoints_ned_m[[-1, -1]], atol=1e-12)
    assert not v[[0, 1, 3]].any()
    sp = route.setpoint(5_000_000)
    assert isinstance(sp, Setpoint) and sp.t_us == 5_000_000
    ref = route.reference(5.0)
    for x, y in zip((sp.p_ned_m, sp.v_ned_m_s, sp.a_ned_m_s2), ref, strict=True):
        np.testing.assert_array_equal(x, y)
    assert np.linalg.norm(sp.v_ned_m_s) > 0  # moving two seconds after departure


def test_line_of_sight_pruning_on_known_geometry():
    world = World(WorldConfig(Bounds(0, 0, 50, 50), (Building(20, 20, 30, 30),), resolution_m=1.0))
    # an L around the building's south-east: the corner cannot be cut with a 3 m margin
    pts = np.array([[10.0, 10.0], [10.0, 20.0], [10.0, 40.0], [25.0, 40.0], [40.0, 40.0]])
    out = prune_line_of_sight(pts, world, 3.0)
    np.testing.assert_array_equal(out, pts[[0, 2, 4]])
    assert world.segment_clearance_m(out[:-1], out[1:]).min() >= 3.0
    # with a tiny margin the diagonal (10,10)->(40,40) still crosses the building: unchanged
    np.testing.assert_array_equal(prune_line_of_sight(pts, world, 0.1), pts[[0, 2, 4]])
    open_pts = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [3.0, 3.0]])
    np.testing.assert_array_equal(prune_line_of_sight(open_pts, world, 3.0), open_pts[[0, 3]])


def test_bad_profile_index_is_one_line():
    with pytest.raises(PlanningError, match=r"default.yaml: no profile 10 \(the mission has 10\)"):
        plan_route(DEFAULT, 10)
