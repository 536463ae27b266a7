"""Minimum-jerk segments between waypoints (eq. 5), at rest at every waypoint.

``p(s) = (1 - α(s))·p_i + α(s)·p_{i+1}``, ``α(s) = 10s³ - 15s⁴ + 6s⁵``, ``s = t/T_i``.
On a segment of length L and duration T the peak speed is ``(15/8)·L/T`` (at s = 1/2) and the
peak acceleration ``(10/√3)·L/T²`` (at s = 1/2 ∓ √3/6), so the shortest T meeting both
limits is ``max(15/8·L/v_max, sqrt(10/√3·L/a_max))``.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

PEAK_SPEED_FACTOR = 15.0 / 8.0  # max α'(s)
PEAK_ACC_FACTOR = 10.0 / math.sqrt(3.0)  # max |α''(s)|


def alpha(s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """α(s) and its first and second derivatives with respect to s."""
    s2 = s * s
    a = s2 * s * (10.0 - 15.0 * s + 6.0 * s2)
    da = 30.0 * s2 * ((1.0 - s) * (1.0 - s))
    dda = 60.0 * s * (1.0 - 3.0 * s + 2.0 * s2)
    return a, da, dda


def segment_duration_s(length_m: np.ndarray, speed_max_m_s: float | np.ndarray,
                       acc_max_m_s2: float) -> np.ndarray:
    """Shortest segment durations whose peak speed and acceleration stay within the limits
    (``speed_max_m_s``: one limit, or one per segment)."""
    length_m = np.asarray(length_m, dtype=float)
    return np.maximum(PEAK_SPEED_FACTOR * length_m / speed_max_m_s,
                      np.sqrt(PEAK_ACC_FACTOR * length_m / acc_max_m_s2))


@dataclass(frozen=True)
class MinJerkTrajectory:
    """Rest-to-rest minimum-jerk segments through ``waypoints`` (N, 3), starting at ``t_start_s``."""

    waypoints: np.ndarray
    durations_s: np.ndarray  # (N - 1,)
    t_start_s: float = 0.0

    @classmethod
    def through(cls, waypoints: np.ndarray, speed_max_m_s: float | np.ndarray, acc_max_m_s2: float,
                t_start_s: float = 0.0) -> MinJerkTrajectory:
        """Segments at their shortest durations; ``speed_max_m_s`` one peak speed, or one per segment."""
        wp = np.array(waypoints, dtype=float)
        lengths_m = np.linalg.norm(np.diff(wp, axis=0), axis=1)
        if wp.shape[0] < 2 or np.any(lengths_m <= 0):
            raise ValueError("a minimum-jerk trajectory needs at least two distinct consecutive waypoints")
        durations = segment_duration_s(lengths_m, speed_max_m_s, acc_max_m_s2)
        wp.setflags(write=False)
        durations.setflags(write=False)
        return cls(wp, durations, float(t_start_s))

    @property
    def duration_s(self) -> float:
        return float(self.durations_s.sum())

    @cached_property
    def _table(self) -> tuple[np.ndarray, np.ndarray, list[float], list[float], list[float],
                              list[tuple[float, ...]], list[tuple[float, ...]]]:
        """Segment ends/starts (arrays and float lists), durations, start points and deltas."""
        ends = np.cumsum(self.durations_s)
        starts = ends - self.durations_s
        delta = self.waypoints[1:] - self.waypoints[:-1]
        return (ends, starts, ends.tolist(), starts.tolist(), self.durations_s.tolist(),
                [tuple(w) for w in self.waypoints.tolist()], [tuple(d) for d in delta.tolist()])

    def reference(self, t_s: float | np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity, acceleration at time(s) ``t_s``: (3,) each, or (K, 3) for (K,) times.

        Before ``t_start_s`` the start is held, after the last segment the goal (both at rest).
        A scalar time takes a float path with the same arithmetic (bit-for-bit equal, tested).
        """
        if np.ndim(t_s) == 0:
            return self._reference_at(float(t_s))
        ends, starts = self._table[:2]
        t = np.asarray(t_s, dtype=float)
        tau = t - self.t_start_s
        k = np.clip(np.searchsorted(ends, tau, side="right"), 0, len(self.durations_s) - 1)
        T = self.durations_s[k]
        s = np.clip((tau - starts[k]) / T, 0.0, 1.0)
        a, da, dda = alpha(s)
        delta = self.waypoints[k + 1] - self.waypoints[k]
        p = self.waypoints[k] + a[..., None] * delta
        v = (da / T)[..., None] * delta
        acc = (dda / (T * T))[..., None] * delta
        return p, v, acc

    def _reference_at(self, t_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        _, _, ends, starts, durations, points, deltas = self._table
        tau = t_s - self.t_start_s
        k = min(bisect.bisect_right(ends, tau), len(durations) - 1)
        T = durations[k]
        s = min(max((tau - starts[k]) / T, 0.0), 1.0)
        a, da, dda = alpha(s)  # type: ignore[arg-type]
        (pn, pe, pd), (dn, de, dd) = points[k], deltas[k]
        kv, ka = da / T, dda / (T * T)
        return (np.array([pn + a * dn, pe + a * de, pd + a * dd]),
                np.array([kv * dn, kv * de, kv * dd]),
                np.array([ka * dn, ka * de, ka * dd]))
