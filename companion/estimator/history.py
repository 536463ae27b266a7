"""Bounded history of NED accelerations with prefix integrals, for O(1) mean propagation.

Each acceleration ``a_k`` (gravity-compensated, NED, m/s²) is held from its time ``t_k`` until
the next sample (zero-order hold, causal). With the prefix sums

    S1(t) = ∫₀ᵗ a dt,   S2(t) = ∫₀ᵗ a(s) s ds

the mean of eq. 12 over any interval [t_a, t_b] is, exactly (no per-sample loop):

    v_b = v_a + S1(t_b) − S1(t_a)
    p_b = p_a + v_a T + t_b (S1(t_b) − S1(t_a)) − (S2(t_b) − S2(t_a)),   T = t_b − t_a
    b_b = α(T) b_a

and, with the acceleration bias ``a`` (constant in the mean: a random walk), ``v_b −= a T`` and
``p_b −= a T²/2``; this equals stepping ``x ← F x + B ã`` (eq. 12) sample by sample.
A sample arriving more than ``hold_max_s`` after the previous one is a gap: the previous input
is held for ``hold_max_s`` only, then the filter coasts at constant velocity (a virtual
zero-acceleration sample), so a stale acceleration is never integrated blindly across a gap.
"""

from __future__ import annotations

import bisect
import math

import numpy as np

# A row: (t_s, ax, ay, az, S1x, S1y, S1z, S2x, S2y, S2z), time in seconds since the first sample.
Row = tuple[float, float, float, float, float, float, float, float, float, float]
# The prefix integrals at one time: (t_s, S1x, S1y, S1z, S2x, S2y, S2z).
Integrals = tuple[float, float, float, float, float, float, float]


class ImuHistory:
    """Append-only (then trimmed) record of held accelerations and their prefix integrals."""

    def __init__(self, hold_max_s: float) -> None:
        self.hold_max_s = hold_max_s
        self._hold_us = int(round(hold_max_s * 1e6))
        self.t0_us: int | None = None
        self.t_us: list[int] = []
        self.rows: list[Row] = []

    def __len__(self) -> int:
        return len(self.rows)

    @property
    def first_t_us(self) -> int:
        return self.t_us[0]

    @property
    def last_t_us(self) -> int:
        return self.t_us[-1]

    def append(self, t_us: int, ax: float, ay: float, az: float) -> bool:
        """Add a sample (strictly later than the last; the caller gates). Returns True on a gap."""
        rows = self.rows
        if not rows:
            self.t0_us = t_us
            self.t_us.append(t_us)
            rows.append((0.0, ax, ay, az, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
            return False
        r = rows[-1]
        t = (t_us - self.t0_us) * 1e-6  # type: ignore[operator]
        gap = t - r[0] > self.hold_max_s
        if gap:
            tv_us = self.t_us[-1] + self._hold_us
            self.t_us.append(tv_us)
            rows.append(_next_row(r, (tv_us - self.t0_us) * 1e-6, 0.0, 0.0, 0.0))  # type: ignore[operator]
            r = rows[-1]
        self.t_us.append(t_us)
        # _next_row(r, t, ax, ay, az), inlined: this is the per-sample hot path
        tp, hx, hy, hz, s1x, s1y, s1z, s2x, s2y, s2z = r
        dt = t - tp
        m = (tp + t) * 0.5
        ix, iy, iz = hx * dt, hy * dt, hz * dt
        rows.append((t, ax, ay, az, s1x + ix, s1y + iy, s1z + iz, s2x + ix * m, s2y + iy * m, s2z + iz * m))
        return gap

    def append_batch(self, t_us: np.ndarray, a_ned: np.ndarray) -> None:
        """Vectorised ``append`` for samples already checked to be increasing and gap-free.

        Bit-for-bit the same rows as appending one by one (same operations in the same order;
        ``np.cumsum`` adds sequentially).
        """
        r = self.rows[-1]
        t = (t_us - self.t0_us) * 1e-6
        t_prev = np.concatenate(([r[0]], t[:-1]))
        a_prev = np.vstack((np.array(r[1:4]), a_ned[:-1]))
        dt = t - t_prev
        inc = a_prev * dt[:, None]
        mid = (t_prev + t) * 0.5
        s1 = np.cumsum(np.vstack((np.array(r[4:7]), inc)), axis=0)[1:]
        s2 = np.cumsum(np.vstack((np.array(r[7:10]), inc * mid[:, None])), axis=0)[1:]
        block = np.hstack((t[:, None], a_ned, s1, s2))
        self.t_us.extend(t_us.tolist())
        self.rows.extend(map(tuple, block.tolist()))

    def integrals(self, t_us: int) -> Integrals:
        """(t_s, S1 (3), S2 (3)) at a time inside the history (held input extrapolated past the last).

        Rows are never rewritten once appended (trimming only drops old ones), so the value for a
        given time never changes: the engine keeps it with each fusion instead of recomputing it.
        """
        k = bisect.bisect_right(self.t_us, t_us) - 1
        r = self.rows[k]
        t = (t_us - self.t0_us) * 1e-6  # type: ignore[operator]
        tau = t - r[0]
        m = (r[0] + t) * 0.5
        ix, iy, iz = r[1] * tau, r[2] * tau, r[3] * tau
        return t, r[4] + ix, r[5] + iy, r[6] + iz, r[7] + ix * m, r[8] + iy * m, r[9] + iz * m

    def last_integrals(self) -> Integrals:
        """``integrals(last_t_us)``, read straight from the newest row (the held input adds 0)."""
        r = self.rows[-1]
        return r[0], r[4], r[5], r[6], r[7], r[8], r[9]

    def propagate_mean(self, x: tuple[float, ...], t_a_us: int, t_b_us: int, alpha: float
                       ) -> tuple[float, ...]:
        """Mean of eq. 12 carried from t_a to t_b (t_a ≤ t_b, both inside the history)."""
        return mean_between(x, self.integrals(t_a_us), self.integrals(t_b_us), alpha)

    def trim_before(self, t_us: int) -> None:
        """Drop samples no longer needed to integrate from ``t_us`` onwards."""
        k = bisect.bisect_right(self.t_us, t_us) - 1
        if k > 0:
            del self.t_us[:k]
            del self.rows[:k]


def mean_between(x: tuple[float, ...], a: Integrals, b: Integrals, alpha: float) -> tuple[float, ...]:
    """Mean of eq. 12 carried between the times of the integrals ``a`` and ``b`` (a before b)."""
    ta, a1x, a1y, a1z, a2x, a2y, a2z = a
    tb, b1x, b1y, b1z, b2x, b2y, b2z = b
    T = tb - ta
    h = 0.5 * T * T
    dx, dy, dz = b1x - a1x, b1y - a1y, b1z - a1z
    ux, uy, uz = x[9], x[10], x[11]
    return (
        x[0] + x[3] * T + (tb * dx - (b2x - a2x)) - ux * h,
        x[1] + x[4] * T + (tb * dy - (b2y - a2y)) - uy * h,
        x[2] + x[5] * T + (tb * dz - (b2z - a2z)) - uz * h,
        x[3] + dx - ux * T, x[4] + dy - uy * T, x[5] + dz - uz * T,
        alpha * x[6], alpha * x[7], alpha * x[8],
        ux, uy, uz,
    )


def _next_row(r: Row, t: float, ax: float, ay: float, az: float) -> Row:
    dt = t - r[0]
    m = (r[0] + t) * 0.5
    ix, iy, iz = r[1] * dt, r[2] * dt, r[3] * dt
    return (t, ax, ay, az, r[4] + ix, r[5] + iy, r[6] + iz, r[7] + ix * m, r[8] + iy * m, r[9] + iz * m)


def finite3(x: float, y: float, z: float) -> bool:
    """All three finite (plain-float check for the per-sample path)."""
    return math.isfinite(x) and math.isfinite(y) and math.isfinite(z)
