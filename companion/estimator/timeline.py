"""The out-of-sequence core both engines are built on: a time-ordered list of entries over the IMU history.

Each entry is the posterior at one measurement's validity time, kept with everything needed to fuse
the later ones again; between two entries nothing but the prediction happens (one closed-form step
on the IMU history's prefix integrals, ``history.py``). ``Timeline`` does the bookkeeping; an
engine (``engine.FusionEngine``: GNSS fixes; ``companion.tight.engine.TightEngine``: raw epochs and
odometry) says how to start, fuse and re-base:

* ``_push(t_us, meas)``: a measurement is rejected (counted) before the first IMU sample
  (``gnss_rejected_before_imu``), valid more than ``future_tolerance_s`` after the newest IMU sample
  (``gnss_rejected_future``), older than ``history_s``, than the first IMU sample kept or than the
  oldest entry (``gnss_rejected_too_old``), or of the same type as one already held at the same time
  (``gnss_rejected_duplicate``); valid after the newest IMU sample it waits until the IMU passes it;
* ``_insert``: the first measurement starts the filter (``_start``); a later one older than the
  last entry rolls back to the entry before its time (``gnss_out_of_order``), is fused
  (``_fuse``), and the later ones are fused again from their stored measurements
  (``gnss_refused``, each): the same result as in order, at a cost O(later entries), never
  O(IMU samples);
* every ``TRIM_EVERY`` IMU samples: entries older than ``history_s`` are dropped; the newest of
  them stays as the base, re-based to the horizon by ``_anchor`` when it is older (so a GNSS outage
  does not grow the IMU history), and the IMU history is trimmed to the base;
* ``_output_now()``: the engine's ``_output`` of the last entry at the newest IMU time, computed once
  per (last entry, IMU time).
"""

from __future__ import annotations

import bisect
from typing import Any, Generic, Protocol, TypeVar

import numpy as np

from companion.domain.physics import MAX_SPECIFIC_FORCE_M_S2
from companion.estimator.history import ImuHistory, Integrals
from companion.estimator.model import IDENTITY9, Rot9

TRIM_EVERY = 256  # IMU samples between two trims of the histories


class Timed(Protocol):
    @property
    def t_us(self) -> int: ...


E = TypeVar("E", bound=Timed)  # an entry (immutable: a NamedTuple with t_us first)
M = TypeVar("M")  # a measurement
Out = TypeVar("Out")  # the output at the newest IMU time


class Timeline(Generic[E, M, Out]):
    """Entries ``entries`` (in time order; their times ``_t``), the measurements waiting for the IMU, and
    the output at the newest IMU time (cached per last entry and IMU time)."""

    def __init__(self, imu_hold_max_s: float, history_s: float, future_tolerance_s: float,
                 gravity_m_s2: float, counts: dict[str, int], imu_hold_periods: float = 0.0) -> None:
        self.imu = ImuHistory(imu_hold_max_s, imu_hold_periods, MAX_SPECIFIC_FORCE_M_S2)
        self._g = gravity_m_s2
        self.imu.trim_len = TRIM_EVERY
        self.entries: list[E] = []
        self._t: list[int] = []  # the entries' times
        self._pending: list[tuple[int, M]] = []  # measurements waiting for the IMU, by time
        self._history_us = int(round(history_s * 1e6))
        self._future_us = int(round(future_tolerance_s * 1e6))
        self._counts = counts
        self._cache: tuple[E, int, Out] | None = None  # (last entry, IMU time, its output)
        for name in ("gnss_rejected_before_imu", "gnss_rejected_future", "gnss_rejected_too_old",
                     "gnss_rejected_duplicate", "gnss_out_of_order", "gnss_refused"):
            counts.setdefault(name, 0)

    # ------------------------------------------------------------ the engine's part
    def _start(self, t_us: int, meas: M) -> E | None:
        """The first entry, from the first measurement (None: it cannot start the filter; counted)."""
        raise NotImplementedError

    def _fuse(self, prev: E, t_us: int, meas: M) -> E:
        """The entry after ``prev`` (the last one) with ``meas``, valid at ``t_us``, fused."""
        raise NotImplementedError

    def _anchor(self, e: E, t_us: int, ints: Integrals) -> E:
        """Entry ``e`` predicted to ``t_us`` (IMU integrals ``ints``) as a base without a measurement."""
        raise NotImplementedError

    def _measurement(self, e: E) -> M | None:
        """What entry ``e`` fused (None: an anchor), to fuse it again."""
        raise NotImplementedError

    def _inserted(self) -> None:
        """After a measurement was inserted (the entries changed): e.g. counters from the newest entry."""

    def _output(self, last: E, now_us: int) -> Out:
        """The output at the newest IMU time ``now_us`` from the last entry."""
        raise NotImplementedError

    # --------------------------------------------------------------------- output
    def _output_now(self) -> Out | None:
        """``_output`` at the newest IMU time (None before the first entry); computed once per last
        entry and IMU time."""
        if not self.entries:
            return None
        last, now = self.entries[-1], self.imu.last_t_us
        c = self._cache
        if c is not None and c[0] is last and c[1] == now:
            return c[2]
        out = self._output(last, now)
        self._cache = (last, now, out)
        return out

    # ------------------------------------------------------------------ IMU
    def push_acc(self, t_us: int, ax: float, ay: float, az: float, rot: Rot9 = IDENTITY9) -> None:
        """One NED acceleration (m/s², gravity-compensated: R f̃ + g) at ``t_us``, with the
        rotation R_ned_frd (row-major 9-tuple) it was measured with (the body-frame bias state
        needs it; identity = the body axes are NED). Gated and counted by the core
        (``ImuHistory.push``)."""
        if self.imu.push(t_us, ax, ay, az, rot) or self._pending:
            self._imu_pushed()

    def push_frd(self, t_us: int, f_frd_m_s2: Any, rot: Rot9) -> None:
        """One body specific force f̃ (FRD, m/s²; 3 numbers or an array) measured with the attitude
        R_ned_frd: ``push_acc`` of R f̃ + [0, 0, g] (computed by the core, the navigator's path)."""
        if self.imu.push_frd(t_us, f_frd_m_s2, rot, self._g) or self._pending:
            self._imu_pushed()

    def frd_sink(self) -> tuple[Any, float, list[Any], Any]:
        """``push_frd`` in parts for a navigator's per-sample path (one Python call fewer per IMU
        sample): (the core's ``push_frd``, the gravity, the measurements waiting for the IMU,
        ``_imu_pushed``), used as ``if push(t_us, f_frd, rot, g) or waiting: pushed()``."""
        return self.imu.push_frd, self._g, self._pending, self._imu_pushed

    def push_acc_batch(self, t_us: np.ndarray, a_ned: np.ndarray, rot: np.ndarray | None = None) -> None:
        """Many NED accelerations (with their rotations, (n, 9) row-major; None = identity) at
        once; the same result as ``push_acc`` one by one."""
        t_us = np.asarray(t_us, dtype=np.int64)
        a_ned = np.asarray(a_ned, dtype=float)
        n = len(t_us)
        if n == 0:
            return
        imu = self.imu
        clean = bool(np.isfinite(a_ned).all()) and len(imu) > 0
        if clean:
            t_prev = np.concatenate(([imu.last_t_us], t_us[:-1]))
            dt_s = (t_us - imu.t0_us) * 1e-6 - (t_prev - imu.t0_us) * 1e-6
            clean = bool((t_us > t_prev).all()) and bool((dt_s <= imu.hold_max_s).all())
        if not clean:  # anything to gate or count: take the per-sample path
            rots = [IDENTITY9] * n if rot is None else [tuple(r) for r in np.asarray(rot, float).tolist()]
            for t, (ax, ay, az), r in zip(t_us.tolist(), a_ned.tolist(), rots, strict=True):
                self.push_acc(t, ax, ay, az, r)
            return
        imu.append_batch(t_us, a_ned, None if rot is None else np.asarray(rot, dtype=float))
        self._imu_pushed()

    def _imu_pushed(self) -> None:
        """Insert the measurements the IMU has now passed; trim when the history is due."""
        imu, pending = self.imu, self._pending
        if pending and pending[0][0] <= imu.last_t_us:
            now = imu.last_t_us
            while pending and pending[0][0] <= now:
                self._insert(*pending.pop(0))
        if len(imu) > imu.trim_len:
            self._trim()
            imu.trim_len = len(imu) + TRIM_EVERY

    # --------------------------------------------------------------- measurements
    def _push(self, t_us: int, meas: M) -> None:
        """A measurement valid at ``t_us``: inserted now, later (waiting for the IMU), or rejected."""
        c = self._counts
        imu = self.imu
        if not len(imu):
            c["gnss_rejected_before_imu"] += 1
            return
        now = imu.last_t_us
        if t_us > now + self._future_us:
            c["gnss_rejected_future"] += 1
            return
        if t_us < now - self._history_us or t_us < imu.first_t_us or (self._t and t_us < self._t[0]):
            c["gnss_rejected_too_old"] += 1
            return
        if self._is_duplicate(t_us, meas):
            c["gnss_rejected_duplicate"] += 1
            return
        if t_us > now:
            bisect.insort(self._pending, (t_us, meas), key=lambda item: item[0])
            return
        self._insert(t_us, meas)

    def _is_duplicate(self, t_us: int, meas: M) -> bool:
        """A measurement of the same type is held (fused or waiting) at ``t_us``."""
        t = self._t
        if (not t or t_us > t[-1]) and not self._pending:  # the usual case: a new time
            return False
        kind = type(meas)
        lo, hi = bisect.bisect_left(t, t_us), bisect.bisect_right(t, t_us)
        return any(type(self._measurement(self.entries[i])) is kind for i in range(lo, hi)) or any(
            ti == t_us and type(m) is kind for ti, m in self._pending)

    def _insert(self, t_us: int, meas: M) -> None:
        entries, t = self.entries, self._t
        if not entries:
            e = self._start(t_us, meas)
            if e is not None:
                entries.append(e)
                t.append(t_us)
                self._inserted()
            return
        i = bisect.bisect_right(t, t_us)
        if i == 0:
            self._counts["gnss_rejected_too_old"] += 1
            return
        later = entries[i:]
        if later:
            self._counts["gnss_out_of_order"] += 1
            del entries[i:]
            del t[i:]
        entries.append(self._fuse(entries[-1], t_us, meas))
        t.append(t_us)
        for e in later:
            m = self._measurement(e)
            assert m is not None  # anchors only ever sit at index 0
            entries.append(self._fuse(entries[-1], e.t_us, m))
            t.append(e.t_us)
            self._counts["gnss_refused"] += 1
        self._inserted()

    # -------------------------------------------------------------------- history
    def _trim(self) -> None:
        """Drop what no measurement inside the history can need; re-base an old base to the horizon."""
        imu, entries, t = self.imu, self.entries, self._t
        horizon = imu.last_t_us - self._history_us
        if not entries:
            imu.trim_before(horizon)
            return
        j = bisect.bisect_right(t, horizon) - 1
        if j < 0:
            return
        if j > 0:
            del entries[:j]
            del t[:j]
        base = entries[0]
        if base.t_us < horizon:
            entries[0] = self._anchor(base, horizon, imu.integrals(horizon))
            t[0] = horizon
        imu.trim_before(t[0])
