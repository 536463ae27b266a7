"""GNSS effects the estimator does not model: NLOS reflections, satellite geometry, heavy tails.

A fixed constellation (azimuths uniform, elevations uniform between the mask and 85°) is drawn
once per flight. At each fix, from the true position:

* **line of sight** (exact, in the 2-D-plus-heights city, ``companion.mission.city3d``): the
  horizontal ray toward a satellite enters building ``k`` at distance ``t_k`` (slab test); the
  satellite is blocked when the roof is above the ray there, ``height_k > h + t_k tan(elevation)``,
  with ``h`` the height above home;
* **NLOS**: a satellite that becomes blocked is, with probability ``nlos_reflect_prob``, tracked
  by a reflection whose extra path ``δ`` (exponential, mean ``nlos_delay_mean_m``) is drawn once
  for that blocked episode, so the fix STEPS when a building cuts the line of sight; otherwise
  it is lost. With fewer than 5 satellites left, the lost ones are taken back as reflections
  (a receiver uses what it gets);
* the **position error** of those pseudorange errors is the least-squares solution's:
  ``Δx = [(GᵀG)⁻¹ Gᵀ δ]_{0:3}``, rows of ``G`` = ``[−u_i, 1]`` (``u_i`` unit vector to satellite
  ``i``, NED) over the satellites used;
* **satellite-dependent noise** (``satellite_noise``): the white-noise std scales by
  ``PDOP(used) / PDOP(all)`` (fewer satellites, worse geometry);
* **heavy tails** (``heavy_tail_dof = ν > 2``): the white-noise vector of a fix is multiplied by
  ``sqrt((ν − 2) / χ²_ν)``: multivariate Student-t with the same covariance.

Its own seeded generator: the eq. 22-27 stream of ``GnssModel`` is untouched. The draws do not
depend on the path flown (common random numbers): each satellite draws its blocked episodes'
(tracked, delay) pairs from its own stream, the k-th episode of satellite i always the same pair,
and the heavy tail draws one number per fix from another. Two estimators flying the same seed
along slightly different paths therefore meet the same reflections, so a paired comparison of
the two measures the estimators, not which reflections a random stream happened to hand out
(with one shared stream, a satellite blocked one fix earlier shifted every later draw).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from companion.mission.city3d import City
from simvehicle.config import GnssConfig

MIN_SATELLITES = 5


@dataclass(frozen=True, slots=True)
class Unmodelled:
    """The unmodelled part of one fix."""

    offset_ned_m: np.ndarray  # NLOS position error (m)
    noise_scale: float  # multiplies the white-noise vector (geometry × heavy tail)
    sigma_scale: float  # geometry part only: what the receiver reports in its accuracy
    satellites: int  # satellites used (LOS + reflections)
    nlos: int  # of which reflections


class Constellation:
    """Satellite directions and the line-of-sight test against the city's buildings."""

    def __init__(self, cfg: GnssConfig, rects_m: np.ndarray, heights_m: np.ndarray,
                 rng: np.random.Generator) -> None:
        n = cfg.constellation_size
        self.azimuth_rad = rng.uniform(0.0, 2.0 * math.pi, n)
        self.elevation_rad = np.radians(rng.uniform(cfg.elevation_min_deg, 85.0, n))
        ce = np.cos(self.elevation_rad)
        self.u_ned = np.column_stack([ce * np.cos(self.azimuth_rad), ce * np.sin(self.azimuth_rad),
                                      -np.sin(self.elevation_rad)])
        self.city = City(rects_m, heights_m)

    def blocked(self, p_ned_m: np.ndarray) -> np.ndarray:
        """(S,) True where a building blocks the line of sight from ``p_ned_m``
        (``City.line_of_sight_blocked``)."""
        return self.city.line_of_sight_blocked(np.asarray(p_ned_m, dtype=float), self.azimuth_rad,
                                               self.elevation_rad)[0]


def position_error(u_ned: np.ndarray, used: np.ndarray, delay_m: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares position error (NED, m) of pseudorange errors ``delay_m`` on the ``used``
    satellites, and the PDOP of that set."""
    G = np.column_stack([-u_ned[used], np.ones(int(used.sum()))])
    inv = np.linalg.inv(G.T @ G)
    dx = inv @ G.T @ delay_m[used]
    return dx[:3], float(math.sqrt(max(0.0, float(np.trace(inv[:3, :3])))))


class UnmodelledGnss:
    """Per-fix NLOS offset and noise scaling (seeded; state: the blocked episodes)."""

    def __init__(self, cfg: GnssConfig, rects_m: np.ndarray, heights_m: np.ndarray,
                 rng: np.random.Generator) -> None:
        self.cfg = cfg
        self.sky = Constellation(cfg, rects_m, heights_m, rng)
        n = cfg.constellation_size
        streams = rng.spawn(n + 1)  # common random numbers: one stream per satellite, one for the tails
        self._episode_rngs = streams[:n]
        self._tail_rng = streams[n]
        self._blocked = np.zeros(n, dtype=bool)
        self._tracked = np.zeros(n, dtype=bool)  # a blocked satellite tracked by its reflection
        self._delay_m = np.zeros(n)
        self.pdop_all = position_error(self.sky.u_ned, np.ones(n, dtype=bool), np.zeros(n))[1]

    def step(self, p_ned_m: np.ndarray) -> Unmodelled:
        cfg = self.cfg
        sees = cfg.nlos or cfg.satellite_noise
        blocked = self.sky.blocked(p_ned_m) if sees else np.zeros_like(self._blocked)
        fresh = blocked & ~self._blocked
        if cfg.nlos:
            for i in np.flatnonzero(fresh).tolist():  # each satellite's next episode, from its own stream
                g = self._episode_rngs[i]
                self._tracked[i] = g.uniform() < cfg.nlos_reflect_prob
                self._delay_m[i] = g.exponential(cfg.nlos_delay_mean_m)
        self._tracked[~blocked] = False
        self._delay_m[~blocked] = 0.0
        self._blocked = blocked
        used = ~blocked | self._tracked
        if used.sum() < MIN_SATELLITES:
            used = np.ones_like(used)  # take the lost ones back as reflections
        delay = np.where(blocked, self._delay_m, 0.0)  # zero without nlos: a lost satellite is just lost
        offset, pdop = position_error(self.sky.u_ned, used, delay)
        sigma_scale = pdop / self.pdop_all if cfg.satellite_noise else 1.0
        tail = 1.0
        if cfg.heavy_tail_dof > 0.0:
            nu = cfg.heavy_tail_dof
            tail = math.sqrt((nu - 2.0) / float(self._tail_rng.chisquare(nu)))
        n_nlos = int((used & blocked).sum())
        return Unmodelled(offset, sigma_scale * tail, sigma_scale, int(used.sum()), n_nlos)
