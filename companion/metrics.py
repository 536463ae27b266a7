"""Position error of an estimate against a reference (an autopilot's estimate, truth, GNSS).

Pure numeric core shared by ``beliefnav replay`` and the live companion: no I/O.

:class:`PositionErrors` matches a reference stream to an estimate stream online, both in the
same local NED frame and in arrival order: each reference sample is compared with the estimate
linearly interpolated to the reference's time, once the estimates have passed that time.
Memory: a short window of recent estimates (``window_us``) plus three float32 per matched
reference (exact medians need the values; 0.8 MB for 18 hours of 5 Hz fixes). A process that
runs for days bounds it with ``max_errors``: once that many are kept, every other one is
dropped and from then on only every 2nd (then 4th, ...) matched error is kept: a uniform
decimation in time, so the statistics are those of an evenly spaced sample (``decimation``
says the stride; ``matched`` and, without a fitted alignment, the maxima stay exact).
References waiting for estimates are bounded too (``max_pending``, the oldest counted as
unmatched). With ``coverage=True`` and the estimate's reported horizontal variances
(``add_estimate(..., var_ne_m2)``) it also counts how often the horizontal error lies inside the
reported 1-σ and 2-σ ellipses (NEES_h = e_N²/σ_N² + e_E²/σ_E² ≤ 1 and ≤ 4, the variances interpolated
like the position; a consistent 2-D Gaussian: 39.3 % and 86.5 %): ``statistics()["coverage_horizontal"]``;
with the vertical variance too (``var_ne_m2`` of 3 or more), how often |e_D| ≤ σ_D and ≤ 2 σ_D (a
consistent Gaussian: 68.3 % and 95.4 %): ``statistics()["coverage_vertical"]``.
:func:`error_statistics` reduces the error vectors to the summary block
``{n, alignment, offset_ned_m, mean_error_ned_m, error_horizontal_m, error_3d_m}`` (each
``median, p95, max, rmse, iqr, n``).

Alignments (how the two origins are made to agree before the norms are taken):

- ``geodetic``: none fitted; both series are in the same frame because the reference's own
  origin (or its geodetic position) was converted into it exactly.
- ``mean_offset``: the mean error vector is removed (translation-only least squares), for a
  reference about an origin the log does not state; ``median_offset``: the per-axis median
  (robust to outliers).
- ``vertical_mean_offset``: geodetic horizontally, the mean vertical error removed (a reference
  whose altitude datum differs from the fixes', e.g. height above take-off against MSL).
"""

from __future__ import annotations

import bisect
import math
from array import array
from collections import deque
from typing import Any

import numpy as np

from companion.domain.statistics import describe

ALIGNMENTS = ("geodetic", "mean_offset", "median_offset", "vertical_mean_offset")
DEFAULT_WINDOW_US = 10_000_000
ERROR_BLOCK = ("median", "p95", "max", "rmse", "iqr", "n")  # companion.domain.statistics names


def _stats(e: np.ndarray) -> dict[str, float]:
    return describe(e, ERROR_BLOCK)


def error_statistics(err_ned_m: np.ndarray, alignment: str = "geodetic") -> dict[str, Any]:
    """Summary of (n, 3) error vectors (estimate − reference) after ``alignment``."""
    if alignment not in ALIGNMENTS:
        raise ValueError(f"alignment {alignment!r} not in {ALIGNMENTS}")
    err = np.asarray(err_ned_m, dtype=float).reshape(-1, 3)
    offset = np.zeros(3)
    if err.shape[0] and alignment != "geodetic":
        offset = np.median(err, axis=0) if alignment == "median_offset" else err.mean(axis=0)
        if alignment == "vertical_mean_offset":
            offset[:2] = 0.0
    aligned = err - offset
    return {
        "n": int(err.shape[0]),
        "alignment": alignment,
        "offset_ned_m": [float(v) for v in offset],
        "mean_error_ned_m": [float(v) for v in aligned.mean(axis=0)] if err.shape[0] else [math.nan] * 3,
        "error_horizontal_m": _stats(np.linalg.norm(aligned[:, :2], axis=1)),
        "error_3d_m": _stats(np.linalg.norm(aligned, axis=1)),
    }


class Distribution:
    """Summary of a stream of values in bounded memory: exact count, mean, min, max and last
    value; quantiles from a histogram of ``bins`` bins over [lo, hi] (linear or logarithmic),
    exact to half a bin (values outside [lo, hi] fall into the end bins)."""

    def __init__(self, lo: float, hi: float, bins: int, log: bool = False) -> None:
        self.lo, self.hi, self.log = lo, hi, log
        self._a, self._b = (math.log(lo), math.log(hi)) if log else (lo, hi)
        self.counts = np.zeros(bins, dtype=np.int64)
        self.n, self.total, self.min, self.max, self.last = 0, 0.0, math.inf, -math.inf, math.nan

    def add(self, values: np.ndarray) -> None:
        x = np.asarray(values, dtype=float).ravel()
        x = x[np.isfinite(x)]
        if x.size == 0:
            return
        self.n += int(x.size)
        self.total += float(x.sum())
        self.min, self.max = min(self.min, float(x.min())), max(self.max, float(x.max()))
        self.last = float(x[-1])
        y = np.log(np.maximum(x, self.lo)) if self.log else x
        k = ((y - self._a) / (self._b - self._a) * self.counts.size).astype(np.int64)
        np.add.at(self.counts, np.clip(k, 0, self.counts.size - 1), 1)

    def quantile(self, q: float) -> float:
        if self.n == 0:
            return math.nan
        k = int(np.searchsorted(np.cumsum(self.counts), q * self.n, side="left"))
        mid = self._a + (k + 0.5) * (self._b - self._a) / self.counts.size
        value = math.exp(mid) if self.log else mid
        return min(max(value, self.min), self.max)

    def summary(self) -> dict[str, float]:
        if self.n == 0:
            return {"n": 0}
        return {"n": self.n, "mean": self.total / self.n, "min": self.min, "p5": self.quantile(0.05),
                "median": self.quantile(0.5), "max": self.max, "final": self.last}


def _tally(counts: list[int], nees: float) -> None:
    """One matched error into [matched, inside 1 σ, inside 2 σ] (NEES ≤ 1, ≤ 4)."""
    counts[0] += 1
    counts[1] += nees <= 1.0
    counts[2] += nees <= 4.0


class PositionErrors:
    """Online estimate-vs-reference matching (see module doc).

    ``add_estimate(t_us, p_ned_m)`` in non-decreasing time; ``add_reference(t_us, p_ned_m)`` in
    any order within the window. A reference older than the first estimate (or than the window),
    newer than the last estimate at the end, or between two estimates more than ``max_gap_us``
    apart is not compared (counted in ``unmatched``).
    ``restart()`` starts a new time base (a log restart): pending references are dropped as
    unmatched, collected errors are kept.
    """

    def __init__(self, window_us: int = DEFAULT_WINDOW_US, max_gap_us: int | None = None,
                 max_errors: int | None = None, max_pending: int = 65_536, coverage: bool = False) -> None:
        self.window_us, self.max_gap_us = window_us, max_gap_us
        self.max_errors, self.max_pending = max_errors, max_pending
        self._t: list[int] = []
        self._p: list[tuple[float, float, float]] = []
        self._v: list[tuple[float, float, float]] | None = [] if coverage else None  # reported σ² N, E, D
        self._within = [0, 0, 0]  # matched with finite variances, inside 1 σ, inside 2 σ
        self._within_v = [0, 0, 0]  # the same vertically
        self._pending: deque[tuple[int, tuple[float, float, float]]] = deque()
        self._err = array("f")  # float32: 12 bytes per kept error
        self.unmatched = 0
        self.matched = 0
        self.decimation = 1  # every decimation-th matched error is kept
        self._max_sq = [0.0, 0.0]  # largest squared horizontal and 3-D error of all matched

    def add_estimate(self, t_us: int, p_ned_m: Any, var_ne_m2: Any = None) -> None:
        """An estimate (time order) with its reported north and east (and down, when given) variances
        (m²; used with ``coverage``, NaN when not given)."""
        if self._t and t_us < self._t[-1]:
            raise ValueError("estimates must come in time order (restart() for a new time base)")
        self._t.append(t_us)
        self._p.append((float(p_ned_m[0]), float(p_ned_m[1]), float(p_ned_m[2])))
        if self._v is not None:
            self._v.append((math.nan, math.nan, math.nan) if var_ne_m2 is None
                           else (float(var_ne_m2[0]), float(var_ne_m2[1]),
                                 float(var_ne_m2[2]) if len(var_ne_m2) > 2 else math.nan))
        while self._pending and self._pending[0][0] <= t_us:
            t, p = self._pending.popleft()
            self._match(t, p)
        if len(self._t) > 4096 and self._t[len(self._t) // 2] < t_us - self.window_us:
            half = len(self._t) // 2
            del self._t[:half], self._p[:half]
            if self._v is not None:
                del self._v[:half]

    def add_reference(self, t_us: int, p_ned_m: Any) -> None:
        p = (float(p_ned_m[0]), float(p_ned_m[1]), float(p_ned_m[2]))
        if self._t and t_us <= self._t[-1]:
            self._match(t_us, p)
        else:
            self._pending.append((t_us, p))
            if len(self._pending) > 1 and self._pending[-2][0] > t_us:  # rare: keep it sorted
                self._pending = deque(sorted(self._pending))
            if len(self._pending) > self.max_pending:
                self._pending.popleft()
                self.unmatched += 1

    def _match(self, t_us: int, p: tuple[float, float, float]) -> None:
        t = self._t
        i = bisect.bisect_left(t, t_us)
        if i == len(t) or (i == 0 and t[0] != t_us) or t_us < t[-1] - self.window_us:
            self.unmatched += 1
            return
        w = 0.0
        if t[i] == t_us:
            q = self._p[i]
        else:
            t0, t1 = t[i - 1], t[i]
            if self.max_gap_us is not None and t1 - t0 > self.max_gap_us:
                self.unmatched += 1  # no estimate for a while (e.g. an IMU dropout): not compared
                return
            w = (t_us - t0) / (t1 - t0)
            q0, q1 = self._p[i - 1], self._p[i]
            q = (q0[0] + w * (q1[0] - q0[0]), q0[1] + w * (q1[1] - q0[1]), q0[2] + w * (q1[2] - q0[2]))
        self.matched += 1
        e = (q[0] - p[0], q[1] - p[1], q[2] - p[2])
        if self._v is not None:
            v1 = self._v[i]
            v0 = self._v[i - 1] if w else v1
            vn, ve = v0[0] + w * (v1[0] - v0[0]), v0[1] + w * (v1[1] - v0[1])
            if vn > 0.0 and ve > 0.0 and math.isfinite(vn) and math.isfinite(ve):
                _tally(self._within, e[0] * e[0] / vn + e[1] * e[1] / ve)
            vd = v0[2] + w * (v1[2] - v0[2])
            if vd > 0.0 and math.isfinite(vd):
                _tally(self._within_v, e[2] * e[2] / vd)
        h_sq = e[0] * e[0] + e[1] * e[1]
        m = self._max_sq
        m[0], m[1] = max(m[0], h_sq), max(m[1], h_sq + e[2] * e[2])
        if (self.matched - 1) % self.decimation:
            return
        self._err.extend(e)
        if self.max_errors is not None and len(self._err) >= 3 * self.max_errors:
            kept = np.frombuffer(self._err, dtype=np.float32).reshape(-1, 3)[::2]
            self._err = array("f", kept.ravel().tobytes())
            self.decimation *= 2

    def restart(self) -> None:
        self.unmatched += len(self._pending)
        self._pending.clear()
        self._t.clear()
        self._p.clear()
        if self._v is not None:
            self._v.clear()

    def errors_ned_m(self) -> np.ndarray:
        """(n, 3) estimate − reference at the matched reference times."""
        return np.frombuffer(self._err, dtype=np.float32).reshape(-1, 3).astype(float)

    def statistics(self, alignment: str = "geodetic") -> dict[str, Any]:
        out = error_statistics(self.errors_ned_m(), alignment)
        if alignment == "geodetic" and self.decimation > 1:  # the maxima of all, not of the kept sample
            out["error_horizontal_m"]["max"] = math.sqrt(self._max_sq[0])
            out["error_3d_m"]["max"] = math.sqrt(self._max_sq[1])
        out["unmatched"] = self.unmatched + len(self._pending)
        out["matched"], out["decimation"] = self.matched, self.decimation
        if self._v is not None:
            n, in1, in2 = self._within
            out["coverage_horizontal"] = {"n": n, "within_1_sigma": in1 / n if n else math.nan,
                                          "within_2_sigma": in2 / n if n else math.nan}
            n, in1, in2 = self._within_v
            out["coverage_vertical"] = {"n": n, "within_1_sigma": in1 / n if n else math.nan,
                                        "within_2_sigma": in2 / n if n else math.nan}
        return out


def compare_series(
    t_us: np.ndarray, p_ned_m: np.ndarray, ref_t_us: np.ndarray, ref_ned_m: np.ndarray,
    alignment: str = "geodetic", max_gap_us: int | None = None,
) -> dict[str, Any]:
    """Batch form of :class:`PositionErrors`: estimates (N,) / (N, 3) in time order, references
    (K,) / (K, 3) at any times; the :func:`error_statistics` block plus ``unmatched``."""
    m = PositionErrors(window_us=2**62, max_gap_us=max_gap_us)
    for t, p in zip(np.asarray(t_us).tolist(), np.asarray(p_ned_m, dtype=float).reshape(-1, 3), strict=True):
        m.add_estimate(int(t), p)
    for t, r in zip(np.asarray(ref_t_us).tolist(), np.asarray(ref_ned_m, dtype=float).reshape(-1, 3),
                    strict=True):
        if np.isfinite(r).all():
            m.add_reference(int(t), r)
        else:
            m.unmatched += 1
    return m.statistics(alignment)
