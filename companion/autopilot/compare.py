"""Our estimate against the autopilot's own (pure numpy: no I/O).

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
"""

from __future__ import annotations

from typing import Any

import numpy as np

from companion import metrics


def distribution(x: np.ndarray) -> dict[str, float | int | None]:
    if x.size == 0:
        return {"median": None, "p95": None, "max": None, "count": 0}
    return {"median": float(np.median(x)), "p95": float(np.percentile(x, 95)), "max": float(x.max()),
            "count": int(x.size)}


def compare(t_us: np.ndarray, p_ned_m: np.ndarray, ref_t_us: np.ndarray, ref_ned_m: np.ndarray,
            max_gap_us: int = 200_000, fit_translation: bool = False) -> dict[str, Any]:
    """Error statistics of ours against the reference; ``fit_translation`` removes the median offset.

    Computed by :func:`companion.metrics.compare_series` (the one error-statistics function,
    shared with ``beliefnav replay``); reported here in the companion's summary layout."""
    s = metrics.compare_series(t_us, p_ned_m, ref_t_us, ref_ned_m,
                               "median_offset" if fit_translation else "geodetic", max_gap_us)

    def block(stats: dict[str, Any]) -> dict[str, float | int | None]:
        if not stats["n"]:
            return {"median": None, "p95": None, "max": None, "count": 0}
        return {"median": stats["median"], "p95": stats["p95"], "max": stats["max"], "count": stats["n"]}

    offset = s["offset_ned_m"]
    return {
        "error_horizontal_m": block(s["error_horizontal_m"]),
        "error_3d_m": block(s["error_3d_m"]),
        "mean_offset_ned_m": s["mean_error_ned_m"] if s["n"] else None,
        "fitted_translation_ned_m": offset if fit_translation else None,
    }
