"""companion.mission.grid against scipy.ndimage, which it replaces in mission loading: the same
distance transform bit for bit, the same 4-connectivity, and no scipy import for a mission."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from scipy import ndimage

from companion.mission import load_mission
from companion.mission.grid import MAX_BFS_CELLS, MAX_EDT_WORK, connected_4, distance_transform_m


@pytest.mark.parametrize("name", ["test", "default", "mild"])
def test_mission_clearance_grid_is_scipys(name):
    w = load_mission(name).world
    ref = ndimage.distance_transform_edt(~w.occupancy, sampling=w.resolution_m)
    assert w.edt_m.dtype == ref.dtype and w.edt_m.tobytes() == ref.tobytes()


def test_random_grids_give_scipys_distances_and_components():
    """Random occupancies (sparse to nearly full, one-row and one-column grids), power-of-two and other
    resolutions (those go to scipy itself), and random cell pairs."""
    rng = np.random.default_rng(7)
    for _ in range(150):
        rows, cols = (int(n) for n in rng.integers(1, 40, 2))
        occ = rng.random((rows, cols)) < rng.choice([0.02, 0.1, 0.3, 0.7, 0.95])
        for res in (1.0, 2.0, 0.5, 0.3):
            got = distance_transform_m(occ, res)
            if occ.any():
                ref = ndimage.distance_transform_edt(~occ, sampling=res)
                assert got.tobytes() == ref.tobytes(), (rows, cols, res)
            else:
                assert np.isinf(got).all() and got.shape == occ.shape
        for _ in range(4):
            a = (int(rng.integers(rows)), int(rng.integers(cols)))
            b = (int(rng.integers(rows)), int(rng.integers(cols)))
            free = ~occ
            free[a] = free[b] = True
            labels, _ = ndimage.label(free)
            assert connected_4(~occ, a, b) == bool(labels[a] == labels[b])


def test_a_large_grid_gives_scipys_answers_through_scipy():
    """Beyond the size bounds (a big city) both answers are scipy's own, at scipy's speed."""
    occ = np.zeros((350, 400), dtype=bool)
    occ[100:110, 20:380] = True  # a wall across, open at both ends
    occ[200:210, 0:400] = True  # a wall right across: rows above 210 unreachable from row 0
    assert MAX_EDT_WORK < 350 * 400 * 400 and MAX_BFS_CELLS < 350 * 400
    ref = ndimage.distance_transform_edt(~occ, sampling=2.0)
    assert distance_transform_m(occ, 2.0).tobytes() == ref.tobytes()
    assert connected_4(~occ, (0, 0), (150, 200)) and not connected_4(~occ, (0, 0), (300, 200))


def test_a_wall_with_one_diagonal_gap_does_not_connect():
    free = np.ones((3, 3), dtype=bool)
    free[0, 1] = free[1, 0] = free[1, 1] = False
    assert not connected_4(free, (0, 0), (2, 2))
    free[1, 1] = True
    assert not connected_4(free, (0, 0), (2, 2))  # (0,0) is walled in on both edges
    free[0, 1] = True
    assert connected_4(free, (0, 0), (2, 2))


def test_loading_a_mission_imports_no_scipy():
    code = ("import sys; from companion.mission import load_mission; load_mission('test'); "
            "print('scipy' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"
