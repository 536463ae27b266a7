"""The 2-D urban world: building rectangles, occupancy grid, EDT clearance (eq. 1), exact distances.

Two distances, for two jobs:

* ``clearance_m`` / ``segment_clearance_m`` are EXACT Euclidean distances to the nearest
  building rectangle (0 inside) — what the GNSS model (eq. 22), collision checks and
  line-of-sight pruning use.
* ``edt_m`` is the paper's grid clearance (eq. 1): for each cell centre, the distance to the
  nearest occupied cell centre (``scipy.ndimage.distance_transform_edt``'s numbers; ``grid.py``). A cell is
  occupied when its square overlaps a building, so every building point lies in an
  occupied cell and ``clearance_m(centre) >= edt_m - resolution_m/√2``.

Grid cell ``(i, j)`` spans north ``[n0 + i·res, n0 + (i+1)·res]`` and east likewise; row ``i``
is north, column ``j`` is east. Pure numpy (scipy for a large grid, ``grid.py``), no I/O.
"""

from __future__ import annotations

import numpy as np

from companion.mission.config import WorldConfig
from companion.mission.grid import distance_transform_m

ArrayLike = float | np.ndarray


class World:
    """Buildings and grids built once from a ``WorldConfig``; read-only afterwards."""

    def __init__(self, config: WorldConfig) -> None:
        self.config = config
        self.resolution_m = config.resolution_m
        b = config.bounds
        self.origin_ne_m = np.array([b.north_min_m, b.east_min_m])
        # (B, 4) rows: north_min, east_min, north_max, east_max
        self.rects_m = np.array(
            [[r.north_min_m, r.east_min_m, r.north_max_m, r.east_max_m] for r in config.buildings],
            dtype=float,
        ).reshape(-1, 4)
        self.rects_m.setflags(write=False)
        self._rect_columns = tuple(np.ascontiguousarray(c) for c in self.rects_m.T)
        n_rows = int(np.ceil((b.north_max_m - b.north_min_m) / self.resolution_m - 1e-9))
        n_cols = int(np.ceil((b.east_max_m - b.east_min_m) / self.resolution_m - 1e-9))
        self.shape = (n_rows, n_cols)
        self.occupancy = self._rasterise()
        self.edt_m = self._edt()
        for a in (self.occupancy, self.edt_m):
            a.setflags(write=False)

    # ---- exact geometry -------------------------------------------------------------------
    def clearance_m(self, north_m: ArrayLike, east_m: ArrayLike) -> ArrayLike:
        """Exact Euclidean distance to the nearest building (0 inside or on a wall); inf if none.

        Vectorised: array inputs broadcast together and give an array of their shape.
        """
        if np.ndim(north_m) == 0 and np.ndim(east_m) == 0:
            return self._point_clearance_m(float(north_m), float(east_m))
        d = self.building_distances_m(north_m, east_m).min(axis=-1, initial=np.inf)
        return float(d) if d.ndim == 0 else d

    def _point_clearance_m(self, north_m: float, east_m: float) -> float:
        """``clearance_m`` of one point: the same arithmetic on the rectangle columns, fewer numpy calls."""
        if not len(self.rects_m):
            return np.inf
        n0, e0, n1, e1 = self._rect_columns
        gap_n = np.maximum(np.maximum(n0 - north_m, north_m - n1), 0.0)
        gap_e = np.maximum(np.maximum(e0 - east_m, east_m - e1), 0.0)
        return float(np.hypot(gap_n, gap_e).min())

    def nearest_building(self, north_m: float, east_m: float) -> int:
        """Index of the building nearest to a point (-1 when there are none)."""
        d = self.building_distances_m(north_m, east_m)
        return int(np.argmin(d)) if d.size else -1

    def building_distances_m(self, north_m: ArrayLike, east_m: ArrayLike) -> np.ndarray:
        """Exact distance from point(s) to every building: shape (..., B)."""
        p = np.stack(np.broadcast_arrays(np.asarray(north_m, float), np.asarray(east_m, float)), -1)
        return _point_rect_m(p[..., None, :], self.rects_m[:, :2], self.rects_m[:, 2:])

    def collides(self, north_m: ArrayLike, east_m: ArrayLike) -> bool | np.ndarray:
        """True where the point is inside (or on the wall of) a building."""
        d = np.asarray(self.clearance_m(north_m, east_m))
        hit = d <= 0.0
        return bool(hit) if hit.ndim == 0 else hit

    def segment_clearance_m(self, a_ne_m: np.ndarray, b_ne_m: np.ndarray) -> ArrayLike:
        """Exact distance from the segment(s) ``a → b`` to the nearest building (0 if crossing).

        ``a_ne_m``, ``b_ne_m``: (..., 2), broadcast together. Two disjoint convex polygons are
        closest at a vertex of one of them, so the distance is the least of the endpoints' distances to the
        rectangle and the rectangle corners' distances to the segment; crossing is detected
        by Liang-Barsky clipping.
        """
        a, b = np.broadcast_arrays(np.asarray(a_ne_m, dtype=float), np.asarray(b_ne_m, dtype=float))
        a, b = a[..., None, :], b[..., None, :]  # (..., 1, 2)
        r = self.rects_m  # (B, 4)
        lo, hi = r[:, :2], r[:, 2:]
        d_ends = np.minimum(_point_rect_m(a, lo, hi), _point_rect_m(b, lo, hi))  # (..., B)
        corners = np.stack(
            [lo, hi, np.stack([lo[:, 0], hi[:, 1]], -1), np.stack([hi[:, 0], lo[:, 1]], -1)], axis=-2
        )  # (B, 4, 2)
        d_corners = _point_segment_m(corners, a[..., None, :], b[..., None, :]).min(axis=-1)
        d = np.minimum(d_ends, d_corners)
        d = np.where(_segment_hits_rect(a, b, lo, hi), 0.0, d).min(axis=-1, initial=np.inf)
        return float(d) if d.ndim == 0 else d

    # ---- grid -----------------------------------------------------------------------------
    def cell_of(self, north_m: float, east_m: float) -> tuple[int, int]:
        """The grid cell containing a point (clipped to the grid)."""
        ij = np.floor((np.array([north_m, east_m]) - self.origin_ne_m) / self.resolution_m).astype(int)
        ij = np.clip(ij, 0, np.array(self.shape) - 1)
        return int(ij[0]), int(ij[1])

    def cell_centre_ne_m(self, cells: np.ndarray) -> np.ndarray:
        """Centres (K, 2) of cells (K, 2) given as (row, column)."""
        return self.origin_ne_m + (np.asarray(cells, dtype=float) + 0.5) * self.resolution_m

    def blocked(self, margin_m: float) -> np.ndarray:
        """Cells the planner may not enter: occupied or with EDT clearance below ``margin_m``."""
        return self.edt_m < margin_m

    def _rasterise(self) -> np.ndarray:
        res = self.resolution_m
        occ = np.zeros(self.shape, dtype=bool)
        for n0, e0, n1, e1 in self.rects_m - np.r_[self.origin_ne_m, self.origin_ne_m]:
            # cells whose open square overlaps the building's interior
            i0, i1 = int(np.floor(n0 / res)), int(np.ceil(n1 / res))
            j0, j1 = int(np.floor(e0 / res)), int(np.ceil(e1 / res))
            occ[max(i0, 0):i1, max(j0, 0):j1] = True
        return occ

    def _edt(self) -> np.ndarray:
        return distance_transform_m(self.occupancy, self.resolution_m)


def _point_rect_m(p: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Distance from points (..., 1, 2) to rectangles lo/hi (B, 2) → (..., B)."""
    gap = np.maximum(np.maximum(lo - p, p - hi), 0.0)
    return np.hypot(gap[..., 0], gap[..., 1])


def _point_segment_m(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from points p to segments a→b (broadcast over leading axes, last axis = 2)."""
    ab = b - a
    den = np.einsum("...i,...i->...", ab, ab)
    t = np.einsum("...i,...i->...", p - a, ab) / np.where(den > 0, den, 1.0)
    t = np.clip(t, 0.0, 1.0)[..., None]
    q = a + t * ab - p
    return np.hypot(q[..., 0], q[..., 1])


def _segment_hits_rect(a: np.ndarray, b: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Liang-Barsky: does the closed segment a→b (..., 1, 2) meet the closed rectangles (B, 2)?"""
    d = b - a
    t0 = np.zeros(np.broadcast_shapes(a.shape[:-1], lo.shape[:-1]))
    t1 = np.ones_like(t0)
    ok = np.ones(t0.shape, dtype=bool)
    for k in range(2):
        dk, ak = d[..., k], a[..., k]
        moving = dk != 0
        safe = np.where(moving, dk, 1.0)
        ta, tb = (lo[:, k] - ak) / safe, (hi[:, k] - ak) / safe
        t_enter, t_exit = np.minimum(ta, tb), np.maximum(ta, tb)
        t0 = np.where(moving, np.maximum(t0, t_enter), t0)
        t1 = np.where(moving, np.minimum(t1, t_exit), t1)
        ok &= moving | ((lo[:, k] <= ak) & (ak <= hi[:, k]))
    return ok & (t0 <= t1)
