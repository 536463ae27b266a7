"""Modified A* on the occupancy grid (eq. 2-3): traversal, turn and clearance costs.

The search state is (cell, heading of the move that entered it), so the turn cost is exact:
moving from cell m to its 8-neighbour n with heading ψ after heading ψ' costs

    w_tra·L + w_turn_m_rad·|ψ - ψ'| + w_clr·L·max(0, 1 - d_obs(n)/clearance_cost_range_m)

with L the move length in metres and d_obs the EDT clearance (eq. 1); the first move has no
turn cost. The heuristic ``w_tra·‖p_n - p_goal‖`` never overestimates (every move costs at
least ``w_tra·L``) and is consistent, so the first goal state popped is optimal. Diagonal
moves need both orthogonal neighbours free (no corner cutting). The start and goal cells are
always enterable: the loader has checked the exact points themselves.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass

import numpy as np

from companion.mission.config import PlannerConfig

# The 8 headings in angular order (45° apart), as (d_row, d_col) = (d_north, d_east).
DIRECTIONS: tuple[tuple[int, int], ...] = (
    (1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1),
)
_NO_HEADING = len(DIRECTIONS)


@dataclass(frozen=True)
class GridPath:
    """An optimal grid path: cells (K, 2) as (row, column), its eq.-3 cost and the search effort."""

    cells: np.ndarray
    cost: float
    expanded: int


def turn_angle_rad(d_from: int, d_to: int) -> float:
    """Heading change between two of the 8 directions (0 from the no-heading start state)."""
    if d_from == _NO_HEADING:
        return 0.0
    k = abs(d_to - d_from) % 8
    return min(k, 8 - k) * math.pi / 4


def clearance_penalty(edt_m: np.ndarray, planner: PlannerConfig) -> np.ndarray:
    """Per-metre clearance cost of entering each cell, ``max(0, 1 - d_obs/range)``."""
    return np.clip(1.0 - np.asarray(edt_m, dtype=float) / planner.clearance_cost_range_m, 0.0, 1.0)


def astar(
    blocked: np.ndarray,
    edt_m: np.ndarray,
    start: tuple[int, int],
    goal: tuple[int, int],
    planner: PlannerConfig,
    resolution_m: float,
) -> GridPath | None:
    """Least-cost path from ``start`` to ``goal`` cell avoiding ``blocked``; None if none exists."""
    n_rows, n_cols = blocked.shape
    free = (~np.asarray(blocked, dtype=bool)).copy()
    free[start] = free[goal] = True
    free_flat: list[bool] = free.ravel().tolist()
    clr_flat: list[float] = (planner.w_clr * clearance_penalty(edt_m, planner)).ravel().tolist()
    w_tra = planner.w_tra
    turn = [[planner.w_turn_m_rad * turn_angle_rad(a, b) for b in range(8)] for a in range(9)]
    moves = [(di, dj, di * n_cols + dj, resolution_m * math.hypot(di, dj)) for di, dj in DIRECTIONS]
    gi, gj = goal
    goal_cell = gi * n_cols + gj
    h_scale = w_tra * resolution_m

    start_state = (start[0] * n_cols + start[1]) * 9 + _NO_HEADING
    best_g: dict[int, float] = {start_state: 0.0}
    parent: dict[int, int] = {}
    heap = [(h_scale * math.hypot(start[0] - gi, start[1] - gj), 0.0, start_state)]
    expanded = 0
    while heap:
        _, g, state = heapq.heappop(heap)
        if g > best_g[state]:
            continue  # a stale entry
        cell, heading = divmod(state, 9)
        if cell == goal_cell:
            return GridPath(_cells(state, parent, n_cols), g, expanded)
        expanded += 1
        i, j = divmod(cell, n_cols)
        turn_from = turn[heading]
        for d, (di, dj, d_flat, length_m) in enumerate(moves):
            ni, nj = i + di, j + dj
            if not (0 <= ni < n_rows and 0 <= nj < n_cols):
                continue
            nxt = cell + d_flat
            if not free_flat[nxt]:
                continue
            if di and dj and not (free_flat[cell + di * n_cols] and free_flat[cell + dj]):
                continue
            g_new = g + length_m * (w_tra + clr_flat[nxt]) + turn_from[d]
            s_new = nxt * 9 + d
            if g_new < best_g.get(s_new, math.inf):
                best_g[s_new] = g_new
                parent[s_new] = state
                heapq.heappush(heap, (g_new + h_scale * math.hypot(ni - gi, nj - gj), g_new, s_new))
    return None


def _cells(state: int, parent: dict[int, int], n_cols: int) -> np.ndarray:
    flat = [state // 9]
    while state in parent:
        state = parent[state]
        flat.append(state // 9)
    rows, cols = np.divmod(np.array(flat[::-1]), n_cols)
    return np.stack([rows, cols], axis=1)
