"""A flight's record, one schema for every vehicle side: the series (``ROW_LAYOUT``, ``row``,
``series_from_rows``) and the goal test (``Goal``), used by the in-process loop
(``simvehicle.harness.fly``), the vehicle process (``FlightRecorder``) and the ArduPilot driver.

A control step is one row of plain float64 (``ROW_LAYOUT``, ``ROW_FLOATS`` floats, 216 bytes);
``series_from_rows`` gives the columns by key plus the two derived errors (``DERIVED``). In the
vehicle process the estimated bias arrives at 5 Hz (DEBUG_VECT ``GNSS_BIAS``), so ``b_est_ned_m``
holds the latest received (NaN before the first), β and NIS their NAMED_VALUE_FLOATs, the
position variances the ODOMETRY covariance, and ``p_ref_ned_m`` the setpoint received; in-process
``p_ref_ned_m`` is the route's reference at ``t_s``.

With a ``spool_path`` the vehicle's rows are appended to that file by :meth:`FlightRecorder.flush`
(the vehicle calls it every second) and dropped from memory, so memory stays flat however long
the flight and a ``kill -9`` loses at most a second of the record: :func:`series_from_spool`
rebuilds the series from the file.
"""

from __future__ import annotations

import math
from array import array
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from companion.domain.samples import NavEstimate, Setpoint, TruthState

_NAN3 = (math.nan, math.nan, math.nan)

ROW_LAYOUT = (
    ("t_s", 1), ("p_true_ned_m", 3), ("p_est_ned_m", 3), ("p_ref_ned_m", 3), ("b_true_ned_m", 3),
    ("b_est_ned_m", 3), ("beta", 1), ("nis", 1), ("p_var_ned_m2", 3), ("latency_s", 1), ("clearance_m", 1),
    ("q_true_ned_frd", 4),
)
DERIVED = ("est_error_m", "track_error_m")  # |p_est - p_true|, |p_true - p_ref|
SERIES_KEYS = (*(key for key, _ in ROW_LAYOUT), *DERIVED)
ROW_FLOATS = sum(width for _, width in ROW_LAYOUT)
SPOOL_NAME = "vehicle_series.f64"  # the raw rows beside vehicle_series.npz


def _columns() -> dict[str, slice]:
    out, col = {}, 0
    for key, width in ROW_LAYOUT:
        out[key] = slice(col, col + width)
        col += width
    return out


COLUMNS = _columns()  # key -> its columns in a row


def row(t_us: int, truth: TruthState, estimate: NavEstimate | None, p_ref_ned_m: Any = _NAN3,
        b_est_ned_m: Any = None, beta: float | None = None, nis: float | None = None) -> tuple[float, ...]:
    """One control step in ``ROW_LAYOUT`` order; the bias, β and NIS default to the estimate's."""
    p_est: Any
    p_var: Any
    b_est: Any
    if estimate is None:
        p_est = p_var = b_est = _NAN3
        beta = math.nan if beta is None else beta
        nis = math.nan if nis is None else nis
    else:
        p_est, p_var = estimate.p_ned_m, estimate.cov_diag[0:3]
        b_est = estimate.b_ned_m
        beta = estimate.beta if beta is None else beta
        nis = estimate.nis if nis is None else nis
    if b_est_ned_m is not None:
        b_est = b_est_ned_m
    return (t_us * 1e-6, *truth.p_ned_m, *p_est, *p_ref_ned_m, *truth.gnss_bias_ned_m, *b_est, beta, nis,
            *p_var, truth.gnss_latency_s, truth.clearance_m, *truth.q_ned_frd)


def series_from_rows(raw: bytes | array) -> dict[str, np.ndarray]:
    """The series of the whole rows in ``raw`` (a trailing partial row, from a kill, is dropped):
    views of the one row buffer (no second copy of an hour of rows) plus ``DERIVED``."""
    n = len(memoryview(raw).cast("B")) // (8 * ROW_FLOATS)
    rows = np.frombuffer(raw, dtype=float, count=n * ROW_FLOATS).reshape(n, ROW_FLOATS)
    out = {key: rows[:, c.start] if c.stop - c.start == 1 else rows[:, c] for key, c in COLUMNS.items()}
    out["est_error_m"] = np.linalg.norm(out["p_est_ned_m"] - out["p_true_ned_m"], axis=1)
    out["track_error_m"] = np.linalg.norm(out["p_true_ned_m"] - out["p_ref_ned_m"], axis=1)
    return out


def series_from_spool(path: Path) -> dict[str, np.ndarray]:
    return series_from_rows(path.read_bytes())


@dataclass(frozen=True)
class Goal:
    """The goal test of every vehicle side: reached once the reference has arrived (``t_s >=
    arrive_after_s``, on the caller's clock) with the TRUE position within ``radius_m`` of the goal
    and slower than ``speed_m_s``."""

    p_ned_m: np.ndarray
    radius_m: float
    speed_m_s: float
    arrive_after_s: float = 0.0

    def distance_m(self, p_ned_m: np.ndarray) -> float:
        return float(np.linalg.norm(p_ned_m - self.p_ned_m))

    def reached(self, t_s: float, p_ned_m: np.ndarray, v_ned_m_s: np.ndarray) -> bool:
        return bool(t_s >= self.arrive_after_s and self.distance_m(p_ned_m) <= self.radius_m
                    and np.linalg.norm(v_ned_m_s) <= self.speed_m_s)


@dataclass(frozen=True, slots=True)
class Row:
    t_s: float
    goal_distance_m: float


class FlightRecorder:
    """The vehicle process's record: a row per control step, spooled to ``spool_path``."""

    def __init__(self, goal_ned_m: np.ndarray, goal_radius_m: float, goal_speed_m_s: float,
                 arrive_after_s: float, spool_path: Path | None = None) -> None:
        self.goal = Goal(np.asarray(goal_ned_m, dtype=float), goal_radius_m, goal_speed_m_s, arrive_after_s)
        self._arrived = False
        self._pending = array("d")  # rows not yet spooled (all of them without a spool file)
        self.spool_path = spool_path
        if spool_path is not None:
            spool_path.write_bytes(b"")

    def record(
        self, out: Any, estimate: NavEstimate | None, setpoint: Setpoint | None, beta: float, nis: float,
        bias_ned_m: np.ndarray | None = None,
    ) -> Row:
        truth = out.truth[-1]
        p_ref = setpoint.p_ned_m if setpoint is not None else _NAN3
        b_est = _NAN3 if bias_ned_m is None else bias_ned_m  # none received yet: never the estimate's
        self._pending.extend(row(out.t_us, truth, estimate, p_ref, b_est, beta, nis))
        t_s = out.t_us * 1e-6
        self._arrived = self.goal.reached(t_s, truth.p_ned_m, truth.v_ned_m_s)
        return Row(t_s, self.goal.distance_m(truth.p_ned_m))

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
