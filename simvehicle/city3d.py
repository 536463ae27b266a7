"""Signal paths in the 3-D city (box buildings on flat ground): line of sight, roof-edge diffraction
and single specular reflections off facades, vectorised over rays. Pure numpy, no state.

Geometry: buildings are the mission's rectangles ``[n_min, e_min, n_max, e_max]`` with their
heights above the home altitude (ground = 0 m); a position is (north, east, height). A satellite is
at infinity in the unit direction ``u`` (elevation ``el`` > 0): every ray rises with slope
``tan el`` per metre of horizontal run.

* **Line of sight** (slab test): the horizontal ray enters building ``b`` at run ``t_b``; the ray
  is blocked when the roof is above it there, ``H_b > h + t_b tan el`` (exact for boxes: the ray
  rises, so its lowest point over a roof is where it enters it).
* **Diffraction** over the dominant roof edge (single knife edge, ITU-R P.526): the Fresnel-Kirchhoff
  parameter ``ν = Δh · sqrt(2 / (λ d))`` with ``Δh`` the roof's height above the ray at the edge
  (negative: the ray clears it) and ``d`` the slant distance to the edge; loss
  ``J(ν) = 6.9 + 20 log10(sqrt((ν − 0.1)² + 1) + ν − 0.1)`` dB for ``ν > −0.78``, else 0. The
  diffracted path's extra length is that of the path receiver → edge → satellite.
* **Reflections** (image method): a facade is a vertical plane (north or east face of a box) with
  outward normal ``n``. A satellite in front of it (``u·n > 0``) reflects into the receiver,
  at horizontal distance ``D`` in front of the plane, from the direction ``u' = u − 2 (u·n) n``
  (the same elevation); the specular point is where the ray from the receiver along ``u'`` meets
  the plane. It counts when that point lies on the facade (within its span, below its roof) and
  both legs are clear (receiver → point, point → satellite). Extra path ``2 D (u·n)``
  = ``2 D cos(el) cos(Δaz)``. One bounce; no ground, roof or double reflections.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

NUDGE_M = 1e-6  # a reflected ray leaves the facade this far in front of it


@dataclass(frozen=True)
class Facades:
    """The vertical faces of the boxes, (W,) arrays: the plane ``x[axis] = coord`` with outward
    normal ``sign`` along ``axis`` (0 north, 1 east), spanning ``lo..hi`` along the other axis,
    up to ``height_m``, of building ``building``."""

    axis: np.ndarray
    coord: np.ndarray
    sign: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    height_m: np.ndarray
    building: np.ndarray

    @classmethod
    def of(cls, rects_m: np.ndarray, heights_m: np.ndarray) -> Facades:
        r = np.asarray(rects_m, dtype=float).reshape(-1, 4)
        h = np.asarray(heights_m, dtype=float)
        b = np.arange(len(r))
        # south (n_min, −N), north (n_max, +N), west (e_min, −E), east (e_max, +E)
        return cls(
            axis=np.repeat([0, 0, 1, 1], len(r)),
            coord=np.concatenate([r[:, 0], r[:, 2], r[:, 1], r[:, 3]]),
            sign=np.repeat([-1.0, 1.0, -1.0, 1.0], len(r)),
            lo=np.concatenate([r[:, 1], r[:, 1], r[:, 0], r[:, 0]]),
            hi=np.concatenate([r[:, 3], r[:, 3], r[:, 2], r[:, 2]]),
            height_m=np.tile(h, 4),
            building=np.tile(b, 4),
        )

    def __len__(self) -> int:
        return len(self.axis)


def knife_edge_loss_db(nu: np.ndarray) -> np.ndarray:
    """ITU-R P.526 single knife-edge diffraction loss (dB, ≥ 0) for Fresnel-Kirchhoff ``ν``."""
    nu = np.asarray(nu, dtype=float)
    x = np.where(nu > -0.78, nu - 0.1, 0.0)
    return np.where(nu > -0.78, 6.9 + 20.0 * np.log10(np.sqrt(x * x + 1.0) + x), 0.0)


@dataclass(frozen=True, slots=True)
class RayTrace:
    """Per ray (K,): blocked by a roof, the dominant edge's ``ν`` (−inf: no building crossed), the
    slant distance to that edge and the roof's height above the ray there (m; > 0 blocked)."""

    blocked: np.ndarray
    nu: np.ndarray
    edge_distance_m: np.ndarray
    edge_over_m: np.ndarray


class City:
    """The buildings as boxes; ray tests vectorised over rays × buildings."""

    def __init__(self, rects_m: np.ndarray, heights_m: np.ndarray) -> None:
        r = np.asarray(rects_m, dtype=float).reshape(-1, 4)
        self.lo = r[:, 0:2]
        self.hi = r[:, 2:4]
        self.height_m = np.asarray(heights_m, dtype=float)
        self.facades = Facades.of(r, self.height_m)
        self._index = np.arange(len(r))

    def _entry(self, origin_ne: np.ndarray, dir_ne: np.ndarray, run_max_m: np.ndarray | None,
               skip: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """Horizontal run (K, B) where each ray enters each box (0 from inside), and whether it does
        (before ``run_max_m``, not building ``skip``): the slab test."""
        d = np.where(np.abs(dir_ne) < 1e-12, 1e-12, dir_ne)  # parallel to a slab: a huge finite run
        inv = (1.0 / d)[:, None, :]
        o = origin_ne[:, None, :]
        t1 = (self.lo[None] - o) * inv
        t2 = (self.hi[None] - o) * inv
        t_near = np.minimum(t1, t2).max(axis=2)
        t_far = np.maximum(t1, t2).min(axis=2)
        t_in = np.maximum(t_near, 0.0)
        hit = t_far >= t_in
        if run_max_m is not None:
            hit &= t_in < run_max_m[:, None]
        if skip is not None:
            hit &= self._index[None] != skip[:, None]
        return t_in, hit

    def blocked(self, origin_ne: np.ndarray, h_m: np.ndarray, dir_ne: np.ndarray, tan_el: np.ndarray,
                run_max_m: np.ndarray | None = None, skip: np.ndarray | None = None) -> np.ndarray:
        """(K,) True where a roof is above the ray (see :meth:`trace`; no diffraction)."""
        if not len(self.height_m):
            return np.zeros(len(origin_ne), bool)
        t_in, hit = self._entry(origin_ne, dir_ne, run_max_m, skip)
        return (hit & (self.height_m[None] > h_m[:, None] + t_in * tan_el[:, None])).any(axis=1)

    def trace(self, origin_ne: np.ndarray, h_m: np.ndarray, dir_ne: np.ndarray, tan_el: np.ndarray,
              wavelength_m: float) -> RayTrace:
        """Rays from ``origin_ne`` (K, 2) at height ``h_m`` (K,) along the horizontal unit
        directions ``dir_ne`` (K, 2), rising ``tan_el`` (K,) per metre: blocked, and the dominant
        roof edge for diffraction."""
        k = len(origin_ne)
        if not len(self.height_m):
            inf = np.full(k, -np.inf)
            return RayTrace(np.zeros(k, bool), inf, np.full(k, np.nan), inf)
        t_in, hit = self._entry(origin_ne, dir_ne, None, None)
        over = self.height_m[None] - (h_m[:, None] + t_in * tan_el[:, None])  # roof above the ray (K, B)
        cos_el = (1.0 / np.sqrt(1.0 + tan_el * tan_el))[:, None]
        dist = np.maximum(t_in / cos_el, 0.1)
        # the edge's distance from the ray, perpendicular to it: the vertical offset × cos(el)
        nu = np.where(hit, over * cos_el * np.sqrt(2.0 / wavelength_m / dist), -np.inf)
        j = np.argmax(nu, axis=1)
        rows = np.arange(k)
        nu_j = nu[rows, j]
        return RayTrace(nu_j > 0.0, nu_j, dist[rows, j], over[rows, j])

    def reflections(self, p_ne: np.ndarray, h_m: float, dir_ne: np.ndarray,
                    tan_el: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Every valid specular reflection of satellites (S,) (horizontal unit directions ``dir_ne``
        (S, 2), slopes ``tan_el``) into the receiver at ``p_ne`` (2,), height ``h_m``:
        ``(satellite (R,), facade (R,), extra path m (R,), cos of the incidence angle u·n (R,))``."""
        f = self.facades
        p = np.asarray(p_ne, dtype=float)
        dist = f.sign * (p[f.axis] - f.coord)  # receiver in front of the plane (W,)
        u_axis = dir_ne[:, f.axis] * f.sign[None]  # (S, W): > 0 the satellite is in front
        cand = (dist[None] > 0.0) & (u_axis > 1e-9)
        s_idx, w_idx = np.nonzero(cand)
        if not len(s_idx):
            return s_idx, w_idx, np.zeros(0), np.zeros(0)
        ua = u_axis[s_idx, w_idx]
        run = dist[w_idx] / ua  # horizontal run to the plane along the mirrored direction
        other = 1 - f.axis[w_idx]
        d_other = dir_ne[s_idx, other]
        q_other = p[other] + d_other * run
        tan = tan_el[s_idx]
        q_h = h_m + run * tan
        on = (q_other >= f.lo[w_idx]) & (q_other <= f.hi[w_idx]) & (q_h <= f.height_m[w_idx])
        s_idx, w_idx, run, q_other, q_h, tan = s_idx[on], w_idx[on], run[on], q_other[on], q_h[on], tan[on]
        if not len(s_idx):
            return s_idx, w_idx, np.zeros(0), np.zeros(0)
        axis = f.axis[w_idx]
        d_in = dir_ne[s_idx].copy()  # the arriving direction, mirrored (toward the facade)
        d_in[np.arange(len(s_idx)), axis] *= -1.0
        b = f.building[w_idx]
        leg1 = self.blocked(np.broadcast_to(p, (len(s_idx), 2)), np.full(len(s_idx), h_m), d_in, tan,
                            run_max_m=run, skip=b)
        q = np.empty((len(s_idx), 2))
        q[np.arange(len(s_idx)), axis] = f.coord[w_idx] + f.sign[w_idx] * NUDGE_M
        q[np.arange(len(s_idx)), 1 - axis] = q_other
        leg2 = self.blocked(q, q_h, dir_ne[s_idx], tan, skip=b)
        ok = ~leg1 & ~leg2
        cos_el = 1.0 / np.sqrt(1.0 + tan[ok] ** 2)
        u_n = dir_ne[s_idx[ok], axis[ok]] * f.sign[w_idx[ok]] * cos_el
        return s_idx[ok], w_idx[ok], 2.0 * dist[w_idx[ok]] * u_n, u_n


def diffraction_extra_m(edge_distance_m: np.ndarray, edge_over_m: np.ndarray, sin_el: np.ndarray) -> np.ndarray:
    """Extra length (m) of the path bent over an edge ``Δh`` above the straight ray at slant
    distance ``d`` (toward a satellite at infinity, elevation ``el``): with the edge at
    ``d u + Δh z``, ``|d u + Δh z| − u·(d u + Δh z)`` (≈ Δh² cos² el / 2d); 0 when the ray clears it."""
    d = np.nan_to_num(edge_distance_m, nan=1.0)
    over = np.maximum(np.nan_to_num(edge_over_m, neginf=0.0), 0.0)
    return np.sqrt(d * d + 2.0 * d * over * sin_el + over * over) - d - over * sin_el
