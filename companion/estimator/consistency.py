"""The honest reported accuracy, shared by the loose (``engine``) and the tight (``companion.tight``)
filters: the position covariance times a consistency factor measured from the filter's own fused
innovations over the last ``accuracy_window_s``, the variance-of-unit-weight test a receiver applies
to its reported accuracy, extended over time (docs/tight.md "Reported accuracy", docs/estimator.md):

    k = max(1, Σ_s (Σ_t w_t ν_s,t)² / Σ_s Σ_t w_t²),   w_t = exp(−(t_now − t)/τ),  τ = accuracy_window_s

over the channels ``s`` fused (the tight filter's satellites; the loose filter's N, E, D axes of a fix),
each innovation normalised by the variance it was fused with, ν = y / √S. A ``Fit`` is immutable and
stored with each filter entry, so a late measurement re-fused out of sequence gives the same factor.
Pure: numpy only.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

FIT_W2_MIN = 1e-3  # a channel's weight in Fit below this (gone for a few windows): forgotten


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
        keys = np.union1d(self.key, key)
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
        return max(1.0, float(self.nu_sum @ self.nu_sum) / den) if den > 0.0 else 1.0


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
