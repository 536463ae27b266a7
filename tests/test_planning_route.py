"""plan_route on the shipped cities: every profile plans, pruned segments stay clear, reference holds."""

import dataclasses

import numpy as np
import pytest

from companion.domain.samples import Setpoint
from companion.mission import Bounds, Building, World, WorldConfig, load_mission
from companion.planning import PlanningError, plan_route, prune_line_of_sight
from companion.planning.route import clearance_speed_m_s

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


def test_clearance_speed_known_answers():
    clearance_m = np.array([0.0, 3.0, 6.0, 9.0, 12.0, 30.0])
    np.testing.assert_allclose(clearance_speed_m_s(clearance_m, 12.0, 4.0, 1.0),
                               [1.0, 1.0, 2.0, 3.0, 4.0, 4.0])
    np.testing.assert_array_equal(clearance_speed_m_s(clearance_m, 0.0, 4.0, 1.0), np.full(6, 4.0))


def _planned_for(error_m):
    planner = dataclasses.replace(DEFAULT.planner, expected_error_m=error_m)
    return dataclasses.replace(DEFAULT, planner=planner)


def test_expected_error_slows_the_segments_narrower_than_it(routes):
    # profile 3: one straight east-west street 16 m wide (8 m from both walls), 280 m
    assert len(routes[3].waypoints_ned_m) == 2
    peak = {}
    for error_m in (0.0, 8.0, 16.0, 32.0):
        route = plan_route(_planned_for(error_m), 3)
        np.testing.assert_array_equal(route.waypoints_ned_m, routes[3].waypoints_ned_m)
        _, v, _ = route.reference(np.linspace(0.0, route.duration_s, 20001))
        peak[error_m] = np.linalg.norm(v, axis=1).max()
    # within the street's clearance: full speed, the same trajectory; beyond: 4 m/s x 8 / error, >= 1 m/s
    assert peak[0.0] == pytest.approx(4.0, rel=1e-6) and peak[8.0] == peak[0.0]
    assert peak[16.0] == pytest.approx(2.0, rel=1e-6)
    assert peak[32.0] == pytest.approx(1.0, rel=1e-6)
    assert plan_route(_planned_for(16.0), 3).duration_s == pytest.approx(2.0 * routes[3].duration_s)


def test_no_expected_error_leaves_every_route_as_it_was(routes):
    for k in (0, 1, 5):
        route = plan_route(_planned_for(0.0), k)
        np.testing.assert_array_equal(route.trajectory.durations_s, routes[k].trajectory.durations_s)
        np.testing.assert_array_equal(route.waypoints_ned_m, routes[k].waypoints_ned_m)
