"""The estimate constrained to the map's free space: truncated-Gaussian known answers, unchanged in
the open, found again from deep inside a block, and what the companion feeds with a mission."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import truncnorm

from companion.estimator.freespace import FreeSpaceConfig, constrain
from companion.mission.config import Bounds, Building, WorldConfig
from companion.mission.world import World

# one street running north between two blocks: east 0..16 free (a 16 m street), buildings beyond
STREET = World(WorldConfig(Bounds(-400, -400, 400, 400), (Building(-300, -300, 300, 0.0),
                                                           Building(-300, 16.0, 300, 300)), resolution_m=4.0))


def test_only_an_estimate_inside_a_building_is_moved_by_default():
    """Default ``when="inside"``: an estimate in the street stays where it is, however wide its σ; one
    inside a building gets the truncated mean (the same as ``when="near"`` gives it)."""
    in_street, inside = np.array([5.0, 3.0]), np.array([5.0, 20.0])
    var = np.array([100.0, 100.0])
    assert constrain(in_street, var, STREET.clearance_m) is None
    assert constrain(in_street, var, STREET.clearance_m, FreeSpaceConfig(when="near")) is not None
    c, c_near = (constrain(inside, var, STREET.clearance_m, cfg) for cfg in (FreeSpaceConfig(),
                                                                             FreeSpaceConfig(when="near")))
    assert c is not None and c_near is not None and np.array_equal(c.p_ne_m, c_near.p_ne_m)
    nearest = constrain(inside, var, STREET.clearance_m, FreeSpaceConfig(nearest=True))
    assert nearest is not None and 15.0 < nearest.p_ne_m[1] < 16.0  # the nearest free grid point


def test_open_space_and_far_buildings_leave_the_estimate_alone():
    # 8 m clear, σ 1 m
    assert constrain(np.array([0.0, 8.0]), np.array([1.0, 1.0]), STREET.clearance_m,
                     FreeSpaceConfig(when="near")) is None
    open_sky = World(WorldConfig(Bounds(0, 0, 10, 10), ()))
    assert constrain(np.array([5.0, 5.0]), np.array([400.0, 400.0]), open_sky.clearance_m) is None


@pytest.mark.parametrize(("east_m", "sigma_m"),
                         [(24.0, 10.0), (8.0, 10.0), (-3.0, 4.0), (14.0, 2.0), (30.0, 20.0)])
def test_the_truncated_gaussian_mean_and_variance_across_the_street(east_m, sigma_m):
    """Across the street the answer is the normal truncated to [0, 16] m: mean μ + σ (φ(α) − φ(β)) /
    (Φ(β) − Φ(α)) (scipy's truncnorm), along it unchanged; on the 33-point grid (spacing 0.22 σ: the
    street's edges are resolved to that) within 5 % of σ (measured: 3.4 % at worst)."""
    near = FreeSpaceConfig(when="near")  # the truncation wherever a building is within the grid
    c = constrain(np.array([5.0, east_m]), np.array([sigma_m**2, sigma_m**2]), STREET.clearance_m, near)
    assert c is not None
    a, b = (0.0 - east_m) / sigma_m, (16.0 - east_m) / sigma_m
    mean, var = truncnorm.stats(a, b, loc=east_m, scale=sigma_m, moments="mv")
    assert c.p_ne_m[1] == pytest.approx(float(mean), abs=0.05 * sigma_m)
    assert math.sqrt(c.var_ne_m2[1]) == pytest.approx(math.sqrt(float(var)), abs=0.05 * sigma_m)
    assert c.p_ne_m[0] == pytest.approx(5.0, abs=1e-9)
    assert c.var_ne_m2[0] == pytest.approx(sigma_m**2, rel=0.05)
    assert 0.0 < c.p_ne_m[1] < 16.0 and c.moved_m == pytest.approx(abs(c.p_ne_m[1] - east_m))
    # a fix 24 m east (8 m inside the building), σ 10 m: not on the wall, inside the street
    if east_m == 24.0:
        assert 9.0 < c.p_ne_m[1] < 12.5 and c.free_fraction < 0.5  # exact: 10.9 m, 5.1 m from the wall


def test_deep_inside_a_block_with_a_small_sigma_the_free_space_is_found_again():
    c = constrain(np.array([0.0, 40.0]), np.array([1.0, 1.0]), STREET.clearance_m)  # 24 m inside, σ 1 m
    assert c is not None and 0.0 < c.p_ne_m[1] < 16.0 and c.p_ne_m[1] > 12.0  # the near side of the street
    assert constrain(np.array([0.0, 250.0]), np.array([1.0, 1.0]), STREET.clearance_m,
                     FreeSpaceConfig(max_sigma_m=10.0)) is None  # 50 m to free space, σ up to 8 m: unchanged
    with pytest.raises(ValueError):
        FreeSpaceConfig(grid_points=2)
    with pytest.raises(ValueError):
        FreeSpaceConfig(when="always")
