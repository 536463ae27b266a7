"""World geometry: exact clearance on known geometry, exact segment distance, grid and EDT (eq. 1)."""

import math

import numpy as np
import pytest

from companion.mission import Bounds, Building, World, WorldConfig


def make_world(rects, size_m=60.0, resolution_m=1.0):
    return World(WorldConfig(
        bounds=Bounds(0.0, 0.0, size_m, size_m),
        buildings=tuple(Building(*r) for r in rects),
        resolution_m=resolution_m,
    ))


ONE = make_world([(10.0, 30.0, 20.0, 50.0)])


@pytest.mark.parametrize(
    ("n", "e", "expected"),
    [
        (0.0, 35.0, 10.0),  # below the south wall
        (15.0, 20.0, 10.0),  # west of the west wall
        (25.0, 52.0, math.hypot(5.0, 2.0)),  # off the north-east corner
        (7.0, 26.0, 5.0),  # off the south-west corner (3-4-5)
        (15.0, 40.0, 0.0),  # inside
        (10.0, 40.0, 0.0),  # on the wall
    ],
)
def test_clearance_is_exact_on_known_geometry(n, e, expected):
    assert ONE.clearance_m(n, e) == pytest.approx(expected, abs=1e-12)
    assert ONE.collides(n, e) == (expected == 0.0)


def test_clearance_is_vectorised_and_takes_the_nearest_building():
    w = make_world([(10.0, 30.0, 20.0, 50.0), (40.0, 0.0, 45.0, 5.0)])
    rng = np.random.default_rng(1)
    n, e = rng.uniform(-10, 70, (2, 7, 5))
    d = w.clearance_m(n, e)
    assert d.shape == (7, 5)
    loop = [w.clearance_m(float(a), float(b)) for a, b in zip(n.ravel(), e.ravel(), strict=True)]
    np.testing.assert_array_equal(d.ravel(), loop)
    assert w.clearance_m(42.0, 10.0) == pytest.approx(5.0)
    assert w.nearest_building(42.0, 10.0) == 1
    assert make_world([]).clearance_m(1.0, 2.0) == math.inf


def test_segment_clearance_is_exact():
    assert ONE.segment_clearance_m(np.array([0.0, 0.0]), np.array([0.0, 60.0])) == pytest.approx(10.0)
    assert ONE.segment_clearance_m(np.array([0.0, 35.0]), np.array([30.0, 35.0])) == 0.0  # crosses
    assert ONE.segment_clearance_m(np.array([15.0, 0.0]), np.array([15.0, 40.0])) == 0.0  # ends inside
    rng = np.random.default_rng(7)
    w = make_world([(10.0, 30.0, 20.0, 50.0), (35.0, 5.0, 50.0, 12.0)])
    a, b = rng.uniform(-5, 65, (2, 200, 2))
    exact = w.segment_clearance_m(a, b)
    s = np.linspace(0.0, 1.0, 4001)[:, None, None]
    pts = a + s * (b - a)  # (S, 200, 2)
    sampled = w.clearance_m(pts[..., 0], pts[..., 1]).min(axis=0)
    assert np.all(exact <= sampled + 1e-9)  # the exact minimum never exceeds a sampled one
    step = np.linalg.norm(b - a, axis=1) / 4000
    assert np.all(sampled - exact <= step / 2 + 1e-9)  # and samples approach it within half a step


def test_occupancy_and_edt_match_eq1_by_brute_force():
    w = make_world([(10.3, 30.0, 20.0, 41.5), (3.0, 3.0, 4.0, 4.0)], size_m=50.0, resolution_m=2.0)
    assert w.shape == (25, 25)
    # occupied cells are exactly those whose square overlaps a building's interior
    assert w.occupancy[5, 15] and w.occupancy[9, 20] and not w.occupancy[10, 15] and not w.occupancy[5, 21]
    assert w.occupancy[1, 1] and not w.occupancy[2, 2]
    occ = np.argwhere(w.occupancy)
    free = np.argwhere(~w.occupancy)
    brute = np.sqrt(((free[:, None, :] - occ[None, :, :]) ** 2).sum(-1)).min(1) * 2.0  # eq. 1
    np.testing.assert_allclose(w.edt_m[~w.occupancy], brute)
    assert np.all(w.edt_m[w.occupancy] == 0.0)
    # every building point lies in an occupied cell: exact clearance is within res/√2 of the EDT
    centres = w.cell_centre_ne_m(free)
    exact = w.clearance_m(centres[:, 0], centres[:, 1])
    assert np.all(exact >= w.edt_m[~w.occupancy] - 2.0 / math.sqrt(2) - 1e-12)
    assert np.all(exact <= w.edt_m[~w.occupancy] + 1e-12)


def test_blocked_cells_keep_the_margin_up_to_half_a_cell_diagonal():
    w = make_world([(10.0, 30.0, 20.0, 50.0), (35.0, 5.0, 50.0, 12.0)], resolution_m=2.0)
    blocked = w.blocked(4.0)
    free = np.argwhere(~blocked)
    centres = w.cell_centre_ne_m(free)
    assert np.all(w.clearance_m(centres[:, 0], centres[:, 1]) >= 4.0 - math.sqrt(2) - 1e-12)
    assert blocked[w.occupancy].all()
    assert w.cell_of(11.0, 31.0) == (5, 15)
    assert w.cell_of(-3.0, 99.0) == (0, 29)  # clipped to the grid
