"""GNSS for a foreign autopilot: our urban degradation model driven by the autopilot's truth.

Pure core, no I/O. ``UrbanGnssSource.on_truth(t_us, p_ned_m)`` is called with every truth sample
(ArduPilot's SIM_STATE, PX4 SIH's HIL_STATE_QUATERNION, stamped with the autopilot's boot time):
on the first truth at or after each fix period it samples one fix of ``simvehicle.gnss.GnssModel``
(clearance-dependent multipath bias, noise and latency, seeded) VALID at that time, and queues it;
``due(t_us)`` releases the fixes whose modelled latency has elapsed. The same fixes (validity
time, position) are kept for the companion, so the autopilot's EKF and every companion method
see identical GNSS. The wire form is the vehicle's: ``ardupilot.gnss_source.gps_input_fields``
(GPS_INPUT), ``px4.session.hil_gps_fields`` (HIL_GPS).

Velocity (``velocity_sigma_m_s`` set): our model has no Doppler, so each fix carries the
autopilot's TRUE velocity at its validity time plus white noise of that std per axis (a separate
seeded generator, so the positions are the same draws with or without it). Multipath barely
biases a receiver's Doppler, which this mirrors; it is stated wherever the figures are.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from companion.domain.geodesy import LocalNedFrame
from companion.domain.samples import GnssFix
from companion.mission.world import World
from simvehicle.config import GnssConfig
from simvehicle.gnss import GnssModel
from simvehicle.rawgnss import RawGnssModel

VELOCITY_SEED_STREAM = 1  # velocity noise: default_rng([seed, this]); positions: default_rng(seed)


@dataclass(frozen=True, slots=True)
class SentFix:
    """One fix as sent: when it was released and what it says (geodetic and in the mission frame)."""

    arrival_us: int
    fix: GnssFix  # t_validity_us, geodetic position, accuracies
    p_ned_m: np.ndarray
    v_ned_m_s: np.ndarray | None = None  # Doppler velocity (truth + noise), None: position only
    speed_accuracy_m_s: float = float("nan")  # the velocity's 1σ as the wire reports it (NaN: none)
    t_gps_s: float | None = None  # GPS time of the measurement (a raw receiver's); None: the wire's own clock


@dataclass(frozen=True, slots=True)
class TruthGnss:
    """The model's state at a truth sample (for the time series: true bias, latency, clearance)."""

    bias_ned_m: np.ndarray
    latency_s: float
    clearance_m: float


class GnssSource:
    """What both sources share (``UrbanGnssSource``, ``canyon_source.CanyonGnssSource``): a model
    sampled on the first truth at or after each period boundary (truth arrives at a rate that need
    not divide ours), and its state at every truth sample. A source adds ``_measure`` and ``due``."""

    model: GnssModel | RawGnssModel
    velocity_sigma_m_s: float | None = None  # the wire's speed accuracy (None: each fix carries its own)

    def __init__(self, world: World, period_us: int) -> None:
        self.world = world
        self.period_us = period_us
        self._next_us: int | None = None
        self.sent: list[SentFix] = []

    def clearance_m(self, p_ned_m: np.ndarray) -> float:
        return float(self.world.clearance_m(float(p_ned_m[0]), float(p_ned_m[1])))

    def on_truth(self, t_us: int, p_ned_m: np.ndarray, v_ned_m_s: np.ndarray | None = None) -> TruthGnss:
        """Feed one truth sample; measures when a period has started. Returns the model state."""
        d = self.clearance_m(p_ned_m)
        if self._next_us is None:
            self._next_us = t_us
        if t_us >= self._next_us:
            self._measure(t_us, p_ned_m, v_ned_m_s, d)
            self._next_us += self.period_us * max(1, math.ceil((t_us + 1 - self._next_us) / self.period_us))
        return TruthGnss(self.model.bias_ned_m.copy(), self.model.latency_s, d)

    def _measure(self, t_us: int, p_ned_m: np.ndarray, v_ned_m_s: np.ndarray | None,
                 clearance_m: float) -> None:  # pragma: no cover - each source's
        raise NotImplementedError

    def due(self, t_us: int) -> list[SentFix]:  # pragma: no cover - each source's
        """Fixes whose latency has elapsed by ``t_us`` (release order); remembered in ``sent``."""
        raise NotImplementedError


class UrbanGnssSource(GnssSource):
    """Samples our GNSS model at ``rate_hz`` on an external truth stream; releases fixes late."""

    def __init__(self, cfg: GnssConfig, world: World, frame: LocalNedFrame, rate_hz: float,
                 rng: np.random.Generator, clearance0_m: float, velocity_sigma_m_s: float | None = None,
                 velocity_rng: np.random.Generator | None = None) -> None:
        super().__init__(world, round(1e6 / rate_hz))
        self.model: GnssModel = GnssModel(cfg, 1.0 / rate_hz, frame, rng, clearance0_m)
        if velocity_sigma_m_s is not None and velocity_rng is None:
            raise ValueError("a velocity needs its own seeded generator")
        self.velocity_sigma_m_s = velocity_sigma_m_s
        self._velocity_rng = velocity_rng
        self._velocity: dict[int, np.ndarray] = {}  # validity time -> measured velocity, until released

    def _measure(self, t_us: int, p_ned_m: np.ndarray, v_ned_m_s: np.ndarray | None,
                 clearance_m: float) -> None:
        self.model.sample(t_us, p_ned_m, clearance_m)
        if self.velocity_sigma_m_s is not None and self._velocity_rng is not None:
            if v_ned_m_s is None:
                raise ValueError("a velocity-measuring source needs the true velocity")
            noise = self._velocity_rng.normal(0.0, self.velocity_sigma_m_s, 3)
            self._velocity[t_us] = np.asarray(v_ned_m_s, dtype=float) + noise

    def due(self, t_us: int) -> list[SentFix]:
        """Fixes whose latency has elapsed by ``t_us`` (release order); remembered in ``sent``."""
        out = []
        for nf in self.model.release(t_us):
            v = self._velocity.pop(nf.t_validity_us, None)
            acc = float("nan") if v is None else float(self.velocity_sigma_m_s or 0.0)
            sf = SentFix(t_us, self.model.to_fix(nf), nf.p_ned_m, v, acc)
            self.sent.append(sf)
            out.append(sf)
        return out
