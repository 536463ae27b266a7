"""Turn a campaign's job results into the ``results.json`` mapping (pure; no files, no plots).

Pooling: a method's error statistics pool every 20 Hz sample of every flight of that
method (all mission profiles and all seeds of the run). Bootstrap intervals resample whole
seeds (each seed is one independent campaign over all profiles): the per-seed statistic
is the median of that seed's pooled samples, the interval is the percentile bootstrap of
the median over seeds, and reductions against naive are resampled pairwise.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from gcs_tools.evaluate import stats
from gcs_tools.evaluate.campaign import JobResult

BASELINE = "naive"
PAPER_ORDER = ("naive", "adaptive", "first-order", "second-order")
PAPER_CLAIMS = {"estimation_error_m": -0.80, "tracking_error_m": -0.30}  # second-order vs naive
CLAIM_TOLERANCE = 0.05  # a claim counts as reproduced within 5 percentage points of it (or better)
ERRORS = {"estimation_error_m": "est_error_m", "tracking_error_m": "track_error_m"}
BOOTSTRAP_SEED = 20240917  # the bootstrap's own generator, recorded in results.json


def of_method(results: Sequence[JobResult], method: str) -> list[JobResult]:
    """The results of one row (a method, or an ablation row's label)."""
    return [r for r in results if r.job.row == method]


def pooled(results: Sequence[JobResult], attr: str) -> np.ndarray:
    arrays = [np.asarray(getattr(r, attr), dtype=float) for r in results]
    return np.concatenate(arrays) if arrays else np.empty(0)


def seed_medians(results: Sequence[JobResult], attr: str, seeds: Sequence[int]) -> np.ndarray:
    """Per seed, the median of that seed's samples pooled over profiles (NaN if none)."""
    out = []
    for seed in seeds:
        x = pooled([r for r in results if r.job.seed == seed], attr)
        x = x[np.isfinite(x)]
        out.append(float(np.median(x)) if x.size else float("nan"))
    return np.array(out)


def method_entry(
    results: Sequence[JobResult], naive: Sequence[JobResult], seeds: Sequence[int], rng: np.random.Generator
) -> dict[str, Any]:
    """Everything results.json says about one method."""
    entry: dict[str, Any] = {"flights": len(results)}
    for name, attr in ERRORS.items():
        s: dict[str, Any] = stats.summarize(pooled(results, attr))
        if naive:
            naive_median = stats.summarize(pooled(naive, attr))["median"]
            s["reduction_vs_naive"] = stats.reduction(s["median"], naive_median)
        if len(seeds) >= 2:
            m = seed_medians(results, attr, seeds)
            s["seed_median"] = float(np.nanmedian(m))
            s["seed_median_ci95"] = list(stats.bootstrap_ci(m, rng))
            if naive:
                value, lo, hi = stats.paired_reduction_ci(m, seed_medians(naive, attr, seeds), rng)
                s["seed_reduction_vs_naive"] = value
                s["seed_reduction_vs_naive_ci95"] = [lo, hi]
        s["per_profile_median"] = {
            str(p): float(np.nanmedian(pooled([r for r in results if r.job.profile_index == p], attr)))
            for p in sorted({r.job.profile_index for r in results})
        }
        entry[name] = s
    reached = [bool(r.summary.get("reached_goal", False)) for r in results]
    collisions = [int(r.summary.get("collisions", 0)) for r in results]
    entry["goal_reached_rate"] = float(np.mean(reached)) if reached else float("nan")
    entry["collisions"] = int(np.sum(collisions))
    entry["flights_with_collision"] = int(np.count_nonzero(collisions))
    entry["belief_settling_time_s"] = _median_iqr([r.settling_time_s for r in results])
    entry["belief_oscillation_rms"] = _median_iqr([r.oscillation_rms for r in results])
    return entry


def build_results(
    results: Sequence[JobResult], methods: Sequence[str], seeds: Sequence[int], campaign: dict[str, Any]
) -> dict[str, Any]:
    """The full ``results.json`` mapping."""
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    naive = of_method(results, BASELINE) if BASELINE in methods else []
    per_method = {m: method_entry(of_method(results, m), naive, seeds, rng) for m in methods}
    return {
        "campaign": {**campaign, "bootstrap": {"seed": BOOTSTRAP_SEED, "resamples": 2000, "unit": "seed"}},
        "definitions": _definitions(),
        "methods": per_method,
        "paper_claims": paper_claims(per_method),
    }


def paper_claims(per_method: dict[str, Any]) -> dict[str, Any]:
    """The paper's headline claims next to what this run measured."""
    out: dict[str, Any] = {}
    for name, claimed in PAPER_CLAIMS.items():
        so = per_method.get("second-order", {}).get(name, {})
        measured = so.get("reduction_vs_naive", float("nan"))
        out[f"second_order_{name}_reduction"] = {
            "claimed": claimed,
            "measured": measured,
            "measured_over_seeds_ci95": so.get("seed_reduction_vs_naive_ci95"),
            "reproduced": bool(measured <= claimed + CLAIM_TOLERANCE),
        }
        medians = {m: e[name]["median"] for m, e in per_method.items()}
        out[f"order_{name}_naive>adaptive>first>second"] = stats.rank_order(medians, PAPER_ORDER)
    return out


def _median_iqr(values: Sequence[float]) -> dict[str, float]:
    s = stats.summarize(np.asarray(values, dtype=float))
    return {"median": s["median"], "iqr": s["iqr"], "n": s["n"]}


def _definitions() -> dict[str, str]:
    return {
        "estimation_error_m": "‖p̂ − p‖ (estimate vs truth, 3-D) at 20 Hz, pooled over time, profiles, seeds",
        "tracking_error_m": "‖p − p_ref‖ (truth vs min-jerk reference, 3-D) at 20 Hz, pooled likewise",
        "iqr": "p75 − p25",
        "reduction_vs_naive": "median / naive median − 1 (−0.8 = 80 % lower)",
        "seed_median": "median over seeds of each seed's pooled median; CI: percentile bootstrap over seeds",
        "belief_settling_time_s": (
            "per flight: earliest time after which β stays within ±0.05 of β∞ (median of β over the last"
            " 20 % of the flight); median/IQR over flights"
        ),
        "belief_oscillation_rms": (
            "per flight: RMS of β minus its centred 2 s moving average (chatter, not slow trust changes)"
        ),
        "goal_reached_rate": "fraction of flights whose summary says reached_goal",
        "collisions": "sum over flights of the flight summary's collision count",
    }
