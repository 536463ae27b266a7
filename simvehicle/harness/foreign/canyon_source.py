"""The calibrated canyon receiver for a foreign autopilot: per-satellite raw epochs and the receiver's
own single-point fix, from the autopilot's truth.

Pure core, no I/O. ``CanyonGnssSource`` offers what the sessions ask of
``gnss_source.UrbanGnssSource`` (``on_truth``, ``due``, ``sent``), with the canyon scenario's raw
receiver (``simvehicle.rawgnss.RawGnssModel``: line of sight, diffraction and facade reflections in
the mission's 3-D city, C/N0, tracking noise, receiver clock; calibrated against the smartLoc
Berlin drive) in place of the eq. 22-27 model. On the first truth at or after each receiver period
it measures one epoch at the TRUE position and velocity of that instant (the truth stream's time,
not a grid of its own: another simulator's truth decides when a measurement can be taken) and
solves it at once; ``latency_s`` later ``due`` releases the epoch and its fix together:

* the fix (``SentFix``) is the receiver's single-point solution with its own reported accuracies
  (horizontal, vertical, speed) and its Doppler velocity (``velocity=False``: position only), and
  the GPS time of its measurement (``t_gps_s``: a receiver stamps its fix with it; the autopilot's
  clock is set from it, and the companion maps the raw epochs to boot time through it);
* the raw epochs (``RawObservation``: pseudoranges, Doppler, C/N0, elevation per satellite, the
  receiver's report without satellite states, as RXM-RAWX carries them) are kept in ``raw`` in
  release order (the flight's record: the companion's tightly coupled rows are scored on them) and
  handed to ``raw_sink`` (the flight's UBX stream) as they are released.

An epoch the receiver cannot solve releases its raw epoch but no fix. Same seed and same truth
stream → the same observations and fixes, bit for bit.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from companion.domain.geodesy import LocalNedFrame
from companion.mission.world import World
from simvehicle.config import ReceiverConfig
from simvehicle.harness.foreign.gnss_source import GnssSource, SentFix
from simvehicle.rawgnss import RawGnssModel
from simvehicle.receiver import RawObservation


class CanyonGnssSource(GnssSource):
    """The raw receiver sampled on an external truth stream; epochs and fixes released late."""

    def __init__(self, cfg: ReceiverConfig, world: World, frame: LocalNedFrame, rng: np.random.Generator,
                 velocity: bool = True) -> None:
        super().__init__(world, round(1e6 / cfg.rate_hz))
        heights = np.array([b.height_m for b in world.config.buildings], dtype=float)
        self.model: RawGnssModel = RawGnssModel(cfg, world.rects_m, heights, frame, rng, self.period_us)
        self.velocity = velocity
        self.raw: list[RawObservation] = []
        self.raw_sink: Callable[[list[RawObservation]], None] | None = None

    def _measure(self, t_us: int, p_ned_m: np.ndarray, v_ned_m_s: np.ndarray | None,
                 clearance_m: float) -> None:
        self.model.measure(t_us, np.asarray(p_ned_m, dtype=float), v_ned_m_s)

    def due(self, t_us: int) -> list[SentFix]:
        """Fixes whose latency has elapsed by ``t_us`` (their raw epochs to ``raw`` and ``raw_sink``)."""
        model = self.model
        out = []
        for fix in model.release(t_us):
            wire = model.to_fix(fix)
            v = fix.v_ned_m_s if self.velocity else None
            acc = float(fix.sigma_velocity_m_s) if v is not None else math.nan
            sf = SentFix(t_us, wire, fix.p_ned_m, v, acc, model.t0_gps_s + fix.t_validity_us * 1e-6)
            self.sent.append(sf)
            out.append(sf)
        raws = model.drain_raw()
        if raws:
            self.raw += raws
            if self.raw_sink is not None:
                self.raw_sink(raws)
        return out
