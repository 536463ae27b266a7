"""Bounded history of NED accelerations and attitudes with prefix integrals, for O(1) blocks.

Each sample ``k`` holds the NED acceleration ``ã_k = R_k f̃_k + g`` (gravity-compensated, m/s²)
and the rotation ``R_k = R_ned_frd`` it was measured with, from its time ``t_k`` until the next
sample (zero-order hold, causal). With the prefix sums

    S1(t) = ∫₀ᵗ ã dt,   S2(t) = ∫₀ᵗ ã(s) s ds,   M1(t) = ∫₀ᵗ R ds,   M2(t) = ∫₀ᵗ R(s) s ds

the mean of the model (``model.py``) over any interval [t_a, t_b] is, exactly (no per-sample
loop), with the body-frame accelerometer bias ``a`` and the NED acceleration error ``d``
constant in the mean (random walks),

    A = M1(t_b) − M1(t_a) = ∫ R,      B = t_b A − (M2(t_b) − M2(t_a)) = ∫ (t_b − s) R(s) ds
    v_b = v_a + S1(t_b) − S1(t_a) − A a − T d
    p_b = p_a + v_a T + t_b (S1(t_b) − S1(t_a)) − (S2(t_b) − S2(t_a)) − B a − T²/2 d,   T = t_b − t_a
    b_b = α(T) b_a

which equals stepping ``v ← v + (ã_k − R_k a − d) dt`` sample by sample; A and B also give the
block's transition matrix. A sample arriving more than ``hold_max_s`` after the previous one is
a gap: the previous input is held for ``hold_max_s`` only, then the filter coasts at constant
velocity (a virtual zero-acceleration sample that keeps the last rotation), so a stale
acceleration is never integrated blindly across a gap.
"""

from __future__ import annotations

import bisect
import math

import numpy as np

from companion.estimator.model import IDENTITY9, Rot9

# A row: (t_s, ã (3), S1 (3), S2 (3), R (9, row-major), M1 (9), M2 (9)); time in s since the first sample.
Row = tuple[float, ...]
# The prefix integrals at one time: (t_s, S1 (3), S2 (3), M1 (9), M2 (9)).
Integrals = tuple[float, ...]
ROW_LEN = 37


class ImuHistory:
    """Append-only (then trimmed) record of held inputs and their prefix integrals."""

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

    def append(self, t_us: int, ax: float, ay: float, az: float, rot: Rot9 = IDENTITY9) -> bool:
        """Add a sample (strictly later than the last; the caller gates). Returns True on a gap."""
        rows = self.rows
        if not rows:
            self.t0_us = t_us
            self.t_us.append(t_us)
            rows.append((0.0, ax, ay, az, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, *rot, *(0.0,) * 18))
            return False
        r = rows[-1]
        t = (t_us - self.t0_us) * 1e-6  # type: ignore[operator]
        gap = t - r[0] > self.hold_max_s
        if gap:
            tv_us = self.t_us[-1] + self._hold_us
            self.t_us.append(tv_us)
            rows.append(_next_row(r, (tv_us - self.t0_us) * 1e-6, 0.0, 0.0, 0.0, r[10:19]))  # type: ignore[operator]
            r = rows[-1]
        self.t_us.append(t_us)
        # _next_row, inlined: this is the per-sample hot path
        (tp, hx, hy, hz, s1x, s1y, s1z, s2x, s2y, s2z, r0, r1, r2, r3, r4, r5, r6, r7, r8,
         m0, m1, m2, m3, m4, m5, m6, m7, m8, n0, n1, n2, n3, n4, n5, n6, n7, n8) = r
        dt = t - tp
        dm = dt * (tp + t) * 0.5
        rows.append((t, ax, ay, az, s1x + hx * dt, s1y + hy * dt, s1z + hz * dt,
                     s2x + hx * dm, s2y + hy * dm, s2z + hz * dm, *rot,
                     m0 + r0 * dt, m1 + r1 * dt, m2 + r2 * dt, m3 + r3 * dt, m4 + r4 * dt, m5 + r5 * dt,
                     m6 + r6 * dt, m7 + r7 * dt, m8 + r8 * dt,
                     n0 + r0 * dm, n1 + r1 * dm, n2 + r2 * dm, n3 + r3 * dm, n4 + r4 * dm, n5 + r5 * dm,
                     n6 + r6 * dm, n7 + r7 * dm, n8 + r8 * dm))
        return gap

    def append_batch(self, t_us: np.ndarray, a_ned: np.ndarray, rot: np.ndarray | None = None) -> None:
        """Vectorised ``append`` for samples already checked to be increasing and gap-free;
        ``rot`` (n, 9) row-major R_ned_frd, None = identity.

        Bit-for-bit the same rows as appending one by one (same operations in the same order;
        ``np.cumsum`` adds sequentially).
        """
        r = self.rows[-1]
        n = len(t_us)
        if rot is None:
            rot = np.tile(np.array(IDENTITY9), (n, 1))
        t = (t_us - self.t0_us) * 1e-6
        t_prev = np.concatenate(([r[0]], t[:-1]))
        held = np.hstack((a_ned, rot))
        held_prev = np.vstack((np.array(r[1:4] + r[10:19]), held[:-1]))
        dt = t - t_prev
        dm = dt * (t_prev + t) * 0.5
        inc1 = held_prev * dt[:, None]
        inc2 = held_prev * dm[:, None]
        i1 = np.cumsum(np.vstack((np.array(r[4:7] + r[19:28]), inc1)), axis=0)[1:]
        i2 = np.cumsum(np.vstack((np.array(r[7:10] + r[28:37]), inc2)), axis=0)[1:]
        block = np.hstack((t[:, None], a_ned, i1[:, 0:3], i2[:, 0:3], rot, i1[:, 3:12], i2[:, 3:12]))
        self.t_us.extend(t_us.tolist())
        self.rows.extend(map(tuple, block.tolist()))

    def integrals(self, t_us: int) -> Integrals:
        """(t_s, S1 (3), S2 (3), M1 (9), M2 (9)) at a time inside the history (held input
        extrapolated past the last).

        Rows are never rewritten once appended (trimming only drops old ones), so the value for a
        given time never changes: the engine keeps it with each fusion instead of recomputing it.
        """
        k = bisect.bisect_right(self.t_us, t_us) - 1
        r = self.rows[k]
        t = (t_us - self.t0_us) * 1e-6  # type: ignore[operator]
        tau = t - r[0]
        if tau == 0.0:
            return (t, *r[4:10], *r[19:37])
        dm = tau * (r[0] + t) * 0.5
        held = r[1:4] + r[10:19]
        s1 = r[4:7] + r[19:28]
        s2 = r[7:10] + r[28:37]
        i1 = [s + h * tau for s, h in zip(s1, held, strict=True)]
        i2 = [s + h * dm for s, h in zip(s2, held, strict=True)]
        return (t, *i1[0:3], *i2[0:3], *i1[3:12], *i2[3:12])

    def last_integrals(self) -> Integrals:
        """``integrals(last_t_us)``, read straight from the newest row (the held input adds 0)."""
        r = self.rows[-1]
        return (r[0], *r[4:10], *r[19:37])

    def propagate_mean(self, x: tuple[float, ...], t_a_us: int, t_b_us: int, alpha: float
                       ) -> tuple[float, ...]:
        """Mean of the model carried from t_a to t_b (t_a ≤ t_b, both inside the history)."""
        return mean_between(x, self.integrals(t_a_us), self.integrals(t_b_us), alpha)[0]

    def trim_before(self, t_us: int) -> None:
        """Drop samples no longer needed to integrate from ``t_us`` onwards."""
        k = bisect.bisect_right(self.t_us, t_us) - 1
        if k > 0:
            del self.t_us[:k]
            del self.rows[:k]


def rotation_blocks(a: Integrals, b: Integrals) -> tuple[list[float], list[float]]:
    """(A, B) row-major between the integrals ``a`` and ``b``: A = ∫R, B = ∫(t_b − s) R."""
    tb = b[0]
    A = [q - p for p, q in zip(a[7:16], b[7:16], strict=True)]
    B = [tb * d - (q - p) for d, p, q in zip(A, a[16:25], b[16:25], strict=True)]
    return A, B


def mean_between(x: tuple[float, ...], a: Integrals, b: Integrals, alpha: float
                 ) -> tuple[tuple[float, ...], list[float], list[float]]:
    """Mean of the model carried between the times of the integrals ``a`` and ``b`` (a before b),
    with the block's rotation integrals (A, B) (row-major 3×3 each; ``rotation_blocks``)."""
    ta, a1x, a1y, a1z, a2x, a2y, a2z = a[0:7]
    tb, b1x, b1y, b1z, b2x, b2y, b2z = b[0:7]
    A, B = rotation_blocks(a, b)
    T = tb - ta
    h = 0.5 * T * T
    dx, dy, dz = b1x - a1x, b1y - a1y, b1z - a1z
    ux, uy, uz, ex, ey, ez = x[9:15]
    return (
        x[0] + x[3] * T + (tb * dx - (b2x - a2x)) - (B[0] * ux + B[1] * uy + B[2] * uz) - ex * h,
        x[1] + x[4] * T + (tb * dy - (b2y - a2y)) - (B[3] * ux + B[4] * uy + B[5] * uz) - ey * h,
        x[2] + x[5] * T + (tb * dz - (b2z - a2z)) - (B[6] * ux + B[7] * uy + B[8] * uz) - ez * h,
        x[3] + dx - (A[0] * ux + A[1] * uy + A[2] * uz) - ex * T,
        x[4] + dy - (A[3] * ux + A[4] * uy + A[5] * uz) - ey * T,
        x[5] + dz - (A[6] * ux + A[7] * uy + A[8] * uz) - ez * T,
        alpha * x[6], alpha * x[7], alpha * x[8],
        ux, uy, uz, ex, ey, ez,
    ), A, B


def _next_row(r: Row, t: float, ax: float, ay: float, az: float, rot: tuple[float, ...]) -> Row:
    dt = t - r[0]
    dm = dt * (r[0] + t) * 0.5
    held = r[1:4] + r[10:19]
    i1 = [s + h * dt for s, h in zip(r[4:7] + r[19:28], held, strict=True)]
    i2 = [s + h * dm for s, h in zip(r[7:10] + r[28:37], held, strict=True)]
    return (t, ax, ay, az, *i1[0:3], *i2[0:3], *rot, *i1[3:12], *i2[3:12])


def finite3(x: float, y: float, z: float) -> bool:
    """All three finite (plain-float check for the per-sample path)."""
    return math.isfinite(x) and math.isfinite(y) and math.isfinite(z)
