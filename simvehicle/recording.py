"""Per-control-step record of a flight in the vehicle process (truth + what it received).

The series keys are those of ``gcs_tools.fly`` (docs/ARCHITECTURE.md); the launcher turns
them into the same summary and figures. The estimated bias arrives at 5 Hz (DEBUG_VECT
``GNSS_BIAS``), so ``b_est_ned_m`` holds the latest received (NaN before the first).
"""

from __future__ import annotations

import math
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
                 arrive_after_s: float) -> None:
        self.goal_ned_m = np.asarray(goal_ned_m, dtype=float)
        self.goal_radius_m = goal_radius_m
        self.goal_speed_m_s = goal_speed_m_s
        self.arrive_after_s = arrive_after_s  # the reference reaches the goal at this time
        self._arrived = False
        self._rows: dict[str, list[Any]] = {k: [] for k in SERIES_KEYS}
        self._goal_distance_m = math.inf

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
        for key, value in values.items():
            self._rows[key].append(value)
        self._goal_distance_m = float(np.linalg.norm(p_true - self.goal_ned_m))
        self._arrived = (self._goal_distance_m <= self.goal_radius_m
                         and float(np.linalg.norm(truth.v_ned_m_s)) <= self.goal_speed_m_s
                         and out.t_us / 1e6 >= self.arrive_after_s)
        return Row(out.t_us / 1e6, self._goal_distance_m)

    def reached_goal(self) -> bool:
        """Within the goal radius, slow enough, and not before the reference arrived (as ``fly``)."""
        return self._arrived

    def series(self) -> dict[str, np.ndarray]:
        return {k: np.asarray(v, dtype=float) for k, v in self._rows.items()}

    def save(self, path: Path) -> None:
        np.savez(path, **self.series())  # type: ignore[arg-type]  # numpy stubs type **kwds as bool


SERIES_KEYS = (
    "t_s", "p_true_ned_m", "p_est_ned_m", "p_ref_ned_m", "b_true_ned_m", "b_est_ned_m", "beta", "nis",
    "latency_s", "clearance_m", "est_error_m", "track_error_m",
)
