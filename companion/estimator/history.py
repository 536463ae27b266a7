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
block's transition matrix.

The hold limit. A sample is held until the next one, for ``lim`` at most: ``lim = hold_max_s``, or,
with ``hold_periods`` k > 0, ``max(hold_max_s, k p)`` with p the IMU's period: the median (the lower
one of an even count) of the last 8 sample intervals before this one, in µs (``k p`` rounded to the
µs). The period follows the log's own stamps, so a 10 Hz IMU (p = 100 ms) is integrated sample to
sample like a 200 Hz one, while a lost stretch of a 200 Hz stream (k p = 12.5 ms < 50 ms) is held
for ``hold_max_s`` as before; the median of 8 is not moved by one long interval (an outage), nor by
lost samples until half of the last 8 intervals are long. A sample arriving more than ``lim`` after
the previous one is a gap: the previous input is held for ``lim`` only, then the filter coasts at
constant velocity (a virtual zero-acceleration sample that keeps the last rotation), so a stale
acceleration is never integrated blindly across a gap. The limit, like the held time below, is a
function of the IMU's arrivals only, decided once when the sample is appended and kept in its rows.

Held time. An interval longer than 1.5 periods of the IMU (a missing sample makes an interval two
periods or more) holds its sample over time it did not measure. Over the L seconds of the interval
(a gap's whole interval: its hold and its coast), with the period p, the hold adds to each axis's
velocity variance (besides the model's σ_q² L)

    ΔP_vv = σ_q² L (L − p) / p  +  σ_j² L³ / 3

The first term is the held sample's white noise: a sample carries variance σ_q² / p, held over L it
gives σ_q² L² / p where L / p measured samples would give σ_q² L. The second is the change of the
acceleration during the hold, a random walk of density σ_j² (``imu_hold_acc_rw_m_s2_sqrt_s``):
∫₀ᴸ (a(s) − a(0)) ds has variance σ_j² L³ / 3. Both are spread evenly over the interval as a
white acceleration of density n(s) = σ_q² w + σ_j² j (w = (L − p) / p, j = L² / 3), so blocks
compose and a block holding part of a hold takes its part. A gap's coast, C = L − lim seconds at
zero acceleration, drops the held acceleration ã too: its velocity is off by ã C besides, so the
coast adds ã_i² C² to axis i's velocity variance, spread evenly over the coast (density
c_i = ã_i² C; its position terms, ã² C⁴ / 3 and ã² C³ / 2, cover the exact ã² C⁴ / 4 and ã² C³ / 2).
With both, a gap's velocity variance grows as if the whole interval had been held, plus what the
coast's mean leaves out: a long IMU outage inflates P (as L³), it does not freeze it. The history
keeps the moments of w, j and c, W = (∫ w, ∫ w s, ∫ w s²), J alike and C (three per axis), as prefix
sums (rows never rewritten: a late fix re-propagated through the history gets the same noise), and a
block [t_a, t_b] adds

    Q_vv += ∫ n,   Q_pv += ∫ n (t_b − s),   Q_pp += ∫ n (t_b − s)²   (each axis; n with its c_i)

(``_core.Propagator``, with σ_q², σ_j² and the coast's scale, 1 or 0, given). Intervals no longer
than 1.5 periods and the limit hold nothing and add nothing: a stream without a lost sample is
predicted bit for bit as before.
"""

from __future__ import annotations

import math

from companion.estimator import _core

# A row: (t_s, ã (3), S1 (3), S2 (3), R (9, row-major), M1 (9), M2 (9), the held-time densities (w, j) of
# the interval ending at it, W (3), J (3), the coast's densities c (3, per axis) of that interval, C (9:
# (∫ c_i, ∫ c_i s, ∫ c_i s²) per axis)); time in s since the first sample.
Row = tuple[float, ...]
# The prefix integrals at one time: (t_s, S1 (3), S2 (3), M1 (9), M2 (9), W (3), J (3), C (9)).
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

    ``ImuHistory(hold_max_s, hold_periods=0, max_force_m_s2=inf)`` (the hold limit: above). The core's methods
    (``_core.History``):

    * ``append(t_us, ax, ay, az, rot=identity) -> gap``: add a sample (strictly later than the
      last; the caller gates);
    * ``push(t_us, ax, ay, az, rot)`` and ``push_frd(t_us, f_frd, rot, g)``: the engine's gated
      per-sample path: a sample not finite or not later than the last is not used; each outcome
      is counted in ``counts`` (used, gaps, not finite, time not increasing, out of range); returns
      True when the history has grown past ``trim_len`` (the engine trims). ``push_frd`` rotates the
      body specific force first (R f̃ + [0, 0, g]), and does not use one beyond ``max_force_m_s2``
      (third argument, default inf; the timeline gives ``MAX_SPECIFIC_FORCE_M_S2``, 16 g) on an axis;
    * ``append_batch(t_us, a_ned, rot)``: many samples (int64 (n,), float64 (n, 3), (n, 9) or None),
      already checked increasing and gap-free; the same rows as appending one by one (counted
      as used);
    * ``integrals(t_us)``: (t_s, S1, S2, M1, M2, W, J, C) at a time inside the history (held input
      extrapolated past the last, with no held time: that is known when the next sample comes);
      rows are never rewritten once appended, so the value for a time up to the newest sample never
      changes: the engine keeps it with each fusion;
    * ``last_integrals()``, ``trim_before(t_us)`` (drop samples not needed from ``t_us`` on);
    * ``len()``, ``first_t_us``, ``last_t_us``, ``t0_us``, ``hold_max_s``, ``hold_periods``, and copies
      ``rows``,
      ``t_us`` (for tests).
    """

    def propagate_mean(self, x: tuple[float, ...], t_a_us: int, t_b_us: int, alpha: float
                       ) -> tuple[float, ...]:
        """Mean of the model carried from t_a to t_b (t_a ≤ t_b, both inside the history)."""
        return mean_between(x, self.integrals(t_a_us), self.integrals(t_b_us), alpha)[0]


def finite3(x: float, y: float, z: float) -> bool:
    """All three finite (plain-float check for the per-sample path)."""
    return math.isfinite(x) and math.isfinite(y) and math.isfinite(z)
