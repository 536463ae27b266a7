"""The mild city (packaged missions ``mild`` and ``mild-tuning``): the default city's streets with lower
roofs, for the simulated receiver (docs/tight.md, "A milder city"). Geometry only: milliseconds."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.mission import load_mission
from companion.wiring import mission_city

TOWER_M = 80.0  # the one building the mild city keeps at its default height


@pytest.fixture(scope="module")
def cities():
    return load_mission("default"), load_mission("mild")


def test_mild_city_is_the_default_city_with_the_roofs_above_the_vehicle_halved(cities):
    default, mild = cities
    alt = default.altitude_m
    assert mild.name == "mild-city" and mild.altitude_m == alt
    np.testing.assert_array_equal(mild.world.rects_m, default.world.rects_m)  # same streets
    assert mild.profiles == default.profiles
    assert load_mission("mild-tuning").profiles == load_mission("default-tuning").profiles
    h_def = np.array([b.height_m for b in default.world.config.buildings])
    h_mild = np.array([b.height_m for b in mild.world.config.buildings])
    tower = h_def == TOWER_M
    assert tower.sum() == 1 and h_mild[tower] == TOWER_M
    np.testing.assert_allclose(h_mild[~tower] - alt, (h_def[~tower] - alt) / 2.0)
    assert (h_mild > alt).all()  # the world stays 2-D: every roof above the flight


def test_a_known_ray_is_blocked_in_the_default_city_and_clear_in_the_mild_one(cities):
    """Mid-street in the 16 m street at east 54-70, north 90, 20 m up, looking east: the block east
    70-118 (north 64-110) rises 50 m above the vehicle in the default city (blocked below
    atan(50/8) = 81°), 25 m in the mild one (blocked below atan(25/8) = 72°)."""
    default, mild = cities
    p = np.array([[90.0, 62.0, -20.0]])
    az = np.array([math.pi / 2] * 4)
    el = np.radians([70.0, 75.0, 80.0, 82.0])
    np.testing.assert_array_equal(mission_city(default).line_of_sight_blocked(p, az, el)[0],
                                  [True, True, True, False])
    np.testing.assert_array_equal(mission_city(mild).line_of_sight_blocked(p, az, el)[0],
                                  [True, False, False, False])


def test_more_sky_in_line_of_sight_along_the_same_routes(cities):
    """Along the two canyon profiles' straight lines (every 5 m, at the flight altitude), over a sky
    grid (every 10° of azimuth, 15-85° of elevation): the mild city hides 39 % of the sky where the
    default city hides 55 %, and never a direction the default city leaves clear."""
    default, mild = cities
    az, el = np.meshgrid(np.radians(np.arange(0.0, 360.0, 10.0)), np.radians(np.arange(15.0, 90.0, 10.0)))
    az, el = az.ravel(), el.ravel()
    pts = []
    for k in (3, 4):
        a, b = (np.array(v, float) for v in (default.profiles[k].start_ne_m, default.profiles[k].goal_ne_m))
        for s in np.linspace(0.0, 1.0, int(np.hypot(*(b - a)) / 5.0) + 1):
            n, e = a + s * (b - a)
            if default.world.clearance_m(n, e) > 0.0:
                pts.append((n, e, -default.altitude_m))
    p = np.array(pts)
    hid_def = mission_city(default).line_of_sight_blocked(p, az, el)
    hid_mild = mission_city(mild).line_of_sight_blocked(p, az, el)
    assert not (hid_mild & ~hid_def).any()  # lower roofs hide nothing new
    assert hid_def.mean() == pytest.approx(0.550, abs=0.005)
    assert hid_mild.mean() == pytest.approx(0.395, abs=0.005)
