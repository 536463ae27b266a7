"""Per-control-step record of a flight in the vehicle process (truth + what it received).

The series keys are those of ``simvehicle.harness.fly`` (docs/ARCHITECTURE.md); the launcher turns
them into the same summary and figures. The estimated bias arrives at 5 Hz (DEBUG_VECT
``GNSS_BIAS``), so ``b_est_ned_m`` holds the latest received (NaN before the first).

Rows are plain float64 (``ROW_LAYOUT``, 176 bytes per control step). With a ``spool_path`` they
are appended to that file by :meth:`FlightRecorder.flush` (the vehicle calls it every second) and
dropped from memory, so memory stays flat however long the flight and a ``kill -9`` loses at
most a second of the record: :func:`series_from_spool` rebuilds the series from the file.
"""

from __future__ import annotations

import math
from array import array
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from companion.domain.samples import NavEstimate, Setpoint

_NAN3 = (math.nan, math.nan, math.nan)


@dataclass(frozen=True, slots=True)
class Row:
    t_s: float
    goal_distance_m: float


class FlightRecorder:
    def __init__(self, goal_ned_m: np.ndarray, goal_radius_m: float, goal_speed_m_s: float,
                 arrive_after_s: float, spool_path: Path | None = None) -> None:
        self.goal_ned_m = np.asarray(goal_ned_m, dtype=float)
        self.goal_radius_m = goal_radius_m
        self.goal_speed_m_s = goal_speed_m_s
        self.arrive_after_s = arrive_after_s  # the reference reaches the goal at this time
        self._arrived = False
        self._pending = array("d")  # rows not yet spooled (all of them without a spool file)
        self._goal_distance_m = math.inf
        self.spool_path = spool_path
        if spool_path is not None:
            spool_path.write_bytes(b"")

    def record(
        self, out: Any, estimate: NavEstimate | None, setpoint: Setpoint | None, beta: float, nis: float,
        bias_ned_m: np.ndarray | None = None,
    ) -> Row:
        truth = out.truth[-1]
        p_true = truth.p_ned_m
        p_est = estimate.p_ned_m if estimate is not None else np.array(_NAN3)
        p_ref = setpoint.p_ned_m if setpoint is not None else np.array(_NAN3)
        values = {
            "t_s": out.t_us / 1e6,
            "p_true_ned_m": p_true,
            "p_est_ned_m": p_est,
            "p_ref_ned_m": p_ref,
            "b_true_ned_m": truth.gnss_bias_ned_m,
            "b_est_ned_m": np.array(_NAN3) if bias_ned_m is None else bias_ned_m,
            "beta": beta,
            "nis": nis,
            "latency_s": truth.gnss_latency_s,
            "clearance_m": truth.clearance_m,
            "est_error_m": float(np.linalg.norm(p_est - p_true)),
            "track_error_m": float(np.linalg.norm(p_true - p_ref)),
        }
        row = self._pending
        for key, width in ROW_LAYOUT:
            value = values[key]
            if width == 1:
                row.append(float(value))
            else:
                row.extend(value)
        self._goal_distance_m = float(np.linalg.norm(p_true - self.goal_ned_m))
        self._arrived = (self._goal_distance_m <= self.goal_radius_m
                         and float(np.linalg.norm(truth.v_ned_m_s)) <= self.goal_speed_m_s
                         and out.t_us / 1e6 >= self.arrive_after_s)
        return Row(out.t_us / 1e6, self._goal_distance_m)

    def reached_goal(self) -> bool:
        """Within the goal radius, slow enough, and not before the reference arrived (as ``fly``)."""
        return self._arrived

    def flush(self) -> None:
        """Append the pending rows to the spool file and forget them (no-op without one)."""
        if self.spool_path is not None and self._pending:
            with open(self.spool_path, "ab") as f:
                f.write(self._pending.tobytes())
            self._pending = array("d")

    def series(self) -> dict[str, np.ndarray]:
        self.flush()
        raw = self.spool_path.read_bytes() if self.spool_path is not None else self._pending.tobytes()
        return series_from_rows(raw)

    def save(self, path: Path) -> None:
        """The series as ``.npz``; the spool file, now redundant, is removed once that is written."""
        np.savez(path, **self.series())  # type: ignore[arg-type]  # numpy stubs type **kwds as bool
        if self.spool_path is not None:
            self.spool_path.unlink(missing_ok=True)


def series_from_rows(raw: bytes) -> dict[str, np.ndarray]:
    """The series of whole rows in ``raw`` (a trailing partial row, from a kill, is dropped)."""
    n = len(raw) // (8 * ROW_FLOATS)
    rows = np.frombuffer(raw[: n * 8 * ROW_FLOATS], dtype=float).reshape(n, ROW_FLOATS)
    out: dict[str, np.ndarray] = {}
    col = 0
    for key, width in ROW_LAYOUT:
        out[key] = rows[:, col].copy() if width == 1 else rows[:, col:col + width].copy()
        col += width
    return out


def series_from_spool(path: Path) -> dict[str, np.ndarray]:
    return series_from_rows(path.read_bytes())


ROW_LAYOUT = (
    ("t_s", 1), ("p_true_ned_m", 3), ("p_est_ned_m", 3), ("p_ref_ned_m", 3), ("b_true_ned_m", 3),
    ("b_est_ned_m", 3), ("beta", 1), ("nis", 1), ("latency_s", 1), ("clearance_m", 1), ("est_error_m", 1),
    ("track_error_m", 1),
)
SERIES_KEYS = tuple(key for key, _ in ROW_LAYOUT)
ROW_FLOATS = sum(width for _, width in ROW_LAYOUT)
SPOOL_NAME = "vehicle_series.f64"  # the raw rows beside vehicle_series.npz
