"""Our estimate against the autopilot's own, online and in bounded memory (pure numpy: no I/O).

Both are put in our local NED frame first (the alignment), then ours is interpolated linearly
at the autopilot's stamps (same boot-time base); stamps outside our series or in a gap longer
than ``max_gap_us`` are not compared. Alignments:

- ``GLOBAL_POSITION_INT``: its lat/lon/alt (AMSL) converted with our frame's geodesy — exact,
  nothing fitted; the vertical error includes any difference between its barometric altitude
  and our GNSS altitude.
- ``LOCAL_POSITION_NED`` with a known EKF origin (GPS_GLOBAL_ORIGIN): the origin's position in our
  frame is added (NED axes are parallel at these distances to within the frame's curvature).
- ``LOCAL_POSITION_NED`` without an origin: the median difference is removed (a fitted
  translation, stated as such: the error is then only the spread about it).

:class:`LiveComparison` keeps none of the series: the matching is online
(:class:`companion.metrics.PositionErrors`, a few seconds of our estimate), the errors are kept
up to ``max_errors`` each (then decimated evenly in time), β is a fixed-size histogram. A
companion that runs for days uses the same memory as one that runs for minutes.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from companion import metrics

MAX_ERRORS = 8_192  # error vectors kept per reference (96 kB; 15 min at 9 Hz), then evenly decimated
BETA_BINS = 10_000  # β quantiles exact to 5e-5


def distribution(x: np.ndarray) -> dict[str, float | int | None]:
    if x.size == 0:
        return {"median": None, "p95": None, "max": None, "count": 0}
    return {"median": float(np.median(x)), "p95": float(np.percentile(x, 95)), "max": float(x.max()),
            "count": int(x.size)}


def _block(stats: dict[str, Any], count: int | None = None) -> dict[str, float | int | None]:
    if not stats["n"]:
        return {"median": None, "p95": None, "max": None, "count": 0}
    return {"median": stats["median"], "p95": stats["p95"], "max": stats["max"],
            "count": stats["n"] if count is None else count}


def _report(s: dict[str, Any], fit_translation: bool) -> dict[str, Any]:
    """An :func:`companion.metrics.error_statistics` block in the companion's summary layout."""
    matched = s.get("matched")
    return {
        "error_horizontal_m": _block(s["error_horizontal_m"], matched),
        "error_3d_m": _block(s["error_3d_m"], matched),
        "mean_offset_ned_m": s["mean_error_ned_m"] if s["n"] else None,
        "fitted_translation_ned_m": s["offset_ned_m"] if fit_translation else None,
    }


def compare(t_us: np.ndarray, p_ned_m: np.ndarray, ref_t_us: np.ndarray, ref_ned_m: np.ndarray,
            max_gap_us: int = 200_000, fit_translation: bool = False) -> dict[str, Any]:
    """Error statistics of ours against the reference; ``fit_translation`` removes the median offset
    (the batch form of :class:`LiveComparison`, computed by :func:`companion.metrics.compare_series`)."""
    s = metrics.compare_series(t_us, p_ned_m, ref_t_us, ref_ned_m,
                               "median_offset" if fit_translation else "geodetic", max_gap_us)
    return _report(s, fit_translation)


class LiveComparison:
    """Our estimate (``estimate``, in time order) against the autopilot's, matched as they come."""

    def __init__(self, max_gap_us: int, max_errors: int = MAX_ERRORS) -> None:
        self.global_errors = metrics.PositionErrors(max_gap_us=max_gap_us, max_errors=max_errors)
        self.local_errors = metrics.PositionErrors(max_gap_us=max_gap_us, max_errors=max_errors)
        self.beta = metrics.Distribution(0.0, 1.0, BETA_BINS)
        self.count = 0
        self.max_horizontal_m = math.nan
        self.final_p_ned_m: tuple[float, float, float] | None = None
        self.global_references = self.local_references = 0

    def estimate(self, key_us: int, p_ned_m: Any, beta: float) -> None:
        p = (float(p_ned_m[0]), float(p_ned_m[1]), float(p_ned_m[2]))
        self.global_errors.add_estimate(key_us, p)
        self.local_errors.add_estimate(key_us, p)
        self.beta.add(np.array((beta,)))
        self.count += 1
        self.max_horizontal_m = max(math.hypot(p[0], p[1]), self.max_horizontal_m) \
            if not math.isnan(self.max_horizontal_m) else math.hypot(p[0], p[1])
        self.final_p_ned_m = p

    def reference_global(self, key_us: int, p_ned_m: Any) -> None:
        """GLOBAL_POSITION_INT already in our frame."""
        self.global_references += 1
        self.global_errors.add_reference(key_us, p_ned_m)

    def reference_local(self, key_us: int, p_ned_m: Any) -> None:
        """LOCAL_POSITION_NED as sent (about the autopilot's EKF origin)."""
        self.local_references += 1
        self.local_errors.add_reference(key_us, p_ned_m)

    def restart(self) -> None:
        """A new time base (the autopilot rebooted): pending references are not compared."""
        self.global_errors.restart()
        self.local_errors.restart()

    def beta_summary(self) -> dict[str, Any]:
        b = self.beta
        if b.n == 0:
            return {"median": None, "p95": None, "max": None, "count": 0, "min": None, "final": None}
        return {"median": b.quantile(0.5), "p95": b.quantile(0.95), "max": b.max, "count": b.n,
                "min": b.min, "final": b.last}

    def errors(self, origin_in_our_frame_ned_m: np.ndarray | None) -> tuple[dict[str, Any], str] | None:
        """(error block, how it was aligned): GLOBAL_POSITION_INT if it came, else LOCAL_POSITION_NED
        with the EKF origin (ours - (local + origin) = raw error - origin), else with the median
        difference removed; None without any reference compared."""
        if self.global_references:
            return _report(self.global_errors.statistics("geodetic"), False), "global"
        if not self.local_references:
            return None
        if origin_in_our_frame_ned_m is not None:
            raw = self.local_errors.errors_ned_m() - np.asarray(origin_in_our_frame_ned_m, dtype=float)
            s = metrics.error_statistics(raw, "geodetic") | {"matched": self.local_errors.matched}
            return _report(s, False), "local_origin"
        return _report(self.local_errors.statistics("median_offset"), True), "local_fitted"
