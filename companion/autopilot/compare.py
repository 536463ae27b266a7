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


def distribution(x: np.ndarray) -> dict[str, float | int | None]:
    if x.size == 0:
        return {"median": None, "p95": None, "max": None, "count": 0}
    return {"median": float(np.median(x)), "p95": float(np.percentile(x, 95)), "max": float(x.max()),
            "count": int(x.size)}


def interpolate(t_us: np.ndarray, p: np.ndarray, at_us: np.ndarray, max_gap_us: int) -> np.ndarray:
    """``p`` (N, 3) at times ``at_us`` (K,), NaN rows outside the series or across a gap."""
    out = np.full((at_us.size, 3), np.nan)
    if t_us.size < 2:
        return out
    idx = np.searchsorted(t_us, at_us)
    ok = (idx > 0) & (idx < t_us.size)
    i1 = np.where(ok, idx, 1)
    i0 = i1 - 1
    gap = t_us[i1] - t_us[i0]
    ok &= gap <= max_gap_us
    w = np.where(gap > 0, (at_us - t_us[i0]) / np.maximum(gap, 1), 0.0)[:, None]
    interp = p[i0] + w * (p[i1] - p[i0])
    out[ok] = interp[ok]
    return out


def compare(t_us: np.ndarray, p_ned_m: np.ndarray, ref_t_us: np.ndarray, ref_ned_m: np.ndarray,
            max_gap_us: int = 200_000, fit_translation: bool = False) -> dict[str, Any]:
    """Error statistics of ours against the reference; ``fit_translation`` removes the median offset."""
    ours = interpolate(t_us, p_ned_m, ref_t_us, max_gap_us)
    ok = np.all(np.isfinite(ours), axis=1) & np.all(np.isfinite(ref_ned_m), axis=1)
    diff = ours[ok] - ref_ned_m[ok]
    offset = np.median(diff, axis=0) if fit_translation and diff.size else np.zeros(3)
    diff = diff - offset
    return {
        "error_horizontal_m": distribution(np.hypot(diff[:, 0], diff[:, 1])),
        "error_3d_m": distribution(np.linalg.norm(diff, axis=1)),
        "mean_offset_ned_m": [float(v) for v in diff.mean(axis=0)] if diff.size else None,
        "fitted_translation_ned_m": [float(v) for v in offset] if fit_translation else None,
    }
