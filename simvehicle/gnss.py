"""GNSS degradation (eq. 22-27) and the delivery queue that makes fixes arrive late.

One fix per control period, valid at its sampling time ``t_validity_us``:

* ``d`` = exact clearance to the nearest building (eq. 22), proximity weight
  ``w(d) = clip((d_near - d) / ramp, 0, 1)`` (see ``GnssConfig``);
* multipath bias, first-order Gauss-Markov (eq. 23-26):
  ``b ← κ b + σ_ss(w) sqrt(1 - κ²) n``, ``κ = exp(-Δt / Γ(w))`` so that ``σ_ss`` is the
  stationary std and Γ the correlation time at a fixed place;
* white noise with variance ``σ² m``, ``m = 1 + (r_urban - 1) w``;
* latency (eq. 27): ``L ← clip(ζ L + (1 - ζ) L̄(w) + Υ, 0, cap)``, ``ζ = exp(-Δt / τ)``,
  ``Υ ~ N(0, σ_L²)``.

The fix is queued (in local NED, ``NedFix``; ``to_fix`` gives the geodetic wire form) and released
at the first physics tick at or after ``t_validity + L``, so
consecutive fixes can overtake each other when the latency drops quickly.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass
from typing import Generic, TypeVar

import numpy as np

from companion.domain.geodesy import LocalNedFrame
from companion.domain.samples import GnssFix
from simvehicle.config import GnssConfig
from simvehicle.nlos import UnmodelledGnss
from simvehicle.noise import NormalBlocks

FIX_TYPE_3D = 3


@dataclass(frozen=True, slots=True)
class NedFix:
    """A fix in the mission's local NED frame (what in-process consumers fuse); ``GnssModel.to_fix``
    gives its wire form."""

    t_validity_us: int
    p_ned_m: np.ndarray  # true position + bias + white noise
    sigma_noise_m: float  # white-noise std in force
    satellites: int
    v_ned_m_s: np.ndarray | None = None  # the receiver's Doppler velocity (None: the receiver gives none)
    sigma_velocity_m_s: float = float("nan")  # its noise std per axis in force


@dataclass(frozen=True, slots=True)
class GnssConditions:
    """Model parameters at one place (function of the clearance only)."""

    weight: float  # proximity weight w(d) in [0, 1]
    gamma_s: float  # bias correlation time Γ
    sigma_bias_m: float  # stationary bias std σ_ss
    sigma_noise_m: float  # white-noise std (inflated by r_urban)
    latency_mean_s: float  # L̄
    satellites: int


def conditions(cfg: GnssConfig, clearance_m: float) -> GnssConditions:
    """Eq. 25-26 and L̄ blended by the proximity weight."""
    w = min(1.0, max(0.0, (cfg.d_near_m - clearance_m) / cfg.proximity_ramp_m))
    return GnssConditions(
        weight=w,
        gamma_s=cfg.gamma_open_s + (cfg.gamma_canyon_s - cfg.gamma_open_s) * w,
        sigma_bias_m=cfg.sigma_bias_open_m + (cfg.sigma_bias_max_m - cfg.sigma_bias_open_m) * w,
        sigma_noise_m=cfg.sigma_noise_m * math.sqrt(1.0 + (cfg.r_urban - 1.0) * w),
        latency_mean_s=cfg.latency_open_s + (cfg.latency_canyon_s - cfg.latency_open_s) * w,
        satellites=round(cfg.satellites_open + (cfg.satellites_canyon - cfg.satellites_open) * w),
    )


class NedToGeodetic:
    """Local NED -> geodetic for ``frame``: the library's forward map (geodetic -> NED), inverted by Newton.

    ``pymap3d.ned2geodetic`` costs ~150 µs per call, ``geodetic2ned`` ~12 µs. With the Jacobian at
    home (central differences of the library map), one correction of the linear guess leaves
    < 0.1 mm within ``one_step_range_m`` of home (tested; degE7 is ~1 cm); farther away it
    iterates until the library map reproduces ``p`` to ``tol_m``.
    """

    def __init__(self, frame: LocalNedFrame, tol_m: float = 1e-6, one_step_range_m: float = 1000.0) -> None:
        self.frame = frame
        self.tol_m = tol_m
        self.one_step_range_m = one_step_range_m
        self._home = np.array([frame.home_lat_deg, frame.home_lon_deg, frame.home_alt_m])
        steps = np.array([1e-5, 1e-5, 1.0])
        cols = [
            (frame.to_ned_m(*(self._home + h)) - frame.to_ned_m(*(self._home - h))) / (2 * h[i])
            for i, h in enumerate(np.diag(steps))
        ]
        self._J_inv = np.linalg.inv(np.column_stack(cols))

    def __call__(self, p_ned_m: np.ndarray) -> tuple[float, float, float]:
        g = self._home + self._J_inv @ p_ned_m
        g = g - self._J_inv @ (self.frame.to_ned_m(*g.tolist()) - p_ned_m)
        if abs(p_ned_m).max() > self.one_step_range_m:
            for _ in range(6):
                r = self.frame.to_ned_m(*g.tolist()) - p_ned_m
                if abs(r).max() <= self.tol_m:
                    break
                g = g - self._J_inv @ r
        return float(g[0]), float(g[1]), float(g[2])


T = TypeVar("T")


class ReleaseQueue(Generic[T]):
    """A receiver's delivery queue: items released at their time, in order of release time (ties: in
    order of queueing)."""

    def __init__(self) -> None:
        self._heap: list[tuple[int, int, T]] = []
        self._n = 0  # items queued (the tie-break)

    def put(self, release_us: int, item: T) -> None:
        heapq.heappush(self._heap, (release_us, self._n, item))
        self._n += 1

    def due(self, t_us: int) -> list[T]:
        """The items whose release time is ``t_us`` or before, taken out of the queue."""
        out = []
        q = self._heap
        while q and q[0][0] <= t_us:
            out.append(heapq.heappop(q)[2])
        return out

    @property
    def next_release_us(self) -> int | float:
        """Release time of the next queued item (inf when none is queued)."""
        return self._heap[0][0] if self._heap else math.inf

    def __len__(self) -> int:
        return len(self._heap)


class QueuedDelivery(Generic[T]):
    """What a receiver model with a delivery queue (``_queue``) shows the vehicle."""

    _queue: ReleaseQueue[T]

    @property
    def next_release_us(self) -> int | float:
        """Release time of the next queued item (inf when none is queued)."""
        return self._queue.next_release_us

    @property
    def pending(self) -> int:
        """Items queued and not yet released."""
        return len(self._queue)


class GnssModel(QueuedDelivery[NedFix]):
    """Bias and latency processes plus the delivery queue (seeded, deterministic)."""

    def __init__(self, cfg: GnssConfig, period_s: float, frame: LocalNedFrame, rng: np.random.Generator,
                 clearance0_m: float, unmodelled: UnmodelledGnss | None = None,
                 velocity_rng: np.random.Generator | None = None) -> None:
        self.cfg = cfg
        # the Doppler velocity's own stream (cfg.velocity), so the positions do not depend on it
        self._velocity_normals = (NormalBlocks(velocity_rng or np.random.default_rng(0)) if cfg.velocity
                                  else None)
        self.unmodelled = unmodelled  # effects beyond eq. 22-27 (simvehicle.nlos), own generator
        self.period_s = period_s
        self.to_geodetic = NedToGeodetic(frame)
        self._normals = NormalBlocks(rng)  # the stream of rng.standard_normal, drawn in blocks
        c0 = conditions(cfg, clearance0_m)
        self.bias_ned_m = c0.sigma_bias_m * self._normals.take(3)  # start in the stationary law
        self.latency_s = c0.latency_mean_s
        self._zeta = math.exp(-period_s / cfg.latency_tau_s)
        self._queue: ReleaseQueue[NedFix] = ReleaseQueue()
        self.sent = 0

    def step(self, clearance_m: float) -> GnssConditions:
        """Advance bias (eq. 23) and latency (eq. 27) by one fix period at clearance ``d``."""
        c = conditions(self.cfg, clearance_m)
        n0, n1, n2, n3 = self._normals.take(4).tolist()
        kappa = math.exp(-self.period_s / c.gamma_s)
        gain = c.sigma_bias_m * math.sqrt(1.0 - kappa * kappa)
        b0, b1, b2 = self.bias_ned_m.tolist()
        self.bias_ned_m = np.array([kappa * b0 + gain * n0, kappa * b1 + gain * n1, kappa * b2 + gain * n2])
        lat = self._zeta * self.latency_s + (1.0 - self._zeta) * c.latency_mean_s
        lat += self.cfg.latency_noise_s * n3
        self.latency_s = min(self.cfg.latency_cap_s, max(0.0, lat))
        return c

    def sample(self, t_validity_us: int, p_ned_m: np.ndarray, clearance_m: float,
               v_ned_m_s: np.ndarray | None = None) -> NedFix:
        """Make the fix valid at ``t_validity_us`` for true position ``p_ned_m`` (and velocity
        ``v_ned_m_s``, for a receiver with ``cfg.velocity``) and queue it."""
        c = self.step(clearance_m)
        s = c.sigma_noise_m
        m0, m1, m2 = self._normals.take(3).tolist()
        (p0, p1, p2), (b0, b1, b2) = p_ned_m.tolist(), self.bias_ned_m.tolist()
        if self.unmodelled is None:
            z_ned_m = np.array([p0 + b0 + s * m0, p1 + b1 + s * m1, p2 + b2 + s * m2])
            fix = NedFix(int(t_validity_us), z_ned_m, s, c.satellites)
        else:
            u = self.unmodelled.step(p_ned_m)
            k = s * u.noise_scale
            o0, o1, o2 = u.offset_ned_m.tolist()
            z_ned_m = np.array([p0 + b0 + o0 + k * m0, p1 + b1 + o1 + k * m1, p2 + b2 + o2 + k * m2])
            fix = NedFix(int(t_validity_us), z_ned_m, s * u.sigma_scale, u.satellites)
        if self._velocity_normals is not None and v_ned_m_s is not None:
            fix = self._with_velocity(fix, v_ned_m_s, c.weight)
        release_us = fix.t_validity_us + math.ceil(self.latency_s * 1e6 - 1e-6)
        self._queue.put(release_us, fix)
        self.sent += 1
        return fix

    def _with_velocity(self, fix: NedFix, v_ned_m_s: np.ndarray, weight: float) -> NedFix:
        """The fix with the receiver's Doppler velocity: white noise of std sqrt(σ_v² + (w κ |v|)²)
        per axis (GnssConfig: a reflection's error is a fraction of the speed)."""
        cfg = self.cfg
        assert self._velocity_normals is not None
        v0, v1, v2 = (float(x) for x in v_ned_m_s)
        k = weight * cfg.velocity_reflection_factor * math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
        s = math.sqrt(cfg.sigma_velocity_m_s**2 + k * k)
        n0, n1, n2 = self._velocity_normals.take(3).tolist()
        return NedFix(fix.t_validity_us, fix.p_ned_m, fix.sigma_noise_m, fix.satellites,
                      np.array([v0 + s * n0, v1 + s * n1, v2 + s * n2]), s)

    def reported_accuracy_m(self, fix: NedFix) -> float:
        """The 1σ accuracy the receiver reports for ``fix`` (h_acc = v_acc): the white-noise std in
        force, NaN when the mission's GNSS reports none."""
        return fix.sigma_noise_m if self.cfg.report_accuracy else float("nan")

    def reported_velocity_accuracy_m_s(self, fix: NedFix) -> float:
        """The 1σ speed accuracy the receiver reports for ``fix`` (NaN without report_accuracy)."""
        return fix.sigma_velocity_m_s if self.cfg.report_accuracy else float("nan")

    def reported_accuracies_m(self, fix: NedFix) -> tuple[float, float]:
        """(horizontal per axis, vertical) 1σ: both ``reported_accuracy_m``."""
        acc = self.reported_accuracy_m(fix)
        return acc, acc

    def to_fix(self, fix: NedFix) -> GnssFix:
        """The wire form of a fix: geodetic position (``frame``), fix type and accuracies."""
        lat, lon, alt = self.to_geodetic(fix.p_ned_m)
        acc = self.reported_accuracy_m(fix)
        vel_acc = self.reported_velocity_accuracy_m_s(fix)
        return GnssFix(
            t_validity_us=fix.t_validity_us,
            lat_deg=lat,
            lon_deg=lon,
            alt_m=alt,
            fix_type=FIX_TYPE_3D,
            satellites_visible=fix.satellites,
            h_acc_m=acc,
            v_acc_m=acc,
            v_ned_m_s=fix.v_ned_m_s,
            vel_acc_m_s=vel_acc,
        )

    def release(self, t_us: int) -> list[NedFix]:
        """Fixes whose latency has elapsed by ``t_us``, in order of release time."""
        return self._queue.due(t_us)
