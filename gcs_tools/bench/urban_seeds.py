"""``python -m gcs_tools.bench.urban_seeds``: ``bench robustness``'s urban-like receiver without a
velocity (its receiver misses) over several seeds of the error, against two references.

For each seed of ``robustness.urban_like`` (seed 0 is the bench's), at 5 Hz and decimated to 1 Hz,
without the receiver's velocity: each method's median, p95 and max distance to the clean fixes over
the raw fixes' (scored as the bench scores them: the fix just received at the estimate's time), and
the same for

* ``bias-only``: the seed's correlated (Gauss-Markov) error alone, without its white noise: a filter
  that removed all the white noise and none of the correlated error;
* ``ema-1s``: the fixes through a first-order low-pass of 1 s (no IMU, no velocity state): a filter
  that follows the fixes, smoothed, without extrapolating their drift as motion.

``--set estimator.FIELD=VALUE`` replaces EstimatorConfig fields for every method (e.g. the error's
true statistics as the bias state: ``sigma_bias_floor_m=8``, ``bias_tau_s=10``, ``sigma_bias0_m=8``).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from typing import Any

import numpy as np

from companion.estimator import EstimatorConfig
from gcs_tools.bench import robustness as rb

RATES = ((5.0, 1), (1.0, 5))  # (Hz, keep every n-th fix of the 5 Hz log)
EMA_TAU_S = 1.0
REFERENCES = ("bias-only", "ema-1s")


def ema(t_s: np.ndarray, p: np.ndarray, tau_s: float) -> np.ndarray:
    """Causal first-order low-pass of the rows of ``p`` sampled at ``t_s`` (irregular steps: the
    weight of each new sample 1 − e^(−Δt/τ)); the first sample passes as is."""
    out = np.array(p, dtype=float)
    for k in range(1, len(out)):
        w = 1.0 - math.exp(-(t_s[k] - t_s[k - 1]) / tau_s)
        out[k] = out[k - 1] + w * (out[k] - out[k - 1])
    return out


def _stats(d: np.ndarray, raw: np.ndarray) -> dict[str, float]:
    """Median, p95 and max of ``d`` over the raw fixes' own."""
    return {"median": float(np.median(d) / np.median(raw)),
            "p95": float(np.percentile(d, 95) / np.percentile(raw, 95)), "max": float(d.max() / raw.max())}


def seed_case(log: rb.Log, clean: tuple[np.ndarray, np.ndarray], seed: int, every: int,
              methods: Sequence[str], cfg: EstimatorConfig | None = None) -> dict[str, Any]:
    """One seed at one rate: the raw fixes' p95 (m) and each row's ratios to the raw fixes'."""
    received = rb.without_velocity(rb.decimated(rb.urban_like(log, seed), every))
    fixes = rb.clean_track(received)
    rows: dict[str, dict[str, float]] = {}
    raw = np.empty(0)
    for m in methods:
        r = rb.replay(received, m, cfg)
        est, raw = rb.distances_to_clean(r, clean, fixes)
        rows[m] = _stats(est, raw)
    bias = rb.clean_track(rb.decimated(rb.urban_like(log, seed, white_scale=0.0), every))
    for name, ref in (("bias-only", bias), ("ema-1s", (fixes[0], ema(fixes[0], fixes[1], EMA_TAU_S)))):
        rows[name] = _stats(rb.distances_to_clean(r, clean, ref)[1], raw)
    return {"seed": seed, "rate_hz": 5.0 / every, "raw_p95_m": float(np.percentile(raw, 95)), "rows": rows}


def summary(cases: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per rate and row: the mean, min and max p95 ratio, the mean median ratio, and the seeds whose
    p95 and max are at most the raw fixes' (the bench's ``ok`` on them)."""
    out: dict[str, dict[str, Any]] = {}
    for rate in sorted({c["rate_hz"] for c in cases}, reverse=True):
        sel = [c for c in cases if c["rate_hz"] == rate]
        for row in sel[0]["rows"]:
            p95 = np.array([c["rows"][row]["p95"] for c in sel])
            ok = sum(c["rows"][row]["p95"] <= 1.0 and c["rows"][row]["max"] <= 1.0 for c in sel)
            out[f"{rate:g} Hz, {row}"] = {
                "p95_ratio_mean": float(p95.mean()), "p95_ratio_min": float(p95.min()),
                "p95_ratio_max": float(p95.max()),
                "median_ratio_mean": float(np.mean([c["rows"][row]["median"] for c in sel])),
                "seeds_ok": ok, "seeds": len(sel)}
    return out


def measure_seeds(seeds: int, methods: Sequence[str], cfg: EstimatorConfig | None = None) -> dict[str, Any]:
    log = rb.load()
    clean = rb.clean_track(log)
    cases = [seed_case(log, clean, s, every, methods, cfg) for s in range(seeds) for _, every in RATES]
    return {"summary": summary(cases), "cases": cases}


def main(argv: Sequence[str] | None = None) -> int:
    from companion.errors import UserError
    from gcs_tools import choices
    from gcs_tools.evaluate.real import estimator_config, parse_sets

    p = argparse.ArgumentParser(allow_abbrev=False, prog="python -m gcs_tools.bench.urban_seeds",
                                description="the urban-like receiver without a velocity over several seeds")
    p.add_argument("--seeds", type=int, default=10, help="seeds 0..N-1 of the urban-like error (default 10)")
    p.add_argument("--methods", default=",".join(rb.METHODS), help="comma-separated (default: the bench's)")
    p.add_argument("--set", action="append", default=[], metavar="estimator.FIELD=VALUE",
                   help="replace an EstimatorConfig field for every method (repeatable)")
    p.add_argument("--json", action="store_true", help="one JSON object (summary and every case)")
    args = p.parse_args(argv)
    if args.seeds < 1:
        p.error("--seeds must be at least 1")
    try:
        methods = choices.methods(args.methods)
        cfg = estimator_config(parse_sets(args.set))
    except UserError as exc:
        print(f"urban_seeds: error: {exc}", file=sys.stderr)
        return 2
    out = measure_seeds(args.seeds, methods, cfg)
    if args.json:
        print(json.dumps(out, indent=2))
    else:
        for row, s in out["summary"].items():
            spread = f"{s['p95_ratio_min']:.3f}-{s['p95_ratio_max']:.3f}"
            print(f"{row:28s} p95/raw {s['p95_ratio_mean']:.3f} ({spread})"
                  f"  median/raw {s['median_ratio_mean']:.3f}  ok {s['seeds_ok']}/{s['seeds']}")
    sys.stdout.flush()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
