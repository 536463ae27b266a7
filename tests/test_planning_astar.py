"""Modified A* (eq. 2-3) against Dijkstra (scipy.sparse.csgraph) on random grids, seeded."""

import math

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from companion.mission import PlannerConfig, load_mission
from companion.planning.astar import DIRECTIONS, astar, clearance_penalty, turn_angle_rad

RES_M = 2.0


def random_grid(rng, shape=(11, 13), density=0.28):
    blocked = rng.random(shape) < density
    free = np.argwhere(~blocked)
    start, goal = (tuple(int(x) for x in free[k]) for k in rng.choice(len(free), 2, replace=False))
    edt_m = rng.uniform(0.0, 12.0, shape)  # any non-negative field will do for the cost
    return blocked, edt_m, start, goal


def moves(blocked, i, j):
    """8-neighbour moves without corner cutting — the rule A* documents."""
    n_rows, n_cols = blocked.shape
    for d, (di, dj) in enumerate(DIRECTIONS):
        ni, nj = i + di, j + dj
        if 0 <= ni < n_rows and 0 <= nj < n_cols and not blocked[ni, nj]:
            if di and dj and (blocked[i + di, j] or blocked[i, j + dj]):
                continue
            yield d, ni, nj, RES_M * math.hypot(di, dj)


def dijkstra_cost(blocked, edt_m, start, goal, planner, with_heading):
    """Reference: Dijkstra on the cell graph, or on the (cell, heading) graph for turn costs."""
    blocked = blocked.copy()
    blocked[start] = blocked[goal] = False
    n_rows, n_cols = blocked.shape
    pen = planner.w_clr * clearance_penalty(edt_m, planner)
    n_head = 9 if with_heading else 1
    node = lambda i, j, h: (i * n_cols + j) * n_head + h  # noqa: E731
    rows, cols, w = [], [], []
    for i, j in np.ndindex(blocked.shape):
        for h in range(n_head):
            for d, ni, nj, length in moves(blocked, i, j):
                turn = planner.w_turn_m_rad * turn_angle_rad(h, d) if with_heading else 0.0
                rows.append(node(i, j, h))
                cols.append(node(ni, nj, d if with_heading else 0))
                w.append(length * (planner.w_tra + pen[ni, nj]) + turn)
    n = n_rows * n_cols * n_head
    graph = coo_matrix((w, (rows, cols)), shape=(n, n)).tocsr()
    src = node(*start, 8 if with_heading else 0)
    dist = dijkstra(graph, indices=src)
    goal_nodes = [node(*goal, h) for h in range(n_head)]
    return dist[goal_nodes].min()


def path_cost(cells, edt_m, planner):
    """Eq. 3 summed along a returned path (independent of the search)."""
    pen = planner.w_clr * clearance_penalty(edt_m, planner)
    steps = np.diff(cells, axis=0)
    dirs = [DIRECTIONS.index((int(a), int(b))) for a, b in steps]
    cost = 0.0
    for k, (d, (i, j)) in enumerate(zip(dirs, cells[1:], strict=True)):
        length = RES_M * math.hypot(*DIRECTIONS[d])
        cost += length * (planner.w_tra + pen[i, j])
        cost += planner.w_turn_m_rad * turn_angle_rad(dirs[k - 1] if k else 8, d)
    return cost


def check_path(cells, blocked, start, goal):
    assert tuple(cells[0]) == start and tuple(cells[-1]) == goal
    for (i, j), (ni, nj) in zip(cells[:-1], cells[1:], strict=True):
        di, dj = ni - i, nj - j
        assert (di, dj) in DIRECTIONS
        if (ni, nj) != goal:
            assert not blocked[ni, nj]
        if di and dj:
            assert not blocked[i + di, j] and not blocked[i, j + dj]


@pytest.mark.parametrize(
    ("seed", "planner", "shape", "with_heading"),
    [
        # turn and clearance weights zero: plain Dijkstra on the cell graph
        (20240601, PlannerConfig(w_tra=1.3, w_turn_m_rad=0.0, w_clr=0.0), (11, 13), False),
        # the full eq. 3: Dijkstra on the (cell, heading) graph
        (7, PlannerConfig(w_tra=1.0, w_turn_m_rad=2.5, w_clr=4.0, clearance_cost_range_m=8.0), (9, 10), True),
    ],
)
def test_astar_equals_dijkstra(seed, planner, shape, with_heading):
    rng = np.random.default_rng(seed)
    found = 0
    for _ in range(25):
        blocked, edt_m, start, goal = random_grid(rng, shape)
        ref = dijkstra_cost(blocked, edt_m, start, goal, planner, with_heading)
        path = astar(blocked, edt_m, start, goal, planner, RES_M)
        if not np.isfinite(ref):
            assert path is None
            continue
        found += 1
        assert path.cost == pytest.approx(ref, rel=1e-12)
        assert path_cost(path.cells, edt_m, planner) == pytest.approx(ref, rel=1e-12)
        check_path(path.cells, blocked, start, goal)
    assert found >= 12  # the draw really exercised the search


def test_turn_weight_straightens_the_path():
    blocked = np.zeros((20, 20), dtype=bool)
    edt_m = np.full((20, 20), 100.0)
    straight = astar(blocked, edt_m, (0, 0), (19, 12), PlannerConfig(w_turn_m_rad=5.0), RES_M)
    n_turns = np.count_nonzero(np.any(np.diff(np.diff(straight.cells, axis=0), axis=0), axis=1))
    assert n_turns == 1  # diagonal run then straight run (or the reverse): one turn only


def test_default_city_paths_avoid_blocked_cells():
    m = load_mission("default")
    blocked = m.world.blocked(m.planner.clearance_margin_m)
    for k in (1, 7):
        p = m.profiles[k]
        start, goal = m.world.cell_of(*p.start_ne_m), m.world.cell_of(*p.goal_ne_m)
        path = astar(blocked, m.world.edt_m, start, goal, m.planner, m.world.resolution_m)
        check_path(path.cells, blocked, start, goal)
        inner = path.cells[1:-1]
        assert np.all(m.world.edt_m[inner[:, 0], inner[:, 1]] >= m.planner.clearance_margin_m)
        assert not m.world.occupancy[path.cells[:, 0], path.cells[:, 1]].any()
