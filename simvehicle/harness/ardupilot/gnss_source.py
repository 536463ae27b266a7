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

Velocity (``velocity_sigma_m_s`` set): our model has no Doppler, so each fix carries ArduPilot's
TRUE velocity at its validity time plus white noise of that std per axis (a separate seeded
generator, so the positions are the same draws with or without it). Multipath barely biases a
receiver's Doppler, which this mirrors; it is stated wherever the figures are.
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
from simvehicle.harness.ardupilot.config import GPS1_ID, GPS_INPUT_IGNORE_VELOCITY, GPS_WEEK


@dataclass(frozen=True, slots=True)
class SentFix:
    """One fix as sent: when it was released and what it says (geodetic and in the mission frame)."""

    arrival_us: int
    fix: GnssFix  # t_validity_us, geodetic position, accuracies
    p_ned_m: np.ndarray
    v_ned_m_s: np.ndarray | None = None  # Doppler velocity (truth + noise), None: position only
    speed_accuracy_m_s: float = float("nan")  # the velocity's 1σ as GPS_INPUT reports it (NaN: none)


@dataclass(frozen=True, slots=True)
class TruthGnss:
    """The model's state at a truth sample (for the time series: true bias, latency, clearance)."""

    bias_ned_m: np.ndarray
    latency_s: float
    clearance_m: float


class UrbanGnssSource:
    """Samples our GNSS model at ``rate_hz`` on an external truth stream; releases fixes late."""

    def __init__(self, cfg: GnssConfig, world: World, frame: LocalNedFrame, rate_hz: float,
                 rng: np.random.Generator, clearance0_m: float, velocity_sigma_m_s: float | None = None,
                 velocity_rng: np.random.Generator | None = None) -> None:
        self.world = world
        self.period_us = round(1e6 / rate_hz)
        self.model = GnssModel(cfg, 1.0 / rate_hz, frame, rng, clearance0_m)
        self._next_us: int | None = None
        self.sent: list[SentFix] = []
        if velocity_sigma_m_s is not None and velocity_rng is None:
            raise ValueError("a velocity needs its own seeded generator")
        self.velocity_sigma_m_s = velocity_sigma_m_s
        self._velocity_rng = velocity_rng
        self._velocity: dict[int, np.ndarray] = {}  # validity time -> measured velocity, until released

    def clearance_m(self, p_ned_m: np.ndarray) -> float:
        return float(self.world.clearance_m(float(p_ned_m[0]), float(p_ned_m[1])))

    def on_truth(self, t_us: int, p_ned_m: np.ndarray, v_ned_m_s: np.ndarray | None = None) -> TruthGnss:
        """Feed one truth sample; samples a fix when a period has started. Returns the model state."""
        d = self.clearance_m(p_ned_m)
        if self._next_us is None:
            self._next_us = t_us
        if t_us >= self._next_us:
            self.model.sample(t_us, p_ned_m, d)
            if self.velocity_sigma_m_s is not None and self._velocity_rng is not None:
                if v_ned_m_s is None:
                    raise ValueError("a velocity-measuring source needs the true velocity")
                noise = self._velocity_rng.normal(0.0, self.velocity_sigma_m_s, 3)
                self._velocity[t_us] = np.asarray(v_ned_m_s, dtype=float) + noise
            # next period boundary after t_us (truth arrives at a rate that need not divide ours)
            self._next_us += self.period_us * max(1, math.ceil((t_us + 1 - self._next_us) / self.period_us))
        return TruthGnss(self.model.bias_ned_m.copy(), self.model.latency_s, d)

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



def gps_input_fields(sf: SentFix, gps_id: int = GPS1_ID,
                     velocity_sigma_m_s: float = 0.0) -> dict[str, float | int]:
    """GPS_INPUT fields (MAVLink common) for a fix: validity time as GPS time, to receiver ``gps_id``.

    Velocity (and ``speed_accuracy`` = ``velocity_sigma_m_s``) when the fix carries one; otherwise
    flagged as ignored.

    ``horiz_accuracy``/``vert_accuracy`` carry the model's reported accuracy (the white-noise std,
    not the bias: what a receiver that cannot see its multipath reports; EKF3 floors it at
    EK3_POSNE_M_NSE). HDOP/VDOP are 1.0 (good geometry): EKF3 uses the accuracies when present.
    """
    fix, v = sf.fix, sf.v_ned_m_s
    acc = fix.h_acc_m if math.isfinite(fix.h_acc_m) else 1.0
    vacc = fix.v_acc_m if math.isfinite(fix.v_acc_m) else 1.5
    t_ms = fix.t_validity_us // 1000
    return {
        "time_usec": int(fix.t_validity_us),
        "gps_id": gps_id,
        "ignore_flags": GPS_INPUT_IGNORE_VELOCITY if v is None else 0,
        "time_week_ms": int(t_ms),
        "time_week": GPS_WEEK,
        "fix_type": int(fix.fix_type),
        "lat": round(fix.lat_deg * 1e7),
        "lon": round(fix.lon_deg * 1e7),
        "alt": float(fix.alt_m),
        "hdop": 1.0,
        "vdop": 1.0,
        "vn": 0.0 if v is None else float(v[0]),
        "ve": 0.0 if v is None else float(v[1]),
        "vd": 0.0 if v is None else float(v[2]),
        "speed_accuracy": 0.0 if v is None else float(velocity_sigma_m_s),
        "horiz_accuracy": float(acc),
        "vert_accuracy": float(vacc),
        "satellites_visible": int(fix.satellites_visible),
        "yaw": 0,
    }
