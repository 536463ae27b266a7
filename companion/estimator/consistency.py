"""The honest reported accuracy, shared by the loose (``engine``) and the tight (``companion.tight``)
filters: the position covariance times a consistency factor measured from the filter's own fused
innovations over the last ``accuracy_window_s``, the variance-of-unit-weight test a receiver applies
to its reported accuracy, extended over time (docs/tight.md "Reported accuracy", docs/estimator.md):

    k = max(1, Σ_s (Σ_t w_t ν_s,t)² / Σ_s Σ_t w_t²),   w_t = exp(−(t_now − t)/τ),  τ = accuracy_window_s

over the channels ``s`` fused (the tight filter's satellites; the loose filter's N, E, D axes of a fix),
each innovation normalised by the variance it was fused with, ν = y / √S. A ``Fit`` is immutable and
stored with each filter entry, so a late measurement re-fused out of sequence gives the same factor.
Pure: numpy, and the C core for the filters' per-fix sums (``_core``: scatter_add, scatter1_add,
decay_add3; their Python forms are in the tests).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from companion.estimator._core import decay_add3 as _decay_add3
from companion.estimator._core import scatter1_add as _scatter1_add
from companion.estimator._core import scatter_add as _scatter_add

FIT_W2_MIN = 1e-3  # a channel's weight in Fit below this (gone for a few windows): forgotten
# the largest variance inflation Scatter.correlation gives: the fixes of a 20 s window at 5 Hz (ρ → 1: one
# error shared by all; the floor is then one fix's variance)
C_MAX = 100.0
# the largest correction of the scatter about the window mean for the window mean's share (Scatter.variance):
# 2, chosen on the real-flight campaign's tuning flights (docs/estimator.md, "Reported accuracy")
SCATTER_MAX = 2.0


# a NamedTuple from all its fields in order without its generated __new__'s Python call (what it does)
_new = tuple.__new__


def _sorted_union(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.union1d(a, b)`` for integer keys, without ``np.unique`` (which imports ``numpy.ma``, 11 ms,
    on its first call: the loose filter's first fix would wait for it)."""
    keys = np.concatenate((a, b))
    keys.sort()
    return keys[np.concatenate(([True], keys[1:] != keys[:-1]))] if len(keys) else keys


class Fit(NamedTuple):
    """The fused innovations' consistency over the last ``window_s`` (the reported accuracy's
    inflation, ``inflation``): per channel (``key``, sorted) the exponentially weighted sum of its
    normalised innovations ν = y / √S and of the squared weights, as of ``t_us``."""

    key: np.ndarray = np.zeros(0, dtype=np.int64)
    nu_sum: np.ndarray = np.zeros(0)
    w2_sum: np.ndarray = np.zeros(0)
    t_us: int = 0

    def add(self, t_us: int, key: np.ndarray, nu: np.ndarray, window_s: float) -> Fit:
        """This measurement's channels added, the older sums decayed by exp(−Δt / window_s)."""
        a = math.exp(-(t_us - self.t_us) * 1e-6 / window_s) if window_s > 0.0 and len(self.key) else 0.0
        if key is self.key or (len(key) == len(self.key) and np.array_equal(key, self.key)):  # the usual
            nu_sum, w2_sum = a * self.nu_sum, (a * a) * self.w2_sum  # new arrays, then in place
            nu_sum += nu
            w2_sum += 1.0
            return Fit(self.key, nu_sum, w2_sum, t_us)
        if len(key) == len(self.key) and np.array_equal(np.sort(key), self.key):
            # the same channels in another order (a receiver's order, by C/N0): what the general case
            # below gives, without the union (self.key is sorted and unique, so key is a permutation)
            nu_sum, w2_sum = a * self.nu_sum, (a * a) * self.w2_sum
            at = np.searchsorted(self.key, key)
            nu_sum[at] += nu
            w2_sum += 1.0
            return Fit(self.key, nu_sum, w2_sum, t_us)
        keys = _sorted_union(self.key, key)
        if len(keys) == len(key) and np.array_equal(keys, key):
            keys = key  # the caller's own (sorted) keys: the next add with them takes the path above at once
        nu_sum, w2_sum = np.zeros(len(keys)), np.zeros(len(keys))
        old = np.searchsorted(keys, self.key)
        nu_sum[old], w2_sum[old] = a * self.nu_sum, a * a * self.w2_sum
        new = np.searchsorted(keys, key)
        np.add.at(nu_sum, new, nu)
        np.add.at(w2_sum, new, 1.0)
        keep = w2_sum > FIT_W2_MIN
        if keep.all():
            return Fit(keys, nu_sum, w2_sum, t_us)
        return Fit(keys[keep], nu_sum[keep], w2_sum[keep], t_us)

    def inflation(self) -> float:
        """max(1, Σ_s (Σ_t w_t ν_st)² / Σ_s Σ_t w_t²): the windowed NIS per degree of freedom of each
        channel's weighted mean innovation. A consistent filter's innovations are white with unit
        variance: 1 on average. Errors larger than S raise it by their variance ratio, errors correlated
        in time (a reflection lasting seconds, which the filter fused as independent measurements) by
        the variance ratio of their window average to white noise's (up to (1 + a)/(1 − a),
        a = e^(−Δt/window))."""
        den = float(self.w2_sum.sum())
        # squares summed by numpy's reduction, not a BLAS dot product: on a CPU with FMA the BLAS
        # kernel rounds differently (the last bit, in a fifth of the cases), so the floats path
        # (fit_inflation3) and this one agree on every machine
        return max(1.0, float((self.nu_sum * self.nu_sum).sum()) / den) if den > 0.0 else 1.0


AXES3 = np.arange(3)  # the loose filter's Fit channels of a fix: N, E, D (fit_add3's key, by identity)


def fit_add3(fit: Fit, t_us: int, nu0: float, nu1: float, nu2: float, window_s: float) -> Fit:
    """``fit.add(t_us, AXES3, (nu0, nu1, nu2), window_s)`` (``window_s`` > 0), the same numbers: once
    ``fit`` holds the three axes, its sums decayed and added on floats (the per-element operations of
    ``Fit.add``'s numpy path in the C core, without its array arithmetic at every fix: the loose filter's)."""
    if fit.key is not AXES3:  # the first fix (an empty Fit): Fit.add's general path
        return fit.add(t_us, AXES3, np.array((nu0, nu1, nu2)), window_s)
    a = math.exp(-(t_us - fit.t_us) * 1e-6 / window_s)
    nu_sum, w2_sum = _decay_add3(fit.nu_sum, fit.w2_sum, a, nu0, nu1, nu2)  # a nu_sum + nu, a² w2_sum + 1
    return _new(Fit, (AXES3, nu_sum, w2_sum, t_us))


def fit_inflation3(fit: Fit) -> float:
    """``fit.inflation()`` on floats for the loose filter's Fit (three axes, or none yet): the same number
    (numpy's sums of three values are the left-to-right sums, checked in the tests)."""
    if fit.key is not AXES3:
        return fit.inflation()
    n0, n1, n2 = fit.nu_sum.tolist()
    w0, w1, w2 = fit.w2_sum.tolist()
    den = w0 + w1 + w2
    if not den > 0.0:
        return 1.0
    k = (n0 * n0 + n1 * n1 + n2 * n2) / den
    return k if k > 1.0 else 1.0


def accuracy_inflation(fit: Fit | None, window_s: float) -> float:
    """The factor (≥ 1) on the reported position variances: ``fit``'s, 1 without one or when
    ``window_s`` is 0 (report the covariance as it is)."""
    return 1.0 if fit is None or window_s <= 0.0 else fit.inflation()


def variance_scale(k: float) -> np.ndarray | None:
    """The factors (9,) on the variances (p, v, b) a filter reports: ``k`` on the position's, 1 on the
    rest; None when k is 1 (report them as they are)."""
    return np.array((k, k, k, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0)) if k > 1.0 else None


def check_accuracy_window(window_s: float) -> None:
    """``accuracy_window_s`` must be a finite number ≥ 0 (ValueError naming it otherwise)."""
    if not (math.isfinite(window_s) and window_s >= 0.0):
        raise ValueError(f"accuracy_window_s: must be a finite number >= 0, got {window_s!r}")


class Scatter(NamedTuple):
    """The fused fixes' own horizontal scatter over the last ``window_s``, independent of the filter's
    position (docs/estimator.md, "Reported accuracy"). Each fix less the motion since the first one
    (the trapezoid of the velocities at the fixes: the receiver's, or the filter's where it states
    none) is ``q``, the fix's error plus a slow drift; exponentially weighted sums (N and E pooled) of
    ``q``, ``q²`` and of the squared changes of ``q`` over one and over two fixes, as of ``t_us``:

    * ``variance()``: the scatter of ``q`` about its window mean (unbiased for independent fixes), the
      variance of one fix's error as far as it varies within the window;
    * ``correlation()``: c = (1 + ρ) / (1 − ρ), the variance of a mean of many fixes over its
      independent-fix value for errors whose correlation from one fix to the next is ρ (a Gauss-Markov
      error of correlation time τ at fix period Δt: ρ = e^(−Δt/τ)), with 1 + ρ = E[(q_i − q_i−2)²] /
      E[(q_i − q_i−1)²] (exact for that process; a drift of the motion removed is second order over two
      fixes). 1 for independent fixes, at most ``C_MAX``.

    One axis alone (the vertical): ``Scatter1``, the same statistics. The fixes may be a receiver's (the
    loose filter's) or the tight filter's per-epoch snapshot positions (``companion.tight.engine``): any
    series of positions independent of the filter that it averages."""

    t_us: int = -1  # -1: no fix yet
    z: tuple[float, float] = (0.0, 0.0)  # the last fix (N, E), m
    v: tuple[float, float] = (0.0, 0.0)  # the velocity at it (N, E), m/s
    q: tuple[float, float] = (0.0, 0.0)  # the last fix less the motion since the first
    q_prev: tuple[float, float] | None = None  # the one before (None: a single fix so far)
    w_sum: float = 0.0
    w2_sum: float = 0.0
    q_sum: tuple[float, float] = (0.0, 0.0)
    q2_sum: tuple[float, float] = (0.0, 0.0)
    d1_sum: float = 0.0  # Σ w |q_i − q_i−1|² (N + E)
    d2_sum: float = 0.0  # Σ w |q_i − q_i−2|², over the same fixes
    d_w_sum: float = 0.0  # their weights

    def add(self, t_us: int, z: tuple[float, float], v: tuple[float, float], window_s: float) -> Scatter:
        """The fix ``z`` (N, E; m) with the velocity ``v`` (m/s) at it added, the older sums decayed by
        exp(−Δt / window_s)."""
        if self.t_us < 0:
            return Scatter(t_us, z, v, (0.0, 0.0), None, 1.0, 1.0, (0.0, 0.0), (0.0, 0.0))
        return _scatter_add(self, t_us, z, v, window_s)  # type: ignore[return-value]

    def variance(self) -> float:
        """One fix's error variance per horizontal axis (m², N and E pooled) from the scatter about the
        window mean: that scatter is short of it by the share of the window mean, c / n for ``n`` = w² / Σw²
        fixes of correlation ``c`` (``correlation()``; n / (n − 1) for independent fixes), so × 1 / (1 − c/n),
        at most ``SCATTER_MAX``; 0 before 3 fixes."""
        return self.statistics()[1]

    def correlation(self) -> float:
        """c in [1, C_MAX]: the fixes' errors' variance inflation for a mean over many of them; 1 before
        3 fixes."""
        return _correlation(self.d_w_sum, self.d1_sum, self.d2_sum)

    def statistics(self) -> tuple[float, float]:
        """(``correlation()``, ``variance()``) in one pass (the floors take both)."""
        _, _, _, _, _, w, w2, s, s2, d1, d2, dw = self
        return _statistics(w, w2, s[0], s2[0], s[1], s2[1], d1, d2, dw)


class Scatter1(NamedTuple):
    """``Scatter`` of one axis (the vertical: D, m; its velocity, m/s): the statistics ``Scatter`` gives
    that axis given twice (``Scatter().add(t, (d, d), (v, v), w)``, as the filters did), the same bits
    at about half the work. Its sums are per axis like ``Scatter``'s (the same values); the squared
    changes' sums are kept as that two-axis pooling has them, the axis's term twice (added to itself:
    exact), so every statistic is the same computation on the same numbers."""

    t_us: int = -1  # -1: no fix yet
    z: float = 0.0  # the last fix, m
    v: float = 0.0  # the velocity at it, m/s
    q: float = 0.0  # the last fix less the motion since the first
    q_prev: float | None = None  # the one before (None: a single fix so far)
    w_sum: float = 0.0
    w2_sum: float = 0.0
    q_sum: float = 0.0
    q2_sum: float = 0.0
    d1_sum: float = 0.0  # Σ w 2 (q_i − q_i−1)² (the axis's term twice: Scatter's pooled sum)
    d2_sum: float = 0.0  # Σ w 2 (q_i − q_i−2)², over the same fixes
    d_w_sum: float = 0.0  # their weights

    def add(self, t_us: int, z: float, v: float, window_s: float) -> Scatter1:
        """The fix ``z`` (m) with the velocity ``v`` (m/s) at it added, the older sums decayed by
        exp(−Δt / window_s)."""
        if self.t_us < 0:
            return Scatter1(t_us, z, v, 0.0, None, 1.0, 1.0, 0.0, 0.0)
        return _scatter1_add(self, t_us, z, v, window_s)  # type: ignore[return-value]

    def variance(self) -> float:
        """One fix's error variance (m²): ``Scatter.variance`` of one axis."""
        return self.statistics()[1]

    def correlation(self) -> float:
        """``Scatter.correlation`` of one axis."""
        return _correlation(self.d_w_sum, self.d1_sum, self.d2_sum)

    def statistics(self) -> tuple[float, float]:
        """(``correlation()``, ``variance()``) in one pass: ``Scatter``'s of the axis given twice."""
        _, _, _, _, _, w, w2, s, s2, d1, d2, dw = self
        return _statistics(w, w2, s, s2, s, s2, d1, d2, dw)


def _statistics(w: float, w2: float, s0: float, s20: float, s1: float, s21: float, d1: float, d2: float,
                dw: float) -> tuple[float, float]:
    """``Scatter.statistics`` from its sums (Σw, Σw², Σq and Σq² of each of the two axes, Σ d1, d2 and
    their weights): (c, the scatter about the window mean N and E pooled × 1 / (1 − c/n), at most
    ``SCATTER_MAX``, never below 0; 0 before 3 fixes)."""
    c = _correlation(dw, d1, d2)
    if dw <= 0.0 or w * w <= w2 * 1.000001:
        return c, 0.0
    m0, m1 = s0 / w, s1 / w
    var = 0.5 * ((s20 / w - m0 * m0) + (s21 / w - m1 * m1))
    share = c * w2 / (w * w)  # c / n
    f = 1.0 / (1.0 - share) if share < 1.0 - 1.0 / SCATTER_MAX else SCATTER_MAX
    v = var * f
    return c, v if v > 0.0 else 0.0  # (max(0.0, v) without the builtin's call)


def _correlation(d_w_sum: float, d1_sum: float, d2_sum: float) -> float:
    """``Scatter.correlation`` from its sums."""
    if d_w_sum < 1.5 or d1_sum <= 0.0:
        return 1.0
    r = d2_sum / d1_sum  # 1 + ρ
    if r <= 1.0:
        return 1.0
    if r >= 2.0 * C_MAX / (C_MAX + 1.0):  # (1 + ρ)/(1 − ρ) = r / (2 − r) ≥ C_MAX
        return C_MAX
    return r / (2.0 - r)


def honest_horizontal(var_ne: np.ndarray, k: float, scatter: Scatter | None, r_h_m2: float) -> np.ndarray:
    """The horizontal position variances to report (N, E; m²) from the filter's ``var_ne``: per axis
    max(k P, min(c k P, σ²)), ``k`` the innovations' consistency factor, ``c`` the fixes' correlation
    (``Scatter.correlation``), σ² the larger of their scatter (``Scatter.variance``) and the receiver's
    stated horizontal variance ``r_h_m2`` (NaN or inf: none). The filter averages the fixes as if
    independent; errors correlated over seconds are not averaged down, up to one fix's variance."""
    if scatter is None:
        return var_ne * k
    return floored(var_ne, k, *fix_floor(scatter, r_h_m2))


def fix_floor(scatter: Scatter | Scatter1, r_h_m2: float) -> tuple[float, float]:
    """(c, σ²) of ``honest_horizontal``: the fixes' correlation and one fix's variance (m²)."""
    c, s2 = scatter.statistics()
    if r_h_m2 > s2 and math.isfinite(r_h_m2):
        s2 = r_h_m2
    return c, s2


class SnapshotFloor(NamedTuple):
    """One axis's floor from a filter's own snapshot positions (``snapshot_parts``): for the filter's variance
    p the report is max(k p, min(p·white + min(slow, p·slow_rate), cap), delay) (``snapshot_axis``; N and E
    share one)."""

    white: float  # σ_w² / r: the white part's share, averaged down as the filter's P says
    slow: float  # σ_s² (m²): the slow part's variance, not averaged below it
    slow_rate: float  # σ_s² c_s / r: its variance when the filter's memory is short of its correlation
    cap: float  # one snapshot's variance (m²): the report's most from the snapshots


def white_and_slow(s2: float, delta1: float, delta2: float) -> tuple[float, float, float]:
    """(σ_w², σ_s², ρ): a series' variance ``s2`` split into a white part and a Gauss-Markov part of
    correlation ρ from one epoch to the next, from half the mean squared changes over one and two epochs,
    δ1 = σ_w² + σ_s² (1 − ρ) and δ2 = σ_w² + σ_s² (1 − ρ²) with s² = σ_w² + σ_s²:

        ρ = (s² − δ2) / (s² − δ1),   σ_s² = (s² − δ1)² / (s² − δ2),   σ_w² = s² − σ_s²

    exact for that process. The edges: s² ≤ δ1 or δ2 ≥ s² (no slow part the series shows): white alone;
    δ2 ≤ δ1 (no decay over two epochs): ρ = 1, the slow part s² − δ1."""
    if not s2 > delta1 or not s2 > delta2:
        return s2, 0.0, 0.0
    if delta2 <= delta1:
        return delta1, s2 - delta1, 1.0
    rho = (s2 - delta2) / (s2 - delta1)
    slow = (s2 - delta1) * (s2 - delta1) / (s2 - delta2)
    return s2 - slow, slow, rho


def snapshot_parts(scatter: Scatter | Scatter1, r_m2: float, kept: float = 1.0) -> SnapshotFloor | None:
    """The floor a filter's own per-epoch snapshot positions give one axis (the tight filter's: independent
    of its state, each with the variance ``r_m2`` its weights give it; docs/tight.md "Reported accuracy").
    Their scatter s² (``Scatter.variance``) is split into a white part σ_w² and a Gauss-Markov part σ_s² of
    correlation ρ from one snapshot to the next (``white_and_slow``, from the squared changes over one and
    two snapshots). P holds the snapshots' information as if each had the variance r and were independent:
    the white part of their average over the filter's memory has the variance P σ_w²/r, the slow part
    P σ_s² c_s / r, at most σ_s² (a filter remembering less than the correlation averages nothing of it),
    with c_s = (1 + aρ)/(1 − aρ) for a filter that keeps the share a = ``kept`` of its past per epoch (an
    exponential average: its weights' correlation-weighted sum over their plain one; a = 1, the long-memory
    limit (1 + ρ)/(1 − ρ)). r is at most s² here (a filter told more than the snapshots scatter is not
    shrunk below its P), the report at most one snapshot's variance max(s², r). None before 3 snapshots or
    without a stated variance."""
    if scatter.d_w_sum < 1.5 or not (r_m2 > 0.0 and math.isfinite(r_m2)):
        return None
    _, s2 = scatter.statistics()
    d = 0.25 / scatter.d_w_sum  # d1_sum, d2_sum hold both axes' (or the one axis's twice) squared changes
    white, slow, rho = white_and_slow(s2, scatter.d1_sum * d, scatter.d2_sum * d)
    r = s2 if 0.0 < s2 < r_m2 else r_m2
    a_rho = rho * kept if 0.0 < kept < 1.0 else rho
    c_s = (1.0 + a_rho) / (1.0 - a_rho) if a_rho < 1.0 - 2.0 / (C_MAX + 1.0) else C_MAX
    return SnapshotFloor(white / r, slow, slow * c_s / r, r_m2 if r_m2 > s2 else s2)


def snapshot_axis(p: float, k: float, f: SnapshotFloor | None, delay_m2: float = 0.0) -> float:
    """max(k p, min(p·white + min(slow, p·slow_rate), cap), delay_m2) for one axis's variance ``p``
    (``SnapshotFloor``; max(k p, delay_m2) without one): ``delay_m2`` the one-signed delays' bias² (m²,
    ``TightConfig.accuracy_delay_fraction``)."""
    v = p * k
    if f is not None:
        slow = p * f.slow_rate
        s = p * f.white + (slow if slow < f.slow else f.slow)
        s = s if s < f.cap else f.cap
        v = v if v > s else s
    return v if v > delay_m2 else delay_m2


def floored(var_ne: np.ndarray, k: float, c: float, s2: float) -> np.ndarray:
    """max(k P, min(c k P, σ²)) per axis (k P when c is 1)."""
    return np.array([floored_axis(float(p), k, c, s2) for p in var_ne])


def floored_axis(p: float, k: float, c: float, s2: float) -> float:
    """max(k p, min(c k p, σ²)) for one axis's variance ``p`` (scalars: the navigator's per-estimate cost)."""
    kp = p * k
    if c <= 1.0:
        return kp
    f = kp * c
    f = f if f < s2 else s2
    return f if f > kp else kp
