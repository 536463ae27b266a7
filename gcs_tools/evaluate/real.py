"""Real IMU flights through synthetic urban GNSS: every method against the raw fixes and naive.

    python -m gcs_tools.evaluate.real --corpus ansfl/ --flights reporting \\
        --errors model,spp_errors.csv --accuracy reported,none --seeds 0-4 --out DIR

Each flight of the ANSFL corpus (a real quadrotor IMU with RTK truth, :mod:`gcs_tools.replay.ansfl`)
is replayed by every method with its GNSS replaced by the truth plus each error source (the
project's urban model, or a recorded error series) with and without a reported accuracy
(:mod:`gcs_tools.replay.synthetic_gnss`); the same seed gives every method the same fixes, so
methods are compared pair by pair. Per run (flight × errors × accuracy × seed × method): the
horizontal error of the estimate against the truth (median, p95, max over the truth's 10 Hz
samples), and the raw fixes' own error at their validity times and at their arrival (latency
counted: what a consumer of the raw fixes has).

``smartloc-sats:INPUT`` (a smartLoc ``*_Input.txt`` with its ``*_GT.txt``): the drive's satellites with
their residuals at its truth placed on each flight (:mod:`gcs_tools.gnss.transplant`): the methods get
the single-point fixes of those pseudoranges (latency, velocity, accuracy as with a series), and the rows
``tight-<weighting>`` (``evaluate.tight.TIGHT_ROWS``: the tightly coupled filter, ``TightConfig()``, no
map) the pseudoranges with the flight's IMU, arriving with the fixes; per condition ``belief_paired``
compares ``tight-second-order`` pair by pair with the other tight rows and the best method.

Pooled figures are means over runs of the per-run statistic with a 95 % percentile-bootstrap
interval that resamples seeds within each flight (``stats.mean_ci``: the flights are a fixed
design, the seeds the random sample); ``vs raw`` is the paired difference of per-run medians
(method − raw fixes at arrival), ``vs naive`` the ratio of the mean per-run medians minus 1 with
its paired interval (:func:`ratio_of_means_ci`).

Flights: the corpus's paths 1, 2, 3 are the TUNING flights (anything tuned on real data is tuned
there); 5, 6, 7, 8, 10 are the REPORTING flights (the numbers quoted); the data set's other
flights are held out by the project.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from companion.errors import UserError
from companion.estimator.config import EstimatorConfig
from gcs_tools.choices import seeds as parse_seeds
from gcs_tools.evaluate import stats
from gcs_tools.gnss.transplant import PREFIX as SATS

TUNING_FLIGHTS = ("path_1", "path_2", "path_3")
REPORTING_FLIGHTS = ("path_5", "path_6", "path_7", "path_8", "path_10")
RAW = ("raw fixes (at arrival)", "raw fixes (at validity)")
STATS = ("median", "p95", "max")
# the fraction of truth samples inside the reported 1-σ / 2-σ horizontal ellipse (2-D Gaussian: 39 / 86 %)
COVERAGE = ("within_1_sigma", "within_2_sigma")
# the same vertically: |e_D| within the reported 1 σ / 2 σ (a Gaussian: 68 / 95 %)
COVERAGE_V = ("vertical_within_1_sigma", "vertical_within_2_sigma")
BOOTSTRAP_SEED = 20261126
GOAL_BELOW_NAIVE = -0.20  # the goal: the best method's median at least 20 % below naive
TIGHT_PREFIX = "tight-"
BELIEF_ROW = "tight-second-order"  # the per-satellite belief, compared pair by pair with the other tight rows
BELIEF_REFERENCES = ("tight-naive", "tight-cn0-elevation", "tight-fde", "tight-student-t")


@dataclass(frozen=True)
class Job:
    """One flight under one GNSS condition and seed; every method replays it."""

    flight: str  # path of the flight directory
    errors: str  # "model" | "none" | series CSV path
    accuracy: str
    seed: int
    rate_hz: float
    latency_ms: float | None
    methods: tuple[str, ...]
    estimator: tuple[tuple[str, Any], ...] = ()  # EstimatorConfig fields replaced (--set estimator.F=V)
    velocity_std_m_s: float | None = 0.2  # the fixes' velocity noise (None: no velocity), as GnssErrorOptions


def needs_map(method: str) -> bool:
    """True when ``method`` cannot run without a mission's map (a real flight has none)."""
    from companion.errors import ConfigError
    from companion.wiring import navigator_for

    try:
        navigator_for(None, method)
    except ConfigError:
        return True
    return False


def is_sats(errors: str) -> bool:
    """The ``smartloc-sats:INPUT`` errors: a smartLoc drive's satellites placed on the flight
    (``gcs_tools.gnss.transplant``): SPP fixes for the loose rows, raw epochs for the tight rows."""
    return errors.startswith(SATS)


def errors_label(errors: str) -> str:
    if is_sats(errors):
        return f"satellites {Path(errors[len(SATS):]).name}"
    return errors if errors in ("model", "none") else f"series {Path(errors).name}"


def tight_rows(errors: str) -> tuple[str, ...]:
    """The tightly coupled rows a condition has (``evaluate.tight``'s weightings; none without satellites)."""
    if not is_sats(errors):
        return ()
    from gcs_tools.evaluate.tight import TIGHT_ROWS

    return tuple(TIGHT_PREFIX + w for w in TIGHT_ROWS)


def _row(base: dict[str, Any], row: str, s: dict[str, Any]) -> dict[str, Any]:
    """One run's line from a replay summary."""
    h = s["errors"]["truth"]["error_horizontal_m"]
    cov = s["errors"]["truth"]["coverage_horizontal"]  # the reported accuracy's, at the truth samples
    cov_v = s["errors"]["truth"]["coverage_vertical"]
    nav = s["navigator"]
    return {**base, "row": row, **{k: round(h[k], 4) for k in STATS},
            **{k: round(cov[k], 4) for k in COVERAGE},
            **{k: round(cov_v[k.removeprefix("vertical_")], 4) for k in COVERAGE_V},
            "gnss_fused": nav.get("gnss_fused", 0),
            "gnss_rejected_innovation": nav.get("gnss_rejected_innovation", 0),
            "gnss_resets": nav.get("gnss_resets", 0), "wall_s": round(s["wall_s"], 4),
            "duration_s": round(s["duration_s"], 3)}


def _raw_rows(base: dict[str, Any], raw: dict[str, Any]) -> list[dict[str, Any]]:
    out = []
    for row, key in zip(RAW, ("at_arrival", "at_validity"), strict=True):
        h = raw[key]["error_horizontal_m"]
        out.append({**base, "row": row, **{k: round(h[k], 4) for k in STATS}})
    return out


def run_job(job: Job) -> list[dict[str, Any]]:
    """Every method on the job's fixes, and the raw fixes' own errors (same for all methods)."""
    if is_sats(job.errors):
        return run_sats_job(job)
    from gcs_tools.replay import core
    from gcs_tools.replay.synthetic_gnss import GnssErrorOptions

    opts = GnssErrorOptions(job.errors, rate_hz=job.rate_hz, accuracy=job.accuracy, latency_ms=job.latency_ms,
                            seed=job.seed, velocity_std_m_s=job.velocity_std_m_s)
    config = estimator_config(job.estimator)
    base = {"flight": Path(job.flight).name, "errors": errors_label(job.errors), "accuracy": job.accuracy,
            "seed": job.seed}
    out: list[dict[str, Any]] = []
    raw: dict[str, Any] | None = None
    for method in job.methods:
        s = core.replay(Path(job.flight), method, gnss=opts, rate_hz=10.0, config=config).summary
        out.append(_row(base, method, s))
        raw = s["errors"]["raw_fixes"]
    assert raw is not None
    return out + _raw_rows(base, raw)


# the tight rows do not depend on the accuracy mode: replayed once per (flight, drive, seed, …) per process
_TIGHT_DONE: dict[tuple[Any, ...], list[dict[str, Any]]] = {}


def run_sats_job(job: Job) -> list[dict[str, Any]]:
    """A smartLoc drive's satellites on the flight (``transplant.sky_on_flight``): every loose method on
    the single-point fixes (latency, velocity and accuracy as the series condition), every tight row
    (``TightConfig()``, no map) on the placed epochs arriving with the fixes, and the fixes' own errors."""
    from companion.tight import TightConfig
    from gcs_tools.evaluate.tight import TIGHT_ROWS
    from gcs_tools.gnss import tight_replay as tr
    from gcs_tools.gnss import transplant
    from gcs_tools.replay import core
    from gcs_tools.replay.synthetic_gnss import GnssErrorOptions, WithSyntheticGnss

    flight = Path(job.flight)
    opts = GnssErrorOptions("none", rate_hz=job.rate_hz, accuracy=job.accuracy, latency_ms=job.latency_ms,
                            seed=job.seed, velocity_std_m_s=job.velocity_std_m_s)
    sky = transplant.drive_sky(transplant.check_choice(job.errors))
    placed = transplant.sky_on_flight(flight, sky, opts)
    frame = placed.frame
    config = estimator_config(job.estimator)
    base = {"flight": flight.name, "errors": errors_label(job.errors), "accuracy": job.accuracy,
            "seed": job.seed}
    out: list[dict[str, Any]] = []
    for method in job.methods:
        fixes = WithSyntheticGnss(transplant.on_drive_frame(flight, None, sky), placed.fixes, frame,
                                  placed.raw_errors)
        s = core.replay(flight, method, home=frame, reader=fixes, rate_hz=10.0, config=config).summary
        out.append(_row(base, method, s))
    key = (job.flight, job.errors, id(sky), job.seed, job.rate_hz, job.latency_ms,  # sky: per file state
           job.velocity_std_m_s)  # the synthetic Doppler's information
    if key not in _TIGHT_DONE:
        done: list[dict[str, Any]] = []
        for w in TIGHT_ROWS:
            raw: Any = transplant.placed_raw_reader(transplant.on_drive_frame(flight, None, sky), placed,
                                                    sky.name)  # a LogReader of RawGnss
            s = core.replay(flight, w, home=frame, reader=raw, rate_hz=10.0,
                            navigator=tr.tight_factory(TightConfig())).summary
            done.append(_row({}, TIGHT_PREFIX + w, s))
        _TIGHT_DONE[key] = done
    out += [{**base, **r} for r in _TIGHT_DONE[key]]
    return out + _raw_rows(base, placed.raw_errors)


def estimator_config(fields: Sequence[tuple[str, Any]]) -> EstimatorConfig | None:
    """The ``EstimatorConfig`` defaults with ``fields`` replaced (None when there are none: the defaults);
    a bad field or value is a UserError."""
    if not fields:
        return None
    from companion.mission.schema import build

    return build(EstimatorConfig, dict(fields), "--set estimator")


def parse_sets(texts: Sequence[str]) -> tuple[tuple[str, Any], ...]:
    """``--set estimator.FIELD=VALUE`` options as (field, value) pairs, checked."""
    from gcs_tools.evaluate.tuning import parse_override

    out = []
    for text in texts:
        key, value = parse_override(text)
        section, _, name = key.partition(".")
        if section != "estimator":
            raise UserError(f"--set {text!r}: only estimator.FIELD applies to replays of real flights")
        out.append((name, value))
    estimator_config(out)
    return tuple(out)


def _runs(runs: list[dict[str, Any]], row: str) -> dict[tuple[str, int], dict[str, Any]]:
    return {(r["flight"], r["seed"]): r for r in runs if r["row"] == row}


def ratio_of_means_ci(a: np.ndarray, b: np.ndarray, strata: np.ndarray, rng: np.random.Generator,
                      n_resamples: int = 2000) -> tuple[float, float, float]:
    """``mean(a) / mean(b) − 1`` over paired units and its percentile-bootstrap 95 % interval, the
    pairs resampled within strata (``stats.stratified_indices``)."""
    if a.size == 0 or not np.mean(b) > 0:
        return (float("nan"),) * 3
    value = float(np.mean(a) / np.mean(b) - 1.0)
    if a.size < 2:
        return (value, float("nan"), float("nan"))
    idx = stats.stratified_indices(strata, rng, n_resamples)
    ratios = a[idx].mean(axis=1) / b[idx].mean(axis=1) - 1.0
    lo, hi = np.percentile(ratios, [2.5, 97.5])
    return (value, float(lo), float(hi))


def summarise(runs: list[dict[str, Any]], rows: Sequence[str]) -> dict[str, Any]:
    """Per row: pooled mean with interval of each statistic, per-flight means, paired comparisons."""
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    raw_a = _runs(runs, RAW[0])
    naive = _runs(runs, "naive")
    out: dict[str, Any] = {}
    for row in rows:
        mine = _runs(runs, row)
        keys = sorted(mine)
        strata = np.array([k[0] for k in keys])
        e: dict[str, Any] = {"runs": len(keys)}
        for st in STATS:
            v = np.array([mine[k][st] for k in keys], dtype=float)
            mean, lo, hi = stats.mean_ci(v, strata, rng)
            e[st] = {"mean": mean, "ci95": [lo, hi]}
        if keys and COVERAGE[0] in mine[keys[0]]:  # a filter row: its reported accuracy's coverage
            e["coverage"] = {c: float(np.mean([mine[k][c] for k in keys])) for c in COVERAGE
                             + tuple(v for v in COVERAGE_V if v in mine[keys[0]])}
        e["per_flight_median"] = {f: float(np.mean([mine[k]["median"] for k in keys if k[0] == f]))
                                  for f in sorted(set(strata.tolist()))}
        pairs = [k for k in keys if k in raw_a]
        d = np.array([mine[k]["median"] - raw_a[k]["median"] for k in pairs])
        mean, lo, hi = stats.mean_ci(d, np.array([k[0] for k in pairs]), rng)
        e["minus_raw_at_arrival_median"] = {"mean": mean, "ci95": [lo, hi]}
        pairs = [k for k in keys if k in naive]
        value, lo, hi = ratio_of_means_ci(np.array([mine[k]["median"] for k in pairs]),
                                          np.array([naive[k]["median"] for k in pairs]),
                                          np.array([k[0] for k in pairs]), rng)
        e["vs_naive_median"] = {"value": value, "ci95": [lo, hi]}
        out[row] = e
    return out


def paired_medians(runs: list[dict[str, Any]], row: str, references: Sequence[str]) -> list[dict[str, Any]]:
    """``row`` against each reference, pair by pair (flight, seed): the mean difference of the run medians
    (m) and the ratio of their means − 1, each with its 95 % interval (seeds resampled within flights)."""
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    mine = _runs(runs, row)
    out = []
    for ref in references:
        other = _runs(runs, ref)
        pairs = [k for k in sorted(mine) if k in other]
        a = np.array([mine[k]["median"] for k in pairs], dtype=float)
        b = np.array([other[k]["median"] for k in pairs], dtype=float)
        strata = np.array([k[0] for k in pairs])
        mean, lo, hi = stats.mean_ci(a - b, strata, rng)
        value, rlo, rhi = ratio_of_means_ci(a, b, strata, rng)
        out.append({"row": row, "reference": ref, "pairs": len(pairs),
                    "median_diff_m": {"mean": mean, "ci95": [lo, hi]},
                    "median_ratio": {"value": value, "ci95": [rlo, rhi]},
                    "excludes_zero": bool(hi < 0 or lo > 0)})
    return out


def goals(table: dict[str, Any], methods: Sequence[str]) -> dict[str, Any]:
    """The issue's goals on one condition: no method's p95 or max above the raw fixes'; the best
    method's median below the raw fixes' (at arrival) and at least 20 % below naive."""
    best = min(methods, key=lambda m: table[m]["median"]["mean"])
    raw_a, raw_v = table[RAW[0]], table[RAW[1]]
    worse = {m: [st for st in ("p95", "max") if table[m][st]["mean"] > raw_a[st]["mean"]] for m in methods}
    return {
        "best_method": best,
        "best_median_m": table[best]["median"]["mean"],
        "raw_at_arrival_median_m": raw_a["median"]["mean"],
        "raw_at_validity_median_m": raw_v["median"]["mean"],
        "best_below_raw_at_arrival": table[best]["median"]["mean"] < raw_a["median"]["mean"],
        "best_below_raw_at_validity": table[best]["median"]["mean"] < raw_v["median"]["mean"],
        "best_vs_naive": table[best]["vs_naive_median"]["value"],
        "best_20_percent_below_naive": table[best]["vs_naive_median"]["value"] <= GOAL_BELOW_NAIVE,
        "methods_with_p95_or_max_above_raw_at_arrival": {m: w for m, w in worse.items() if w},
    }


def _ci(e: dict[str, Any]) -> str:
    lo, hi = e["ci95"]
    return f"{e['mean']:.2f} [{lo:.2f}, {hi:.2f}]"


def _velocity_text(std: float | None) -> str:
    return "no velocity" if std is None else f"a velocity: truth + {std:g} m/s noise"


def markdown(result: dict[str, Any]) -> str:
    info = result["campaign"]
    lines = [
        "# Real IMU flights through synthetic urban GNSS", "",
        f"Flights ({info['split']}): {', '.join(info['flights'])}. "
        f"Tuning flights: {', '.join(TUNING_FLIGHTS)}; reporting flights: {', '.join(REPORTING_FLIGHTS)}; "
        "the data set's other flights are held out.",
        f"Seeds {info['seeds']}, fixes at {info['rate_hz']:g} Hz, latency: "
        f"{'the model process' if info['latency_ms'] is None else str(info['latency_ms']) + ' ms'}; "
        f"{info['runs']} replays in {info['wall_s']:.0f} s.",
        *([f"The fixes carry {_velocity_text(info['velocity_std_m_s'])} (default: truth + 0.2 m/s noise)."]
          if info.get("velocity_std_m_s", 0.2) != 0.2 else []),
        *([f"Estimator fields replaced for every method: "
           f"{', '.join(f'`{k}` = {v}' for k, v in info['estimator'].items())}."]
          if info.get("estimator") else []),
        "", "Horizontal error against the RTK truth [m]: mean over runs (flight × seed) of each run's "
        "statistic, 95 % bootstrap interval (seeds resampled within flights). `− raw` = paired "
        "difference of run medians against the raw fixes at arrival; `vs naive` = ratio of the mean "
        "run medians − 1 (paired interval); `within 1 σ / 2 σ` = mean over runs of the fraction of truth "
        "samples inside the reported horizontal 1-σ / 2-σ ellipse (a consistent 2-D Gaussian: 39 % / 86 %).",
        ""]
    for cond in result["conditions"]:
        t, g = cond["table"], cond["goals"]
        lines += [f"## errors: {cond['errors']}, accuracy: {cond['accuracy']}", ""]
        if "belief_paired" in cond:
            lines += ["The drive's per-satellite errors (residuals at its truth) placed on each flight's "
                      "truth: the methods get the single-point fixes of those pseudoranges (latency, "
                      "velocity and accuracy as a recorded series), the `tight-*` rows the pseudoranges "
                      "themselves (arriving with the fixes) and the flight's IMU. "
                      + ("The drive has no Doppler and the fixes no velocity: no row gets a velocity."
                         if info.get("velocity_std_m_s", 0.2) is None else
                         "The drive has no Doppler: the epochs carry SYNTHETIC pseudorange rates at the "
                         "flight's truth velocity with the drive's clock drift and noise of the fixes' "
                         "velocity information (their Doppler velocity's mean per-axis std = the fixes' "
                         f"{info.get('velocity_std_m_s', 0.2):g} m/s)."), ""]
        lines += [
                  "| row | median | p95 | max | − raw (arrival), median | vs naive | within 1 σ / 2 σ "
                  "| vertical 1 σ / 2 σ |",
                  "|---|---|---|---|---|---|---|---|"]
        for row, e in t.items():
            diff = e["minus_raw_at_arrival_median"]
            vs = e["vs_naive_median"]
            cells = [f"`{row}`", _ci(e["median"]), _ci(e["p95"]), _ci(e["max"]),
                     "—" if row in RAW else _ci(diff),
                     "—" if row in (*RAW, "naive") else
                     f"{vs['value']:+.0%} [{vs['ci95'][0]:+.0%}, {vs['ci95'][1]:+.0%}]",
                     "—" if "coverage" not in e else
                     f"{e['coverage'][COVERAGE[0]]:.0%} / {e['coverage'][COVERAGE[1]]:.0%}",
                     "—" if COVERAGE_V[0] not in e.get("coverage", {}) else
                     f"{e['coverage'][COVERAGE_V[0]]:.0%} / {e['coverage'][COVERAGE_V[1]]:.0%}"]
            lines.append("| " + " | ".join(cells) + " |")
        over = g["methods_with_p95_or_max_above_raw_at_arrival"]
        over_text = ", ".join(f"`{m}` ({'/'.join(w)})" for m, w in over.items()) or "none"
        lines += ["", f"Best: `{g['best_method']}` {g['best_median_m']:.2f} m vs raw fixes "
                      f"{g['raw_at_arrival_median_m']:.2f} m at arrival, "
                      f"{g['raw_at_validity_median_m']:.2f} m at validity; "
                      f"{g['best_vs_naive']:+.0%} vs naive. "
                      f"Goals: below the raw fixes at arrival "
                      f"{'met' if g['best_below_raw_at_arrival'] else 'NOT met'}; 20 % below naive "
                      f"{'met' if g['best_20_percent_below_naive'] else 'NOT met'}; p95/max above the raw "
                      f"fixes': {over_text}.", ""]
        flights = list(next(iter(t.values()))["per_flight_median"])
        lines += ["Per flight, median [m] (mean over seeds):", "",
                  "| row | " + " | ".join(flights) + " |", "|---|" + "---|" * len(flights)]
        for row, e in t.items():
            per_flight = " | ".join(f"{e['per_flight_median'][f]:.2f}" for f in flights)
            lines.append(f"| `{row}` | {per_flight} |")
        lines.append("")
        if cond.get("belief_paired"):
            lines += ["The per-satellite belief against each row, pair by pair (flight × seed): the mean "
                      "difference of the run medians [m] and the ratio of the mean run medians − 1, 95 % "
                      "intervals (seeds resampled within flights):", "",
                      "| row − reference | median difference [m] | ratio | interval excludes 0 |",
                      "|---|---|---|---|"]
            for c in cond["belief_paired"]:
                r = c["median_ratio"]
                lines.append(f"| `{c['row']}` − `{c['reference']}` | {_ci(c['median_diff_m'])} | "
                             f"{r['value']:+.0%} [{r['ci95'][0]:+.0%}, {r['ci95'][1]:+.0%}] | "
                             f"{'yes' if c['excludes_zero'] else 'no'} |")
            lines.append("")
    return "\n".join(lines)


def flight_dirs(corpus: Path | None, spec: str) -> tuple[str, list[Path]]:
    """``reporting`` / ``tuning`` / ``all`` under ``corpus``, or comma-separated names or paths."""
    names = {"reporting": REPORTING_FLIGHTS, "tuning": TUNING_FLIGHTS,
             "all": (*TUNING_FLIGHTS, *REPORTING_FLIGHTS)}.get(spec)
    split = spec if names is not None else "as listed"
    if corpus is not None and not corpus.is_dir():
        raise UserError(f"--corpus {corpus}: no such directory (the ANSFL data set: path_1, path_2, ...)")
    items = list(names) if names is not None else [s.strip() for s in spec.split(",") if s.strip()]
    out = []
    for item in items:
        p = Path(item)
        if not p.is_dir() and corpus is not None:
            p = corpus / item
        if not (p / "IMU_1.csv").is_file():
            where = f" under --corpus {corpus}" if corpus is not None else " (give --corpus)"
            raise UserError(f"--flights: {item!r} is not an ANSFL flight directory{where}")
        out.append(p)
    if not out:
        raise UserError("--flights: no flight given")
    return split, out


def run(flights: Sequence[Path], errors: Sequence[str], accuracies: Sequence[str], methods: Sequence[str],
        seeds: Sequence[int], rate_hz: float = 5.0, latency_ms: float | None = None, workers: int = 1,
        split: str = "as listed", estimator: tuple[tuple[str, Any], ...] = (),
        velocity_std_m_s: float | None = 0.2) -> dict[str, Any]:
    """The campaign's results (``conditions``: one table per errors × accuracy, and every run);
    ``estimator``: EstimatorConfig fields replaced for every method; ``velocity_std_m_s``: the fixes'
    velocity noise (None: the fixes carry no velocity)."""
    jobs = [Job(str(f), e, a, s, rate_hz, latency_ms, tuple(methods), estimator, velocity_std_m_s)
            for e in errors for a in accuracies for f in flights for s in seeds]
    t0 = time.perf_counter()
    if workers > 1:
        with ProcessPoolExecutor(workers) as pool:
            results = list(pool.map(run_job, jobs))
    else:
        results = [run_job(j) for j in jobs]
    runs = [r for rs in results for r in rs]
    conditions = []
    for e in errors:
        for a in accuracies:
            mine = [r for r in runs if r["errors"] == errors_label(e) and r["accuracy"] == a]
            filters = [*methods, *tight_rows(e)]
            table = summarise(mine, [*filters, *RAW])
            cond: dict[str, Any] = {"errors": errors_label(e), "accuracy": a, "table": table,
                                    "goals": goals(table, filters)}
            if tight_rows(e):
                best_loose = min(methods, key=lambda m: table[m]["median"]["mean"])
                cond["belief_paired"] = paired_medians(mine, BELIEF_ROW, [*BELIEF_REFERENCES, best_loose])
            conditions.append(cond)
    return {
        "campaign": {"flights": [f.name for f in flights], "split": split,
                     "errors": [errors_label(e) for e in errors],
                     "accuracy": list(accuracies), "methods": list(methods), "seeds": list(seeds),
                     "rate_hz": rate_hz, "latency_ms": latency_ms,
                     "runs": sum(len(methods) + len(tight_rows(j.errors)) for j in jobs),
                     "estimator": dict(estimator), "velocity_std_m_s": velocity_std_m_s,
                     "wall_s": time.perf_counter() - t0,
                     "bootstrap": {"seed": BOOTSTRAP_SEED, "resamples": 2000, "strata": "flight"}},
        "conditions": conditions,
        "runs": runs,
    }


# replay's synthetic GNSS option -> this campaign's name for it (GnssErrorOptions.check names replay's)
OWN_OPTION_NAMES = {"--gnss-errors": "--errors", "--gnss-accuracy": "--accuracy",
                    "--gnss-rate-hz": "--rate-hz", "--gnss-latency-ms": "--latency-ms"}


def main(argv: Sequence[str] | None = None) -> int:
    from companion.estimator import METHODS
    from gcs_tools import choices
    from gcs_tools.outdir import check_out_dir, ensure_out_dir
    from gcs_tools.replay.synthetic_gnss import ACCURACY_MODES, GnssErrorOptions, velocity_option

    p = argparse.ArgumentParser(
        prog="python -m gcs_tools.evaluate.real", description=__doc__.split("\n")[0],
        allow_abbrev=False)
    p.add_argument("--corpus", type=Path, default=None, help="the ANSFL directory (path_1, path_2, ...)")
    p.add_argument("--flights", default="reporting",
                   help="reporting (paths 5,6,7,8,10), tuning (1,2,3), all, or flight names/paths")
    p.add_argument("--errors", default="model",
                   help="comma-separated: model, none, error series CSV files, or "
                        f"{SATS}INPUT (a smartLoc drive's satellites placed on each flight: SPP fixes for "
                        "the methods, raw epochs for the tightly coupled rows)")
    p.add_argument("--accuracy", default="reported,none",
                   help=f"comma-separated of {', '.join(ACCURACY_MODES)}")
    p.add_argument("--methods", default="all",
                   help="comma-separated loosely coupled methods on the fixes (default: all that run "
                        "without a map); with smartloc-sats errors every tight-* row runs as well (the "
                        "belief per satellite is compared with each of them)")
    p.add_argument("--seeds", default="0-4")
    p.add_argument("--rate-hz", type=float, default=5.0)
    p.add_argument("--latency-ms", type=float, default=None,
                   help="fixed latency (default: the model's process)")
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--gnss-velocity", default="0.2", metavar="STD_M_S|none",
                   help="the fixes' velocity: the truth's plus white noise of this std per axis (default 0.2 "
                        "m/s), or none")
    p.add_argument("--set", action="append", default=[], metavar="estimator.FIELD=VALUE",
                   help="replace an EstimatorConfig field for every method (repeatable)")
    p.add_argument("--out", type=Path, default=Path("runs/real"))
    args = p.parse_args(argv)
    try:
        check_out_dir(args.out)
        methods = [m for m in METHODS if not needs_map(m)] if args.methods == "all" else \
            choices.methods(args.methods)
        for m in methods:
            if needs_map(m):
                raise UserError(f"--methods {m}: needs a mission's map, and a real flight has none")
        split, flights = flight_dirs(args.corpus, args.flights)
        estimator = parse_sets(args.set)
        velocity = velocity_option(args.gnss_velocity)
        errors = [e.strip() for e in args.errors.split(",") if e.strip()]
        accuracies = [a.strip() for a in args.accuracy.split(",") if a.strip()]
        for e in errors:
            if is_sats(e):
                from gcs_tools.gnss.transplant import check_choice

                check_choice(e)
            for a in accuracies:
                try:
                    GnssErrorOptions("none" if is_sats(e) else e, rate_hz=args.rate_hz, accuracy=a,
                                     latency_ms=args.latency_ms, velocity_std_m_s=velocity).check()
                except UserError as exc:  # named as replay's options: this tool's own names instead
                    text = str(exc)
                    for replay_name, own in OWN_OPTION_NAMES.items():
                        text = text.replace(replay_name, own)
                    raise UserError(text) from None
        if not errors or not accuracies:
            raise UserError("--errors and --accuracy need at least one value each")
        if "naive" not in methods:
            methods.insert(0, "naive")  # the reference of "vs naive"
        result = run(flights, errors, accuracies, methods, parse_seeds(args.seeds), args.rate_hz,
                     args.latency_ms, max(1, args.workers), split, estimator, velocity)
        out = ensure_out_dir(args.out)
    except UserError as exc:
        print(f"real: error: {exc}", file=sys.stderr)
        return 2
    runs = result.pop("runs")
    write_outputs(out, result, runs, markdown(result))
    return 0


def write_outputs(out: Path, result: dict[str, Any], runs: Sequence[dict[str, Any]], text: str) -> None:
    """``out/results.json`` (``result`` with its ``runs``, one compact line per run) and ``out/report.md``
    (``text``, also printed)."""
    from gcs_tools.replay.core import json_safe

    head = json.dumps(json_safe(result), indent=1)[:-2]
    lines = ",\n".join(json.dumps(json_safe(r), separators=(",", ":")) for r in runs)
    (out / "results.json").write_text(f'{head},\n "runs": [\n{lines}\n ]\n}}\n')
    (out / "report.md").write_text(text + "\n")
    print(text)
    print(f"wrote {out / 'results.json'} and {out / 'report.md'}")


if __name__ == "__main__":
    sys.exit(main())
