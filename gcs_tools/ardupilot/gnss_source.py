"""GNSS source for ArduPilot: our urban degradation model driven by ArduPilot's truth -> GPS_INPUT.

Pure core, no I/O. ``UrbanGnssSource.on_truth(t_us, p_ned_m)`` is called with every SIM_STATE
(truth, stamped with ArduPilot's boot time): on the first truth at or after each fix period it
samples one fix of ``simvehicle.gnss.GnssModel`` (clearance-dependent multipath bias, noise and
latency, seeded) VALID at that time, and queues it; ``due(t_us)`` releases the fixes whose
modelled latency has elapsed, as the GPS_INPUT fields to send now. The same fixes (validity
time, position) are kept for the companion, so EKF3 and every companion method see identical
GNSS.

Timing on the wire: ``time_week_ms`` carries the fix's validity time (ArduPilot boot ms on a
fixed GPS week), as a receiver stamps its measurement epoch; ArduPilot's MAVLink GPS driver
(AP_GPS_MAV) uses it only through its jitter correction against the arrival time, and EKF3 then
assumes the fix is ``GPS1_DELAY_MS`` old. The modelled latency varies (0.1 s in open sky, up to
1.2 s in canyons); a constant delay is all EKF3 can assume. The companion fuses each fix at its
validity time (Algorithm 1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from companion.domain.geodesy import LocalNedFrame
from companion.domain.samples import GnssFix
from companion.mission.world import World
from gcs_tools.ardupilot.config import GPS_INPUT_IGNORE_VELOCITY, GPS_WEEK
from simvehicle.config import GnssConfig
from simvehicle.gnss import GnssModel, NedFix


@dataclass(frozen=True, slots=True)
class SentFix:
    """One fix as sent: when it was released and what it says (geodetic and in the mission frame)."""

    arrival_us: int
    fix: GnssFix  # t_validity_us, geodetic position, accuracies
    p_ned_m: np.ndarray


@dataclass(frozen=True, slots=True)
class TruthGnss:
    """The model's state at a truth sample (for the time series: true bias, latency, clearance)."""

    bias_ned_m: np.ndarray
    latency_s: float
    clearance_m: float


class UrbanGnssSource:
    """Samples our GNSS model at ``rate_hz`` on an external truth stream; releases fixes late."""

    def __init__(self, cfg: GnssConfig, world: World, frame: LocalNedFrame, rate_hz: float,
                 rng: np.random.Generator, clearance0_m: float) -> None:
        self.world = world
        self.period_us = round(1e6 / rate_hz)
        self.model = GnssModel(cfg, 1.0 / rate_hz, frame, rng, clearance0_m)
        self._next_us: int | None = None
        self.sent: list[SentFix] = []

    def clearance_m(self, p_ned_m: np.ndarray) -> float:
        return float(self.world.clearance_m(float(p_ned_m[0]), float(p_ned_m[1])))

    def on_truth(self, t_us: int, p_ned_m: np.ndarray) -> TruthGnss:
        """Feed one truth sample; samples a fix when a period has started. Returns the model state."""
        d = self.clearance_m(p_ned_m)
        if self._next_us is None:
            self._next_us = t_us
        if t_us >= self._next_us:
            self.model.sample(t_us, p_ned_m, d)
            # next period boundary after t_us (truth arrives at a rate that need not divide ours)
            self._next_us += self.period_us * max(1, math.ceil((t_us + 1 - self._next_us) / self.period_us))
        return TruthGnss(self.model.bias_ned_m.copy(), self.model.latency_s, d)

    def due(self, t_us: int) -> list[SentFix]:
        """Fixes whose latency has elapsed by ``t_us`` (release order); remembered in ``sent``."""
        out = []
        for nf in self.model.release(t_us):
            sf = SentFix(t_us, self.model.to_fix(nf), nf.p_ned_m)
            self.sent.append(sf)
            out.append(sf)
        return out

    @staticmethod
    def ned_fix(sf: SentFix) -> NedFix:
        return NedFix(sf.fix.t_validity_us, sf.p_ned_m, sf.fix.h_acc_m, sf.fix.satellites_visible)


def gps_input_fields(fix: GnssFix) -> dict[str, float | int]:
    """GPS_INPUT fields (MAVLink common) for a fix: validity time as GPS time, no velocity.

    ``horiz_accuracy``/``vert_accuracy`` carry the model's reported accuracy (the white-noise std,
    not the bias: what a receiver that cannot see its multipath reports; EKF3 floors it at
    EK3_POSNE_M_NSE). HDOP/VDOP are 1.0 (good geometry): EKF3 uses the accuracies when present.
    """
    acc = fix.h_acc_m if math.isfinite(fix.h_acc_m) else 1.0
    vacc = fix.v_acc_m if math.isfinite(fix.v_acc_m) else 1.5
    t_ms = fix.t_validity_us // 1000
    return {
        "time_usec": int(fix.t_validity_us),
        "gps_id": 0,
        "ignore_flags": GPS_INPUT_IGNORE_VELOCITY,
        "time_week_ms": int(t_ms),
        "time_week": GPS_WEEK,
        "fix_type": int(fix.fix_type),
        "lat": round(fix.lat_deg * 1e7),
        "lon": round(fix.lon_deg * 1e7),
        "alt": float(fix.alt_m),
        "hdop": 1.0,
        "vdop": 1.0,
        "vn": 0.0,
        "ve": 0.0,
        "vd": 0.0,
        "speed_accuracy": 0.0,
        "horiz_accuracy": float(acc),
        "vert_accuracy": float(vacc),
        "satellites_visible": int(fix.satellites_visible),
        "yaw": 0,
    }
