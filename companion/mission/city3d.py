"""Signal paths in the 3-D city (box buildings on flat ground): line of sight, roof-edge diffraction
and single specular reflections off facades, vectorised over rays. Pure numpy, no state: the one
implementation the simulated receiver (``simvehicle.receiver``, ``simvehicle.nlos``) and the
companion's map prior (``companion.wiring.tight_navigator_for``) share.

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
        self._lo_n, self._lo_e = r[None, :, 0], r[None, :, 1]
        self._hi_n, self._hi_e = r[None, :, 2], r[None, :, 3]

    def _entry(
        self, origin_ne: np.ndarray, dir_ne: np.ndarray, run_max_m: np.ndarray | None, skip: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Horizontal run (K, B) where each ray enters each box (0 from inside), and whether it does
        (before ``run_max_m``, not building ``skip``): the slab test."""
        d = np.where(np.abs(dir_ne) < 1e-12, 1e-12, dir_ne)  # parallel to a slab: a huge finite run
        inv_n, inv_e = (1.0 / d[:, 0])[:, None], (1.0 / d[:, 1])[:, None]
        o_n, o_e = origin_ne[:, 0:1], origin_ne[:, 1:2]
        n0, n1 = (
            (self._lo_n - o_n) * inv_n,
            (self._hi_n - o_n) * inv_n,
        )  # (K, B) per slab, no axis-2 reductions
        e0, e1 = (self._lo_e - o_e) * inv_e, (self._hi_e - o_e) * inv_e
        t_near = np.maximum(np.minimum(n0, n1), np.minimum(e0, e1))
        t_far = np.minimum(np.maximum(n0, n1), np.maximum(e0, e1))
        t_in = np.maximum(t_near, 0.0)
        hit = t_far >= t_in
        if run_max_m is not None:
            hit &= t_in < run_max_m[:, None]
        if skip is not None:
            hit &= self._index[None] != skip[:, None]
        return t_in, hit

    def perturbed(self, rng: np.random.Generator, sigma_height_m: float, sigma_shift_m: float) -> City:
        """The same city as an imperfect map would have it: each building's height off by
        N(0, sigma_height_m²) (kept ≥ 1 m) and its footprint moved by N(0, sigma_shift_m²) per axis."""
        n = len(self.height_m)
        h = np.maximum(self.height_m + rng.normal(0.0, sigma_height_m, n), 1.0)
        shift = rng.normal(0.0, sigma_shift_m, (n, 2))
        return City(np.hstack((self.lo + shift, self.hi + shift)), h)

    def shifted(self, origin_ned_m: np.ndarray) -> City:
        """The same city in a frame whose origin lies at ``origin_ned_m`` (NED) in this one: footprints
        moved by its north and east, heights above its level (a translation: two local frames a few
        hundred metres apart are also turned by their distance over the Earth's radius, 5e-5 rad per
        300 m, i.e. centimetres over such a map)."""
        o = np.asarray(origin_ned_m, dtype=float)
        ne = np.array([o[0], o[1]])
        return City(np.hstack((self.lo - ne, self.hi - ne)), self.height_m + o[2])

    def line_of_sight_blocked(
        self, p_ned_m: np.ndarray, azimuth_rad: np.ndarray, elevation_rad: np.ndarray
    ) -> np.ndarray:
        """(K, n) True where a roof hides the satellite at ``azimuth_rad``, ``elevation_rad`` (n,)
        from the position(s) ``p_ned_m`` ((3,) or (K, 3), NED: height ``−p_d``): the slab test of
        the module doc. A ray touching a wall or a corner enters the box; a satellite at or below
        the horizon (el ≤ 0) is blocked by any box its ray crosses."""
        p = np.atleast_2d(np.asarray(p_ned_m, dtype=float))
        az = np.asarray(azimuth_rad, dtype=float).ravel()
        el = np.asarray(elevation_rad, dtype=float).ravel()
        k, n = len(p), len(az)
        if not len(self.height_m) or not n:
            return np.zeros((k, n), dtype=bool)
        dirs = np.tile(np.column_stack((np.cos(az), np.sin(az))), (k, 1))
        origins = np.repeat(p[:, 0:2], n, axis=0)
        t_in, hit = self._entry(origins, dirs, None, None)
        ray_h = np.repeat(-p[:, 2], n)[:, None] + t_in * np.tile(np.tan(el), k)[:, None]
        return (hit & (self.height_m[None] > ray_h)).any(axis=1).reshape(k, n)

    def trace(
        self,
        origin_ne: np.ndarray,
        h_m: np.ndarray,
        dir_ne: np.ndarray,
        tan_el: np.ndarray,
        wavelength_m: float,
    ) -> RayTrace:
        """Rays from ``origin_ne`` (K, 2) at height ``h_m`` (K,) along the horizontal unit
        directions ``dir_ne`` (K, 2), rising ``tan_el`` (K,) per metre: blocked, and the dominant
        roof edge for diffraction."""
        k = len(origin_ne)
        if not len(self.height_m):
            inf = np.full(k, -np.inf)
            return RayTrace(np.zeros(k, bool), inf, np.full(k, np.nan), inf)
        t_in, hit = self._entry(origin_ne, dir_ne, None, None)
        return self._edges(t_in, hit, h_m, tan_el, wavelength_m)

    def _edges(
        self,
        t_in: np.ndarray,
        hit: np.ndarray,
        h_m: np.ndarray | float,
        tan_el: np.ndarray,
        wavelength_m: float,
    ) -> RayTrace:
        over = self.height_m[None] - (np.reshape(h_m, (-1, 1)) + t_in * tan_el[:, None])  # roof above the ray
        cos_el = (1.0 / np.sqrt(1.0 + tan_el * tan_el))[:, None]
        dist = np.maximum(t_in / cos_el, 0.1)
        # the edge's distance from the ray, perpendicular to it: the vertical offset × cos(el)
        nu = np.where(hit, over * cos_el * np.sqrt(2.0 / wavelength_m / dist), -np.inf)
        j = np.argmax(nu, axis=1)
        rows = np.arange(len(t_in))
        nu_j = nu[rows, j]
        return RayTrace(nu_j > 0.0, nu_j, dist[rows, j], over[rows, j])

    def paths(
        self, p_ne: np.ndarray, h_m: float, dir_ne: np.ndarray, tan_el: np.ndarray, wavelength_m: float
    ) -> tuple[RayTrace, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
        """The direct paths of satellites (S,) (horizontal unit directions ``dir_ne`` (S, 2), slopes
        ``tan_el``) to the receiver at ``p_ne`` (2,), height ``h_m`` (:meth:`trace`), and every valid
        specular facade reflection ``(satellite (R,), facade (R,), extra path m (R,), cos of the
        incidence angle u·n (R,))``; all rays in one slab test."""
        f = self.facades
        p = np.asarray(p_ne, dtype=float)
        n_s = len(dir_ne)
        empty = (np.zeros(0, int), np.zeros(0, int), np.zeros(0), np.zeros(0))
        if not len(self.height_m):
            return self.trace(
                np.broadcast_to(p, (n_s, 2)), np.full(n_s, h_m), dir_ne, tan_el, wavelength_m
            ), empty
        dist = f.sign * (p[f.axis] - f.coord)  # receiver in front of the plane (W,)
        u_axis = dir_ne[:, f.axis] * f.sign[None]  # (S, W): > 0 the satellite is in front
        s_idx, w_idx = np.nonzero((dist[None] > 0.0) & (u_axis > 1e-9))
        run = dist[w_idx] / u_axis[s_idx, w_idx]  # horizontal run to the plane along the mirrored direction
        other = 1 - f.axis[w_idx]
        q_other = p[other] + dir_ne[s_idx, other] * run
        tan = tan_el[s_idx]
        q_h = h_m + run * tan
        on = (q_other >= f.lo[w_idx]) & (q_other <= f.hi[w_idx]) & (q_h <= f.height_m[w_idx])
        s_idx, w_idx, run, q_other, q_h, tan = s_idx[on], w_idx[on], run[on], q_other[on], q_h[on], tan[on]
        k = len(s_idx)
        rows = np.arange(k)
        axis = f.axis[w_idx]
        d_in = dir_ne[s_idx].copy()  # the arriving direction, mirrored (toward the facade)
        d_in[rows, axis] *= -1.0
        q = np.empty((k, 2))
        q[rows, axis] = f.coord[w_idx] + f.sign[w_idx] * NUDGE_M
        q[rows, 1 - axis] = q_other
        b = f.building[w_idx]
        # one slab test: the direct rays, receiver -> facade legs (up to the facade), facade -> satellite legs
        origins = np.concatenate((np.broadcast_to(p, (n_s + k, 2)), q))
        dirs = np.concatenate((dir_ne, d_in, dir_ne[s_idx]))
        tans = np.concatenate((tan_el, tan, tan))
        h0 = np.concatenate((np.full(n_s + k, h_m), q_h))
        run_max = np.concatenate((np.full(n_s, np.inf), run, np.full(k, np.inf)))
        skip = np.concatenate((np.full(n_s, -1), b, b))
        t_in, hit = self._entry(origins, dirs, run_max, skip)
        direct = self._edges(t_in[:n_s], hit[:n_s], h_m, tan_el, wavelength_m)
        legs = (hit[n_s:] & (self.height_m[None] > h0[n_s:, None] + t_in[n_s:] * tans[n_s:, None])).any(
            axis=1
        )
        ok = ~legs[:k] & ~legs[k:]
        cos_el = 1.0 / np.sqrt(1.0 + tan[ok] ** 2)
        u_n = dir_ne[s_idx[ok], axis[ok]] * f.sign[w_idx[ok]] * cos_el
        return direct, (s_idx[ok], w_idx[ok], 2.0 * dist[w_idx[ok]] * u_n, u_n)

    def reflections(
        self, p_ne: np.ndarray, h_m: float, dir_ne: np.ndarray, tan_el: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The reflections of :meth:`paths` alone."""
        return self.paths(p_ne, h_m, dir_ne, tan_el, 0.19)[1]


def diffraction_extra_m(
    edge_distance_m: np.ndarray, edge_over_m: np.ndarray, sin_el: np.ndarray
) -> np.ndarray:
    """Extra length (m) of the path bent over an edge ``Δh`` above the straight ray at slant
    distance ``d`` (toward a satellite at infinity, elevation ``el``): with the edge at
    ``d u + Δh z``, ``|d u + Δh z| − u·(d u + Δh z)`` (≈ Δh² cos² el / 2d); 0 when the ray clears it."""
    d = np.where(np.isfinite(edge_distance_m), edge_distance_m, 1.0)
    over = np.where(edge_over_m > 0.0, edge_over_m, 0.0)
    return np.sqrt(d * d + 2.0 * d * over * sin_el + over * over) - d - over * sin_el
