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

from companion.gnss.atmosphere import iono_frequency_scale, klobuchar_m, saastamoinen_m
from companion.gnss.constants import MU_GPS_M3_S2, OMEGA_E_RAD_S
from companion.gnss.ephemeris import SatStates, transmission_states
from companion.gnss.timescale import week_tow
from companion.tight import _tight

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
        # anchor index -> (row of each satellite key, table (m, 12): pos, vel, acc, clock, drift, valid)
        self._anchors: dict[int, tuple[dict[int, int], np.ndarray]] = {}
        self.evaluations = 0  # satellite states computed by the store (for the benchmark)
        # the last one-anchor query: (anchor, keys, the anchor's (index, table) then, the keys' rows)
        self._last: tuple[int, list[int], tuple[dict[int, int], np.ndarray], np.ndarray] | None = None
        self._last_keys: tuple[tuple[bytes, bytes, str, str], list[int]] | None = None  # (``keys``' memo)

    def _table(self, k: int, keys: list[int], system: np.ndarray, prn: np.ndarray
               ) -> tuple[dict[int, int], np.ndarray]:
        """The anchor ``k``'s (row of each key, table (m, 12): pos, vel, acc, clock, drift, valid),
        evaluating the satellites it does not hold yet."""
        have = self._anchors.get(k)
        index, table = have if have is not None else ({}, np.zeros((0, 12)))
        missing = [i for i, key in enumerate(keys) if key not in index]
        if missing:
            new: dict[int, int] = {}
            for i in missing:
                new.setdefault(keys[i], i)
            rows_i = np.array(list(new.values()))
            s = self.store.states(system[rows_i], prn[rows_i], np.full(len(rows_i), k * self.period_s))
            self.evaluations += len(rows_i)
            acc = ecef_acceleration(s.pos_ecef_m, s.vel_ecef_m_s)
            rows = np.column_stack((s.pos_ecef_m, s.vel_ecef_m_s, acc, s.clock_s, s.clock_drift_s_s,
                                    s.valid.astype(float)))
            index = dict(index)
            for j, key in enumerate(new):
                index[key] = len(table) + j
            table = np.vstack((table, rows))
            self._anchors[k] = (index, table)
            for old in [a for a in self._anchors if a < k - self.keep_anchors]:
                del self._anchors[old]
        return index, table

    def _rows(self, k: int, keys: list[int], system: np.ndarray, prn: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
        """(anchor ``k``'s table, the row of each key); the rows of the last query are reused while
        the keys and the anchor's table are the same (a receiver tracks the same satellites for
        minutes: one list comparison per epoch)."""
        last = self._last
        if last is not None and last[0] == k and last[2] is self._anchors.get(k) and last[1] == keys:
            return last[2][1], last[3]
        index, table = self._table(k, keys, system, prn)
        rows = np.array([index[key] for key in keys], dtype=np.intp)
        self._last = (k, keys, self._anchors[k], rows)
        return table, rows

    def states(self, system: np.ndarray, prn: np.ndarray, t_gps_s: np.ndarray) -> SatStates:
        system = np.asarray(system, dtype=np.int64)
        prn = np.asarray(prn, dtype=np.int64)
        n = len(system)
        t = np.asarray(t_gps_s, dtype=float)
        if t.shape != (n,):  # a scalar time (or one per row already)
            t = t * np.ones(n)
        keys = (system * 1000 + prn).tolist()
        k = np.rint(t / self.period_s)  # = np.round (its rint); NaN where there is no time: no state
        finite = np.isfinite(k)
        if n and finite.all() and (k == k[0]).all():  # the usual case: one anchor for the whole epoch
            k = k.astype(np.int64)
            table, rows = self._rows(int(k[0]), keys, system, prn)
            out = table[rows]
            dt = t - k * self.period_s
        else:
            k = np.where(finite, k, 0.0).astype(np.int64)
            out = np.full((n, 12), np.nan)
            for a in set(k[finite].tolist()):
                sel = np.flatnonzero(finite & (k == a))
                # every satellite of the query evaluated at the anchor (a row is a function of the anchor and
                # the satellite alone): an epoch straddling two anchors fills the next one whole, not in parts
                index, table = self._table(a, keys, system, prn)
                out[sel] = table[[index[keys[i]] for i in sel.tolist()]]
            dt = np.where(finite, t - k * self.period_s, 0.0)
        # p + v dt + ½ a dt², v + a dt, clock + drift dt and the anchors' validity, in C (_tight.carry_states:
        # numpy's operations in its order, tested equal bit for bit)
        pos, vel, clock, drift, anchored = _tight.carry_states(out, dt)
        return SatStates(pos, vel, clock, drift, finite & anchored)

    def keys(self, system: np.ndarray, prn: np.ndarray) -> list[int]:
        """system × 1000 + PRN per satellite, as a list (the last epoch's list while its satellites are the
        same: a receiver tracks the same ones for minutes)."""
        ids = (system.tobytes(), prn.tobytes(), system.dtype.str, prn.dtype.str)
        last = self._last_keys
        if last is not None and last[0] == ids:
            return last[1]
        keys = (np.asarray(system, dtype=np.int64) * 1000 + np.asarray(prn, dtype=np.int64)).tolist()
        self._last_keys = (ids, keys)
        return keys

    def transmission_states(self, epoch: Any) -> tuple[SatStates, np.ndarray]:
        """``companion.gnss.ephemeris.transmission_states(self, epoch)``, the same numbers: when every
        satellite's ``t_rx − P/c`` has the same anchor (the usual case), its step from the anchor and back by
        the clock offset in C (``_tight.transmit_states``: numpy's operations element by element, tested
        bit for bit); else that function itself."""
        t0, k = _tight.transmit_anchor(epoch.t_gps_s, epoch.pseudorange_m, self.period_s)
        if k is None:
            return transmission_states(self, epoch)  # type: ignore[arg-type]  # (states() as a store's)
        table, rows = self._rows(k, self.keys(epoch.system, epoch.prn), epoch.system, epoch.prn)
        pos, vel, clock, drift, valid, t_tx = _tight.transmit_states(table, rows, t0, k * self.period_s)
        return SatStates(pos, vel, clock, drift, valid), t_tx


class AtmosphereCache:
    """Tropospheric (Saastamoinen) and ionospheric (Klobuchar, per signal) delays at a fixed site,
    once per satellite and ``period_s`` (at whole multiples of it, from the satellite's position
    then): the value is a function of the time alone (out-of-sequence fusion stays exact). Over the
    ±2.5 s of the 5 s period a satellite's elevation moves by a few hundredths of a degree: on the
    synthetic constellation the delay is within 1.7 cm of the exact one down to 5° elevation (where
    the σ model's pseudorange σ is ~30 m) and within 5 mm above 15° (tested)."""

    def __init__(self, sats: Any, lat_rad: float, lon_rad: float, h_m: float, r0_ecef_m: np.ndarray,
                 c_ecef_ned: np.ndarray, klobuchar: Any = None, period_s: float = 5.0) -> None:
        self.sats, self.klobuchar, self.period_s = sats, klobuchar, period_s
        self.site = (lat_rad, lon_rad, h_m)
        self.r0, self.c = np.asarray(r0_ecef_m, float), np.asarray(c_ecef_ned, float)
        self._memo: dict[tuple[int, int], float] = {}
        # the last query: (keys, anchors, delays)
        self._last: tuple[list[int], list[int], np.ndarray] | None = None

    def delays_m(self, system: np.ndarray, prn: np.ndarray, t_gps_s: np.ndarray,
                 keys: list[int] | None = None) -> np.ndarray:
        """The delay (m) of each observation's signal (L1 scaled to its frequency). ``keys``: system × 1000
        + PRN of each, when known (``SatelliteCache.keys``)."""
        if keys is None:
            keys = (np.asarray(system, np.int64) * 1000 + np.asarray(prn, np.int64)).tolist()
        # round(t / period) of each (0 where t is not finite), in C: numpy's rint of the same quotient
        k = _tight.anchors(t_gps_s, self.period_s)
        if k is None:  # a time beyond ±9e15 periods (damaged): numpy's own conversion
            t = np.where(np.isfinite(t_gps_s), t_gps_s, 0.0)
            k = np.rint(t / self.period_s).astype(np.int64).tolist()
        last = self._last
        if last is not None and last[0] == keys and last[1] == k:  # the same satellites and anchors
            return last[2]
        memo = self._memo
        missing = [i for i, (key, a) in enumerate(zip(keys, k, strict=True)) if (key, a) not in memo]
        if missing:
            mi = np.array(missing)
            ta = np.array([k[i] for i in missing]) * self.period_s
            pos = self.sats.states(np.asarray(system)[mi], np.asarray(prn)[mi], ta).pos_ecef_m
            d = pos - self.r0
            ned = d @ self.c / np.linalg.norm(d, axis=1)[:, None]
            el = np.arcsin(np.clip(-ned[:, 2], -1.0, 1.0))
            lat, lon, h = self.site
            delay = saastamoinen_m(lat, h, el)
            if self.klobuchar is not None:
                az = np.arctan2(ned[:, 1], ned[:, 0]) % (2 * np.pi)
                iono = np.empty(len(mi))
                for t in set(ta.tolist()):  # usually one anchor time per call
                    j = ta == t
                    iono[j] = klobuchar_m(self.klobuchar[0], self.klobuchar[1], lat, lon, az[j], el[j],
                                          week_tow(t)[1])
                delay = delay + iono * iono_frequency_scale(np.asarray(system)[mi])
            for i, v in zip(missing, np.where(np.isfinite(delay), delay, 0.0).tolist(), strict=True):
                memo[(keys[i], k[i])] = v
            newest = max(k)
            if len(memo) > 4096:
                for old in [key for key in memo if key[1] < newest - 8]:
                    del memo[old]
        out = np.array([memo[(key, a)] for key, a in zip(keys, k, strict=True)])
        out.flags.writeable = False  # handed out again for the same query
        self._last = (keys, k, out)
        return out
