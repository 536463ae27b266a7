"""Satellite states evaluated once per ``period_s`` and carried in between (the tight filter's speed).

Broadcast orbits cost 150-260 µs per epoch to evaluate (``beliefnav bench gnss``). Over a second a
satellite's motion in the Earth-fixed frame is a smooth curve: from the state at the anchor time
``t_a = round(t / period) · period`` (evaluated once) the state at t is carried by a second-order
step with the ECEF acceleration of a point mass in the rotating frame,

    a = −μ r / |r|³ − 2 ω × v − ω × (ω × r)

so the error is the third-order term (jerk ≈ μ v / r³ ≈ 1e-4 m/s³: < 0.01 mm at 0.5 s; the J2 and
luni-solar accelerations left out of a, ~1e-5 m/s² for GPS, add < 2 µm at 0.5 s; measured against
the full evaluation in the tests and by ``beliefnav bench tight``). The satellite clock is carried
linearly with its drift (the broadcast af2 is 0 in practice; the relativistic term, periodic over
12 h, changes its rate by < 1e-12 over a second: < 0.1 mm). Anchors are a function of t alone, so the
result does not depend on the order of queries (out-of-sequence fusion stays exact).

``SatelliteCache(store)`` has ``states(system, prn, t)`` like ``EphemerisStore``, so
``companion.gnss.transmission_states(cache, epoch)`` uses it unchanged.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from companion.gnss.constants import MU_GPS_M3_S2, OMEGA_E_RAD_S
from companion.gnss.ephemeris import SatStates

_W = np.array([0.0, 0.0, OMEGA_E_RAD_S])


def ecef_acceleration(pos_ecef_m: np.ndarray, vel_ecef_m_s: np.ndarray) -> np.ndarray:
    """Point-mass gravity plus Coriolis and centrifugal accelerations in the rotating frame (n, 3)."""
    r = np.linalg.norm(pos_ecef_m, axis=1)
    return (-MU_GPS_M3_S2 * pos_ecef_m / (r**3)[:, None] - 2.0 * np.cross(_W, vel_ecef_m_s)
            - np.cross(_W, np.cross(_W, pos_ecef_m)))


class SatelliteCache:
    """``states`` of an ephemeris store, evaluated at anchors ``period_s`` apart and carried between."""

    def __init__(self, store: Any, period_s: float = 1.0, keep_anchors: int = 8) -> None:
        if not period_s > 0:
            raise ValueError("period_s must be > 0")
        self.store = store
        self.period_s = float(period_s)
        self.keep_anchors = keep_anchors
        # (key, anchor index) -> (pos, vel, acc, clock, drift, valid)
        self._anchors: dict[tuple[int, int], tuple[np.ndarray, np.ndarray, np.ndarray, float, float, bool]] = {}
        self.evaluations = 0  # satellite states computed by the store (for the benchmark)

    def states(self, system: np.ndarray, prn: np.ndarray, t_gps_s: np.ndarray) -> SatStates:
        system = np.asarray(system, dtype=np.int64)
        prn = np.asarray(prn, dtype=np.int64)
        t = np.asarray(t_gps_s, dtype=float) * np.ones(len(system))
        finite = np.isfinite(t)
        if not finite.all():  # no time (no pseudorange): no state
            out = self.states(system[finite], prn[finite], t[finite])
            n = len(t)
            pos, vel = np.full((n, 3), np.nan), np.full((n, 3), np.nan)
            clk, drift = np.full(n, np.nan), np.full(n, np.nan)
            pos[finite], vel[finite], clk[finite], drift[finite] = out[0], out[1], out[2], out[3]
            return SatStates(pos, vel, clk, drift, finite & np.isin(np.arange(n), np.flatnonzero(finite)[out.valid]))
        k = np.round(t / self.period_s).astype(np.int64)
        keys = (system * 1000 + prn).tolist()
        anchors = self._anchors
        missing = [i for i, (key, a) in enumerate(zip(keys, k.tolist(), strict=True)) if (key, a) not in anchors]
        if missing:
            mi = np.array(missing)
            ta = k[mi] * self.period_s
            s = self.store.states(system[mi], prn[mi], ta)
            self.evaluations += len(mi)
            acc = ecef_acceleration(s.pos_ecef_m, s.vel_ecef_m_s)
            for j, i in enumerate(missing):
                anchors[(keys[i], int(k[i]))] = (s.pos_ecef_m[j], s.vel_ecef_m_s[j], acc[j], float(s.clock_s[j]),
                                                 float(s.clock_drift_s_s[j]), bool(s.valid[j]))
            newest = int(k.max())
            if len(anchors) > 64 * self.keep_anchors:
                for old in [a for a in anchors if a[1] < newest - self.keep_anchors]:
                    del anchors[old]
        rows = [anchors[(key, a)] for key, a in zip(keys, k.tolist(), strict=True)]
        pos0 = np.array([r[0] for r in rows]).reshape(-1, 3)
        vel0 = np.array([r[1] for r in rows]).reshape(-1, 3)
        acc0 = np.array([r[2] for r in rows]).reshape(-1, 3)
        clk0 = np.array([r[3] for r in rows])
        drift = np.array([r[4] for r in rows])
        valid = np.array([r[5] for r in rows], dtype=bool)
        dt = (t - k * self.period_s)[:, None]
        pos = pos0 + vel0 * dt + 0.5 * acc0 * dt * dt
        vel = vel0 + acc0 * dt
        return SatStates(pos, vel, clk0 + drift * dt[:, 0], drift, valid)
