"""Campaign statistics: pure functions of numpy arrays (no I/O, no global random state).

Definitions used in ``results.json`` and the report:

- **median / IQR / p95** of an error sample: the project's statistics vocabulary
  (``companion.domain.statistics``: ``np.median``; percentiles with linear interpolation;
  IQR = p75 − p25).
- **percentile bootstrap 95 % CI** of a statistic of a sample of independent units
  (seeds): resample the units with replacement ``n_resamples`` times with an injected
  ``numpy.random.Generator``, evaluate the statistic on each resample and take the 2.5th
  and 97.5th percentiles of those values (Efron's percentile interval).
- **reduction vs naive**: ``value / naive − 1`` (−0.80 means 80 % lower than naive).
- **belief settling time** ``t_settle``: the final belief ``β∞`` is the median of β over
  the last ``tail_fraction`` of the flight; ``t_settle`` is the earliest time, measured from
  the first sample, after which β stays within ``±band`` of ``β∞`` until the end.
- **belief oscillation**: RMS of the high-frequency part of β, i.e. of β minus its centred
  moving average over ``window_s`` seconds. Slow, legitimate trust changes (open sky →
  street canyon) pass through the moving average and do not count; chatter does.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np

from companion.domain.statistics import describe, finite

Statistic = Callable[..., np.ndarray]


def summarize(samples: np.ndarray) -> dict[str, float]:
    """``{median, iqr, p95, n}`` of a 1-D sample (``companion.domain.statistics``; non-finite dropped)."""
    return describe(samples, ("median", "iqr", "p95", "n"))


def bootstrap_ci(
    x: np.ndarray,
    rng: np.random.Generator,
    statistic: Statistic = np.median,
    n_resamples: int = 2000,
    level: float = 0.95,
) -> tuple[float, float]:
    """Percentile bootstrap interval of ``statistic`` of a 1-D sample of independent units.

    ``statistic(a, axis=1)`` must reduce each row of an (n_resamples, n) array.
    """
    a = finite(x)
    if a.size < 2:
        return (float("nan"), float("nan"))
    values = statistic(a[rng.integers(0, a.size, size=(n_resamples, a.size))], axis=1)
    return _percentile_interval(values, level)


def paired_reduction_ci(
    seed_medians: np.ndarray,
    naive_seed_medians: np.ndarray,
    rng: np.random.Generator,
    n_resamples: int = 2000,
    level: float = 0.95,
) -> tuple[float, float, float]:
    """Reduction ``median(m)/median(naive) − 1`` over seeds and its paired bootstrap CI.

    Seeds are resampled jointly for both methods (the same seed drives the same vehicle
    noise), so the interval reflects the paired comparison. Returns (value, lo, hi).
    """
    a = np.asarray(seed_medians, dtype=float)
    b = np.asarray(naive_seed_medians, dtype=float)
    ok = np.isfinite(a) & np.isfinite(b)
    a, b = a[ok], b[ok]
    if a.size == 0:
        return (float("nan"),) * 3
    value = reduction(float(np.median(a)), float(np.median(b)))
    if a.size < 2:
        return (value, float("nan"), float("nan"))
    idx = rng.integers(0, a.size, size=(n_resamples, a.size))
    values = np.median(a[idx], axis=1) / np.median(b[idx], axis=1) - 1.0
    lo, hi = _percentile_interval(values, level)
    return (value, lo, hi)


def reduction(value: float, naive: float) -> float:
    """Relative change against naive: ``value / naive − 1`` (negative = lower than naive)."""
    return float(value / naive - 1.0) if naive > 0 else float("nan")


def settling_time_s(
    t_s: np.ndarray, beta: np.ndarray, band: float = 0.05, tail_fraction: float = 0.2
) -> float:
    """Earliest time (from the first sample) after which β stays within ``±band`` of β∞.

    β∞ is the median of β over the last ``tail_fraction`` of the samples. NaN samples
    (before the filter is initialised) count as outside the band.
    """
    t = np.asarray(t_s, dtype=float)
    b = np.asarray(beta, dtype=float)
    if b.size == 0:
        return float("nan")
    tail = b[int(np.floor(b.size * (1.0 - tail_fraction))) :]
    tail = tail[np.isfinite(tail)]
    if tail.size == 0:
        return float("nan")
    beta_inf = float(np.median(tail))
    outside = ~(np.abs(b - beta_inf) <= band)  # NaN compares False → outside
    if not outside.any():
        return 0.0
    last_out = int(np.flatnonzero(outside)[-1])
    if last_out + 1 >= b.size:
        return float(t[-1] - t[0])
    return float(t[last_out + 1] - t[0])


def oscillation_rms(t_s: np.ndarray, beta: np.ndarray, window_s: float = 2.0) -> float:
    """RMS of β minus its centred moving average over ``window_s`` (uniform sampling assumed)."""
    t = np.asarray(t_s, dtype=float)
    b = np.asarray(beta, dtype=float)
    ok = np.isfinite(b)
    t, b = t[ok], b[ok]
    if b.size < 3:
        return float("nan")
    dt = float(np.median(np.diff(t)))
    w = max(1, int(round(window_s / dt)))
    w += 1 - w % 2  # odd, so the average is centred
    if w >= b.size:
        return float(np.std(b))
    kernel = np.ones(w) / w
    padded = np.pad(b, w // 2, mode="edge")
    trend = np.convolve(padded, kernel, mode="valid")
    return float(np.sqrt(np.mean((b - trend) ** 2)))


def rank_order(medians: Mapping[str, float], order: Sequence[str]) -> bool:
    """True when the medians are strictly decreasing along ``order`` (names missing → False)."""
    if any(name not in medians for name in order):
        return False
    values = [medians[name] for name in order]
    return all(a > b for a, b in zip(values, values[1:], strict=False))


def _percentile_interval(values: np.ndarray, level: float) -> tuple[float, float]:
    tail = 50.0 * (1.0 - level)
    lo, hi = np.percentile(values, [tail, 100.0 - tail])
    return (float(lo), float(hi))


# ---- per-flight statistics (the unit of the ablation's intervals) --------------------------------
CHI2_3DOF_95 = 7.814727903251178  # χ²₀.₉₅ with 3 dof: NEES / NIS above it are outside the 95 % bound


def flight_stats(series: Mapping[str, np.ndarray]) -> dict[str, float]:
    """One flight's statistics from its 20 Hz series (samples before the filter starts are NaN).

    - ``est_h_median_m`` / ``est_3d_median_m`` / ``est_h_p95_m``: of ‖p̂ − p‖ horizontal / 3-D;
    - ``nees_mean`` / ``nees_median``: position NEES ``Σᵢ eᵢ² / Pᵢᵢ`` (3 dof, the diagonal only) of the
      position variances the estimator *reports* (``p_var``: its P × the consistency factor of
      ``accuracy_window_s``, horizontally floored by the fixes' own correlation, what GPS_INPUT and
      ODOMETRY carry; with that window 0, of P itself);
      ``nees_out95``: fraction above χ²₀.₉₅;
    - ``nis_mean`` / ``nis_median``: NIS of the last fused fix (3 dof), sampled at 20 Hz;
    - ``track_median_m``: of ‖p − p_ref‖.
    """
    e = np.asarray(series["p_est_ned_m"], dtype=float) - np.asarray(series["p_true_ned_m"], dtype=float)
    ok = np.isfinite(e).all(axis=1)
    e = e[ok]
    out: dict[str, float] = {}
    h = np.hypot(e[:, 0], e[:, 1])
    d3 = np.linalg.norm(e, axis=1)
    nan = float("nan")
    out["est_h_median_m"] = float(np.median(h)) if h.size else nan
    out["est_h_p95_m"] = float(np.percentile(h, 95)) if h.size else nan
    out["est_3d_median_m"] = float(np.median(d3)) if d3.size else nan
    nees = np.empty(0)
    if "p_var_ned_m2" in series:
        var = np.asarray(series["p_var_ned_m2"], dtype=float)[ok]
        good = (var > 0).all(axis=1) & np.isfinite(var).all(axis=1)
        nees = np.sum(e[good] ** 2 / var[good], axis=1)
    out["nees_mean"] = float(np.mean(nees)) if nees.size else nan
    out["nees_median"] = float(np.median(nees)) if nees.size else nan
    out["nees_out95"] = float(np.mean(nees > CHI2_3DOF_95)) if nees.size else nan
    nis = finite(series["nis"]) if "nis" in series else np.empty(0)
    out["nis_mean"] = float(np.mean(nis)) if nis.size else nan
    out["nis_median"] = float(np.median(nis)) if nis.size else nan
    track = finite(series["track_error_m"]) if "track_error_m" in series else np.empty(0)
    out["track_median_m"] = float(np.median(track)) if track.size else nan
    return out


def stratified_indices(strata: np.ndarray, rng: np.random.Generator, n_resamples: int) -> np.ndarray:
    """(n_resamples, n) bootstrap indices that resample units WITHIN each stratum (e.g. seeds within
    each mission profile: the profiles are a fixed design, the seeds are the random sample).

    A stratum of one unit has no within-stratum spread to resample: when any stratum has a single
    unit (one seed per profile), all units are resampled together instead (profiles then count as
    the random sample), so the interval is not a false zero width."""
    strata = np.asarray(strata)
    _, counts = np.unique(strata, return_counts=True)
    if counts.size and counts.min() < 2:
        return rng.integers(0, strata.size, size=(n_resamples, strata.size))
    cols = []
    for s in np.unique(strata):
        members = np.flatnonzero(strata == s)
        cols.append(members[rng.integers(0, members.size, size=(n_resamples, members.size))])
    return np.concatenate(cols, axis=1) if cols else np.empty((n_resamples, 0), dtype=int)


def mean_ci(
    values: np.ndarray,
    strata: np.ndarray,
    rng: np.random.Generator,
    n_resamples: int = 2000,
    level: float = 0.95,
) -> tuple[float, float, float]:
    """Mean of per-unit values and its stratified percentile-bootstrap interval: (mean, lo, hi).

    Non-finite units are dropped (with their stratum entry); fewer than 2 units → NaN interval."""
    v = np.asarray(values, dtype=float)
    s = np.asarray(strata)
    ok = np.isfinite(v)
    v, s = v[ok], s[ok]
    if v.size == 0:
        return (float("nan"),) * 3
    m = float(np.mean(v))
    if v.size < 2:
        return (m, float("nan"), float("nan"))
    idx = stratified_indices(s, rng, n_resamples)
    lo, hi = _percentile_interval(v[idx].mean(axis=1), level)
    return (m, lo, hi)
