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

Held time. An interval longer than 1.5 periods of the IMU (the period: the median of the last 8
sample intervals; a missing sample makes an interval two periods or more) holds its sample over
time it did not measure. Over the L seconds the sample is held (the interval, or ``hold_max_s`` for
a gap), with the period p, the hold adds to each axis's velocity variance (besides the model's σ_q² L)

    ΔP_vv = σ_q² L (L − p) / p  +  σ_j² L³ / 3

The first term is the held sample's white noise: a sample carries variance σ_q² / p, held over L it
gives σ_q² L² / p where L / p measured samples would give σ_q² L. The second is the change of the
acceleration during the hold, a random walk of density σ_j² (``imu_hold_acc_rw_m_s2_sqrt_s``):
∫₀ᴸ (a(s) − a(0)) ds has variance σ_j² L³ / 3. Both are spread evenly over the held interval as a
white acceleration of density n(s) = σ_q² w + σ_j² j (w = (L − p) / p, j = L² / 3), so blocks
compose and a block holding part of a hold takes its part. The history keeps the moments of w and
j, W = (∫ w, ∫ w s, ∫ w s²) and J alike, as prefix sums (rows never rewritten: a late fix
re-propagated through the history gets the same noise), and a block [t_a, t_b] adds

    Q_vv += ∫ n,   Q_pv += ∫ n (t_b − s),   Q_pp += ∫ n (t_b − s)²   (each axis)

(``_core.Propagator``, with σ_q² and σ_j² given). Intervals no longer than 1.5 periods hold nothing
and add nothing: a stream without a lost sample is predicted bit for bit as before. The coast after
a gap's ``hold_max_s`` adds none either (as before).
"""

from __future__ import annotations

import math

from companion.estimator import _core

# A row: (t_s, ã (3), S1 (3), S2 (3), R (9, row-major), M1 (9), M2 (9), the held-time densities (w, j) of
# the interval ending at it, W (3), J (3)); time in s since the first sample.
Row = tuple[float, ...]
# The prefix integrals at one time: (t_s, S1 (3), S2 (3), M1 (9), M2 (9), W (3), J (3)).
Integrals = tuple[float, ...]

# The numeric core is C (``_core.c``: the formulas above, the same operations in the same order
# as the float expressions they replaced; tested against a pure-Python history in the tests).
# (−A, −B) row-major between two integrals (A = ∫R, B = ∫(t_b − s) R, negated as they enter the
# mean and F):  rotation_blocks(a, b) -> (list of 9, list of 9)
rotation_blocks = _core.rotation_blocks
# The mean of the model carried between the times of the integrals ``a`` and ``b`` (a before b),
# with the block's (−A, −B):  mean_between(x, a, b, alpha) -> (x at b, −A, −B)
mean_between = _core.mean_between


class ImuHistory(_core.History):
    """Append-only (then trimmed) record of held inputs and their prefix integrals.

    ``ImuHistory(hold_max_s)``. The core's methods (``_core.History``):

    * ``append(t_us, ax, ay, az, rot=identity) -> gap``: add a sample (strictly later than the
      last; the caller gates);
    * ``push(t_us, ax, ay, az, rot)`` and ``push_frd(t_us, f_frd, rot, g)``: the engine's gated
      per-sample path: a sample not finite or not later than the last is not used; each outcome
      is counted in ``counts`` (used, gaps, not finite, time not increasing); returns True when
      the history has grown past ``trim_len`` (the engine trims). ``push_frd`` rotates the body
      specific force first (R f̃ + [0, 0, g]);
    * ``append_batch(t_us, a_ned, rot)``: many samples (int64 (n,), float64 (n, 3), (n, 9) or None),
      already checked increasing and gap-free; the same rows as appending one by one (counted
      as used);
    * ``integrals(t_us)``: (t_s, S1, S2, M1, M2, W, J) at a time inside the history (held input
      extrapolated past the last, with no held time: that is known when the next sample comes);
      rows are never rewritten once appended, so the value for a time up to the newest sample never
      changes: the engine keeps it with each fusion;
    * ``last_integrals()``, ``trim_before(t_us)`` (drop samples not needed from ``t_us`` on);
    * ``len()``, ``first_t_us``, ``last_t_us``, ``t0_us``, ``hold_max_s``, and copies ``rows``,
      ``t_us`` (for tests).
    """

    def propagate_mean(self, x: tuple[float, ...], t_a_us: int, t_b_us: int, alpha: float
                       ) -> tuple[float, ...]:
        """Mean of the model carried from t_a to t_b (t_a ≤ t_b, both inside the history)."""
        return mean_between(x, self.integrals(t_a_us), self.integrals(t_b_us), alpha)[0]


def finite3(x: float, y: float, z: float) -> bool:
    """All three finite (plain-float check for the per-sample path)."""
    return math.isfinite(x) and math.isfinite(y) and math.isfinite(z)
