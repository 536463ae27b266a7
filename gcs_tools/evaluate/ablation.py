"""The ablation protocol: tune every row alike on the tuning set, then sweep model-mismatch severity.

    python -m gcs_tools.evaluate.ablation tune --scenario realistic --out docs/results/ablation
    beliefnav evaluate --scenario realistic --rows docs/results/ablation/rows-realistic.yaml ...
    python -m gcs_tools.evaluate.ablation severity --rows docs/results/ablation/rows-mismatch.yaml ...

``tune`` (mission ``default-tuning``, seeds 1000-1009 only — never reported):

1. the filter's IMU noise density ``estimator.sigma_acc_m_s2`` is a model of the SENSOR, shared by
   every row: swept with ``fixed-beta`` (β 0.5) and ``second-order``, the value with the lowest
   mean of their two scores is kept for every row;
2. then each method's OWN hyper-parameters are swept on their grid (``SWEEPS``) with that value;
   the best point of each becomes its row. ``fixed-beta-0.5`` stays at 0.5 (the issue's row);
   ``fixed-beta-best`` is the best β of the sweep. A re-tune (``--only``) keeps a row's point
   unless another point beats it with a paired interval excluding zero.

Score of a point: the mean over its flights of the per-flight median horizontal error (the
campaign's headline statistic). Every point is appended to ``tuning-<scenario>.jsonl``; the rows
go to ``rows-<scenario>.yaml`` (``beliefnav evaluate --rows``).

``pair`` compares the rows of one campaign with reference rows of another, paired by flight
(``paired.json``): a campaign that re-flies only re-tuned rows against the rows that did not change.

``effects`` flies the given rows on ``mismatch`` with each unmodelled GNSS effect switched off in
turn (``EFFECTS``): what each effect costs each row, paired by flight (``effects.json``).

``severity`` flies the given rows under the ``realistic`` scenario plus the unmodelled GNSS effects
scaled by a severity ``s`` (``severity_overrides``; s = 1 is the ``mismatch`` scenario, s = 0 is
``realistic``), and draws the error ratio of each belief row over the best fixed-β row against s,
with paired-bootstrap intervals (``fig_where_adaptation_pays.png``, ``severity.json``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from companion.errors import UserError
from gcs_tools import choices
from gcs_tools.evaluate import campaign, flights, stats, tuning
from gcs_tools.evaluate import rows as rows_mod
from gcs_tools.evaluate.campaign import Row

SCORE = "est_h_median_m"
SIGMA_ACC = "estimator.sigma_acc_m_s2"
SIGMA_ACC_VALUES = (0.1, 0.2, 0.4)
GATE_OFF = ("estimator.gnss_gate_sigma", 1.0e3)  # a 1000σ gate: no fix is ever rejected
_HMM = "belief_plugins.hmm_"
BIAS_LEVEL, BIAS_LEVELS = "estimator.lambda_bias_level", (0.0, 1.0, 3.0, 10.0)  # the loss's bias-level term
# Each method's own hyper-parameters: (row label, method, axes), where axes is either
# {override key: values} (their cartesian product) or an explicit tuple of points. 2-9 points each.
SWEEPS: tuple[tuple[str, str, Any], ...] = (
    ("naive", "naive", {"estimator.beta_fixed": (0.5, 1.0)}),
    ("fixed-beta-best", "fixed-beta",
     {"estimator.beta_fixed": (0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.9)}),
    ("map-beta", "map-beta", {"belief_plugins.map_beta_open": (0.9, 1.0),
                              "belief_plugins.map_beta_canyon": (0.2, 0.35, 0.5)}),
    # the trust rules: the step size and the weight of the bias-level term (0: the paper's loss; with a
    # receiver velocity the one-step innovations do not show the bias's level, docs/science.md); η 1.5
    # never won on either scenario
    ("first-order", "first-order", {"estimator.eta_first_order": (0.15, 0.5), BIAS_LEVEL: BIAS_LEVELS}),
    ("second-order", "second-order", {"estimator.eta": (0.15, 0.5), BIAS_LEVEL: BIAS_LEVELS}),
    ("second-order-gate-off", "second-order", {"estimator.eta": (0.15, 0.5), BIAS_LEVEL: BIAS_LEVELS,
                                               GATE_OFF[0]: (GATE_OFF[1],)}),
    ("adaptive", "adaptive", {"estimator.beta_fixed": (0.5, 1.0),
                              "estimator.adaptive_window_fixes": (20, 60)}),
    ("vbakf", "vbakf", {"estimator.beta_fixed": (0.5, 1.0), "estimator.vb_forgetting": (0.95, 0.98)}),
    ("windowed-ml", "windowed-ml", {"belief_plugins.window_fixes": (20, 60), BIAS_LEVEL: BIAS_LEVELS}),
    # hmm-trust: the (clean, degraded) trust pair, the outlier level's R factor and the dwell time
    ("hmm-trust", "hmm-trust", tuple(
        ((_HMM + "beta_clean", c), (_HMM + "beta_degraded", d), (_HMM + "outlier_r_factor", o),
         (_HMM + "dwell_s", w))
        for c, d, o, w in ((1.0, 0.0, 25.0, 2.0), (0.8, 0.2, 25.0, 2.0), (0.7, 0.3, 25.0, 2.0),
                           (0.6, 0.4, 25.0, 2.0), (0.7, 0.3, 100.0, 2.0), (0.6, 0.4, 100.0, 2.0),
                           (0.7, 0.3, 25.0, 5.0), (0.6, 0.4, 25.0, 5.0)))),
    # map-hmm: the evidence weight κ and the dwell time, at the trust levels map-beta's sweep chose
    ("map-hmm", "map-hmm", {"belief_plugins.mhmm_evidence": (0.1, 0.3, 1.0),
                            "belief_plugins.mhmm_dwell_s": (1.0, 3.0)}),
)
# A row whose sweep starts from another row's chosen point (its own keys override that point's).
INHERITS = {"map-hmm": "map-beta"}
ROW_ORDER = ("naive", "fixed-beta-0.5", "fixed-beta-best", "map-beta", "first-order", "second-order",
             "second-order-gate-off", "adaptive", "vbakf", "windowed-ml", "hmm-trust", "map-hmm")
SEVERITIES = (0.0, 1.0, 2.0)
# The mismatch scenario's unmodelled GNSS effects, each switched off in turn (``effects``)
EFFECTS: tuple[tuple[str, str, tuple[tuple[str, Any], ...]], ...] = (
    ("no reflections", "a blocked satellite is lost, never tracked by its reflection",
     (("gnss.nlos", False),)),
    ("canyon bias 3 s", "the canyon bias correlation time the filter assumes (3 s, not 10 s)",
     (("gnss.gamma_canyon_s", 3.0),)),
    ("Gaussian noise", "no Student-t tail", (("gnss.heavy_tail_dof", 0.0),)),
    ("fixed geometry", "the white noise does not grow with the satellites lost",
     (("gnss.satellite_noise", False),)),
)
# campaign directories the report picks up: the two scenarios, mismatch with the step offset limited, and
# each scenario with the receiver's velocity (every row at its earlier settings; the rows re-tuned for it)
CAMPAIGNS = ("realistic", "realistic-velocity", "realistic-velocity-retuned", "mismatch",
             "mismatch-offset-limited", "mismatch-velocity", "mismatch-velocity-retuned")


def severity_overrides(s: float) -> tuple[tuple[str, Any], ...]:
    """GNSS overrides of severity ``s`` on top of ``realistic``: NLOS delay s m (mean), canyon bias
    correlation 3 + 7 s seconds (the filter assumes 3), Student-t dof 2 + 1/s; off at s = 0.
    s = 1 reproduces the ``mismatch`` scenario's GNSS."""
    if s < 0:
        raise UserError(f"severity: expected >= 0, got {s}")
    if s == 0:
        return ()
    return (("gnss.nlos", True), ("gnss.satellite_noise", True), ("gnss.nlos_delay_mean_m", 1.0 * s),
            ("gnss.gamma_canyon_s", 3.0 + 7.0 * s), ("gnss.heavy_tail_dof", 2.0 + 1.0 / s))


def _points(axes: Any) -> list[tuple[tuple[str, Any], ...]]:
    """The points of a sweep: an explicit tuple of points, or the product of a {key: values} map."""
    import itertools

    if not isinstance(axes, dict):
        return [tuple(p) for p in axes]
    keys = list(axes)
    return [tuple(zip(keys, values, strict=True)) for values in itertools.product(*(axes[k] for k in keys))]


def _fly(rows: Sequence[Row], scenario: str | None, profiles: Sequence[int], seeds: Sequence[int],
         workers: int, mission: str = tuning.TUNING_MISSION,
         overrides: Sequence[tuple[str, Any]] = ()) -> list[campaign.JobResult]:
    for row in rows:
        tuning.check(campaign.mission(mission, tuple(overrides) + row.overrides, scenario))
    jobs = campaign.grid_rows(mission, profiles, rows, seeds, overrides=overrides, scenario=scenario)
    return campaign.run(jobs, workers, progress=sys.stderr.isatty())


def _score(results: Sequence[campaign.JobResult], label: str) -> float:
    v = [r.flight[SCORE] for r in results if r.job.row == label]
    return float(np.nanmean(v)) if v else float("nan")


def paired_gap(results: Sequence[campaign.JobResult], label: str, winner: str,
               rng: np.random.Generator, n_resamples: int = 2000) -> tuple[float, float, float]:
    """mean(label − winner) of the per-flight score over the same flights, with a 95 % paired
    stratified bootstrap interval: how far a candidate is behind the chosen point, and whether
    the tuning set can tell them apart."""
    return table_gap(flights.table_of(results, label), flights.table_of(results, winner), rng, n_resamples)


def table_gap(a: dict[tuple[int, int], dict[str, float]], b: dict[tuple[int, int], dict[str, float]],
              rng: np.random.Generator, n_resamples: int = 2000) -> tuple[float, float, float]:
    """mean(a − b) of the per-flight score over the flights both tables hold ((profile, seed) →
    statistics), with its 95 % paired stratified bootstrap interval."""
    keys = sorted(set(a) & set(b))
    if not keys:
        return (float("nan"),) * 3
    d = np.array([a[k][SCORE] - b[k][SCORE] for k in keys])
    idx = stats.stratified_indices(np.array([k[0] for k in keys]), rng, n_resamples)
    lo, hi = np.percentile(d[idx].mean(axis=1), [2.5, 97.5])
    return float(d.mean()), float(lo), float(hi)


def choose(results: Sequence[campaign.JobResult], candidates: Sequence[Row], scores: dict[str, float],
           incumbent: Row | None, rng: np.random.Generator) -> Row:
    """The candidate with the lowest mean score, except that an incumbent (the row's point before a
    re-tune) is kept unless that candidate beats it with a paired 95 % interval excluding zero: a
    few tuning flights per point cannot tell small gaps apart, and a re-tune should not move a row
    on noise."""
    win = min(candidates, key=lambda c: scores[c.label])
    if incumbent is None or win is incumbent:
        return win
    _, lo, _ = paired_gap(results, incumbent.label, win.label, rng)
    return win if lo > 0.0 else incumbent


def tune(scenario: str, seeds: Sequence[int], profiles: Sequence[int], workers: int, out: Path,
         only: Sequence[str] = ()) -> list[Row]:
    """Tune every row (or re-tune the rows ``only`` names, keeping the others and the shared IMU
    noise density from ``rows-<scenario>.yaml``). Every point of a sweep flies the same flights
    (profiles × seeds; common random numbers), so the point with the lowest mean is the lowest
    paired mean; each record also carries its paired gap to the winner with a 95 % interval. A
    re-tuned row keeps its point unless another beats it significantly (``choose``)."""
    out.mkdir(parents=True, exist_ok=True)
    log = out / f"tuning-{scenario}.jsonl"
    rows_path = out / f"rows-{scenario}.yaml"
    unknown = sorted(set(only) - {label for label, _, _ in SWEEPS})
    if unknown:
        known = ", ".join(s[0] for s in SWEEPS)
        raise UserError(f"--only: no sweep for {', '.join(unknown)} (known: {known})")
    rng = np.random.default_rng(flights.BOOTSTRAP_SEED)

    def record(stage: str, row: Row, score: float, n: int, wall_s: float,
               gap: tuple[float, float, float] | None = None) -> None:
        entry = {"scenario": scenario, "stage": stage, "row": row.label, "method": row.method,
                 "overrides": dict(row.overrides), "profiles": list(profiles), "seeds": list(seeds),
                 "flights": n, "score_" + SCORE: score, "wall_s": round(wall_s, 1)}
        if gap is not None:
            entry["paired_gap_to_winner_m"] = [round(v, 4) for v in gap]
        with log.open("a", encoding="utf-8") as f:
            f.write(json.dumps(entry) + "\n")
        tail = f" (vs winner {gap[0]:+.3f} [{gap[1]:+.3f}, {gap[2]:+.3f}])" if gap is not None else ""
        print(f"{scenario} {stage} {row.label} {dict(row.overrides)} -> {score:.3f}{tail}", flush=True)

    if only:  # re-tune some rows: the shared value and the other rows as the rows file has them
        kept = {r.label: r for r in rows_mod.load_rows(rows_path)} if rows_path.exists() else {}
        if "fixed-beta-0.5" not in kept:
            raise UserError(f"--only needs {rows_path} from a full tuning run (its fixed-beta-0.5 row)")
        shared = tuple(o for o in kept["fixed-beta-0.5"].overrides if o[0] == SIGMA_ACC)
        chosen = dict(kept)
    else:
        # 1. the shared IMU noise model
        best_sigma, best = SIGMA_ACC_VALUES[0], float("inf")
        for sigma in SIGMA_ACC_VALUES:
            o = ((SIGMA_ACC, sigma),)
            rows = [Row("fixed-beta-0.5", "fixed-beta", o + (("estimator.beta_fixed", 0.5),)),
                    Row("second-order", "second-order", o)]
            t0 = time.perf_counter()
            res = _fly(rows, scenario, profiles, seeds, workers)
            score = 0.5 * (_score(res, "fixed-beta-0.5") + _score(res, "second-order"))
            wall_s = time.perf_counter() - t0
            record("shared", Row("fixed-beta-0.5+second-order", "-", o), score, len(res), wall_s)
            if score < best:
                best_sigma, best = sigma, score
        shared = ((SIGMA_ACC, best_sigma),)
        chosen = {}
    chosen["fixed-beta-0.5"] = Row("fixed-beta-0.5", "fixed-beta", shared + (("estimator.beta_fixed", 0.5),))

    # 2. every method's own hyper-parameters, on the shared value
    for label, method, axes in SWEEPS:
        if only and label not in only:
            continue
        base: tuple[tuple[str, Any], ...] = shared
        if label in INHERITS:  # start from the chosen point of the row it builds on
            parent = chosen[INHERITS[label]].overrides
            base = tuple(o for o in parent if not any(o[0] == k for k, _ in _points(axes)[0]))
        candidates = [Row(f"{label}#{i}", method, base + p) for i, p in enumerate(_points(axes))]
        t0 = time.perf_counter()
        res = _fly(candidates, scenario, profiles, seeds, workers)
        wall = (time.perf_counter() - t0) / len(candidates)
        scores = {c.label: _score(res, c.label) for c in candidates}
        before = dict(chosen[label].overrides) if label in chosen else None  # a re-tune: the row's point
        incumbent = next((c for c in candidates if dict(c.overrides) == before), None)
        win = choose(res, candidates, scores, incumbent, rng)
        for c in candidates:
            record("own", Row(label, method, c.overrides), scores[c.label], len(res) // len(candidates), wall,
                   paired_gap(res, c.label, win.label, rng))
        chosen[label] = Row(label, method, win.overrides)
    rows = [chosen[label] for label in ROW_ORDER if label in chosen]
    write_rows(rows_path, rows, scenario, profiles, seeds, only)
    return rows


def shared_sweep(scenario: str, rows: Sequence[Row], key: str, values: Sequence[Any], seeds: Sequence[int],
                 profiles: Sequence[int], workers: int, out: Path) -> Any:
    """A setting shared by every row (e.g. ``estimator.gnss_offset_max_s``), chosen on the tuning set
    alike for all: each value flies every given row on the same flights; the value with the lowest
    mean of the rows' scores wins. Records go to ``tuning-<scenario>.jsonl`` (stage ``shared``)."""
    out.mkdir(parents=True, exist_ok=True)
    candidates = [Row(f"{r.label}@{i}", r.method, r.overrides + ((key, v),))
                  for i, v in enumerate(values) for r in rows]
    t0 = time.perf_counter()
    res = _fly(candidates, scenario, profiles, seeds, workers)
    wall_s = time.perf_counter() - t0
    means = {}
    with (out / f"tuning-{scenario}.jsonl").open("a", encoding="utf-8") as f:
        for i, v in enumerate(values):
            scores = {r.label: _score(res, f"{r.label}@{i}") for r in rows}
            means[v] = float(np.mean(list(scores.values())))
            f.write(json.dumps({"scenario": scenario, "stage": "shared", "key": key, "value": v,
                                "rows": scores, "score_mean_" + SCORE: means[v], "profiles": list(profiles),
                                "seeds": list(seeds), "flights": len(res) // len(values),
                                "wall_s": round(wall_s / len(values), 1)}) + "\n")
            print(f"{scenario} shared {key}={v}: " + ", ".join(f"{k} {x:.3f}" for k, x in scores.items())
                  + f" -> mean {means[v]:.3f}", flush=True)
    best = min(values, key=lambda v: means[v])
    print(f"{scenario} shared {key}: chosen {best}", flush=True)
    return best


def write_rows(path: Path, rows: Sequence[Row], scenario: str, profiles: Sequence[int],
               seeds: Sequence[int], only: Sequence[str] = ()) -> None:
    body = {"rows": {r.label: {"method": r.method, "set": dict(r.overrides)} for r in rows}}
    which = f"rows {', '.join(only)} re-tuned" if only else "every row tuned"
    head = (f"# Rows of the {scenario!r} ablation, each at the hyper-parameters the tuning sweep chose\n"
            f"# (python -m gcs_tools.evaluate.ablation tune; mission {tuning.TUNING_MISSION}, {which} on "
            f"profiles {list(profiles)}, seeds {list(seeds)}; records in tuning-{scenario}.jsonl).\n")
    path.write_text(head + yaml.safe_dump(body, sort_keys=False), encoding="utf-8")


def ratio_ci(results: Sequence[campaign.JobResult], row: str, base: str, rng: np.random.Generator,
             n_resamples: int = 2000) -> tuple[float, float, float]:
    """mean(row) / mean(base) of the per-flight score over matched flights, paired stratified bootstrap."""
    a, b = flights.table_of(results, row), flights.table_of(results, base)
    keys = sorted(set(a) & set(b))
    va = np.array([a[k][SCORE] for k in keys])
    vb = np.array([b[k][SCORE] for k in keys])
    if not keys:
        return (float("nan"),) * 3
    idx = stats.stratified_indices(np.array([k[0] for k in keys]), rng, n_resamples)
    ratios = va[idx].mean(axis=1) / vb[idx].mean(axis=1)
    lo, hi = np.percentile(ratios, [2.5, 97.5])
    return float(va.mean() / vb.mean()), float(lo), float(hi)


def severity(rows: Sequence[Row], levels: Sequence[float], profiles: Sequence[int], seeds: Sequence[int],
             workers: int, out: Path, mission: str = "default",
             shared: Sequence[tuple[str, Any]] = ()) -> dict[str, Any]:
    """``shared``: overrides every flight gets (a setting chosen for every row alike, e.g. the
    GNSS step offset's limit)."""
    base = "fixed-beta-best"
    if base not in {r.label for r in rows}:
        raise UserError(f"severity: the rows need a {base!r} row")
    rng = np.random.default_rng(flights.BOOTSTRAP_SEED)
    table: dict[str, Any] = {"base": base, "score": SCORE, "profiles": list(profiles), "seeds": list(seeds),
                             "mission": mission, "shared": dict(shared), "levels": {}}
    t0 = time.perf_counter()
    for s in levels:
        overrides = tuple(shared) + severity_overrides(s)
        res = _fly(rows, "realistic", profiles, seeds, workers, mission, overrides)
        entry = {r.label: dict(zip(("ratio", "lo", "hi"), ratio_ci(res, r.label, base, rng), strict=True))
                 for r in rows if r.label != base}
        entry[base] = {"mean_m": _score(res, base)}
        table["levels"][str(s)] = entry
        table.setdefault("flights", {})[str(s)] = {  # profile/seed -> score, to recompute from
            r.label: {f"{k[0]}/{k[1]}": v[SCORE] for k, v in flights.table_of(res, r.label).items()}
            for r in rows
        }
        cells = [f"{k} {v.get('ratio', v.get('mean_m')):.3f}" for k, v in entry.items()]
        print(f"severity {s}: " + ", ".join(cells), flush=True)
    table["wall_s"] = round(time.perf_counter() - t0, 1)
    out.mkdir(parents=True, exist_ok=True)
    (out / "severity.json").write_text(json.dumps(table, indent=2) + "\n", encoding="utf-8")
    figure(table, out / "fig_where_adaptation_pays.png")
    return table


def effects(rows: Sequence[Row], profiles: Sequence[int], seeds: Sequence[int], workers: int, out: Path,
            mission: str = "default", shared: Sequence[tuple[str, Any]] = ()) -> dict[str, Any]:
    """Fly ``rows`` on ``mismatch`` with every unmodelled GNSS effect on, then with each of ``EFFECTS``
    switched off in turn: each row's mean score, and the paired difference (effect off − all on)
    with its 95 % interval, which is what that effect costs the row (``effects.json``)."""
    rng = np.random.default_rng(flights.BOOTSTRAP_SEED)
    table: dict[str, Any] = {"score": SCORE, "profiles": list(profiles), "seeds": list(seeds),
                             "mission": mission, "shared": dict(shared), "effects": {}}
    t0 = time.perf_counter()
    all_on: dict[str, Any] = {}
    for name, what, off in (("all on", "the mismatch scenario", ()), *EFFECTS):
        res = _fly(rows, "mismatch", profiles, seeds, workers, mission, tuple(shared) + off)
        entry: dict[str, Any] = {"what": what, "overrides": dict(off), "rows": {}}
        for r in rows:
            t = flights.table_of(res, r.label)
            all_on.setdefault(r.label, t)
            gap = table_gap(t, all_on[r.label], rng) if off else (0.0, 0.0, 0.0)
            entry["rows"][r.label] = {"mean_m": _score(res, r.label), "minus_all_on": list(gap)}
        table["effects"][name] = entry
        print(f"effects {name}: " + ", ".join(f"{k} {v['mean_m']:.3f}" for k, v in entry["rows"].items()),
              flush=True)
    table["wall_s"] = round(time.perf_counter() - t0, 1)
    out.mkdir(parents=True, exist_ok=True)
    (out / "effects.json").write_text(json.dumps(table, indent=2) + "\n", encoding="utf-8")
    return table


def _per_flight(campaign_dir: Path) -> dict[str, dict[tuple[int, int], dict[str, float]]]:
    """row → (profile, seed) → that flight's statistics, from a campaign's results.json."""
    path = campaign_dir / "results.json"
    if not path.exists():
        raise UserError(f"{path}: no campaign results there")
    per_flight = json.loads(path.read_text(encoding="utf-8"))["flights"]["per_flight"]
    return {row: {(int(k.split("/")[0]), int(k.split("/")[1])): v for k, v in table.items()}
            for row, table in per_flight.items()}


def pair(new: Path, base: Path, references: Sequence[str]) -> dict[str, Any]:
    """Every row of campaign ``new`` against each ``references`` row of campaign ``base``, paired by
    (profile, seed): mean(row − reference) of the per-flight score with its 95 % stratified bootstrap
    interval (``table_gap``). Valid when the two campaigns fly bit-identical flights for rows whose
    settings did not change (same code, common random numbers): re-flying only the re-tuned rows
    then compares them with the rest. Written to ``new/paired.json``."""
    a, b = _per_flight(new), _per_flight(base)
    missing = sorted(set(references) - set(b))
    if missing:
        raise UserError(f"--reference: {', '.join(missing)} not in {base} (rows: {', '.join(b)})")
    rng = np.random.default_rng(flights.BOOTSTRAP_SEED)
    rows = {row: {ref: list(table_gap(a[row], b[ref], rng)) for ref in references} for row in a}
    table = {"score": SCORE, "new": str(new), "base": str(base), "rows": rows}
    (new / "paired.json").write_text(json.dumps(table, indent=2) + "\n", encoding="utf-8")
    for row, gaps in rows.items():
        cells = (f"− {ref} {d:+.3f} [{lo:+.3f}, {hi:+.3f}]" for ref, (d, lo, hi) in gaps.items())
        print(f"{row}: " + ", ".join(cells))
    return table


def figure(table: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from gcs_tools.evaluate.plots import color
    from gcs_tools.figures import DPI

    levels = sorted(table["levels"], key=float)
    x = np.array([float(s) for s in levels])
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    labels = [k for k in table["levels"][levels[0]] if k != table["base"]]
    for i, label in enumerate(labels):
        r = np.array([table["levels"][s][label]["ratio"] for s in levels])
        lo = np.array([table["levels"][s][label]["lo"] for s in levels])
        hi = np.array([table["levels"][s][label]["hi"] for s in levels])
        dx = (i - (len(labels) - 1) / 2) * 0.03
        ax.errorbar(x + dx, r, yerr=[r - lo, hi - r], marker="o", capsize=3, label=label,
                    color=color(label.split("#")[0]) if label in ("second-order", "first-order") else None)
    ax.axhline(1.0, color="k", lw=0.8, ls="--")
    ax.set_xlabel("model-mismatch severity s (0 = realistic, 1 = mismatch scenario)")
    ax.set_ylabel(f"error ratio: row / {table['base']}")
    ax.set_title("Where adaptation pays: < 1 = better than the best fixed β", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def report(out: Path) -> str:
    """``out/report.md``: the hand-written findings (``findings.md``), then per scenario the tuned rows,
    the per-flight table and the cost, then the severity table; from the files the steps wrote."""
    parts = ["# Ablation: what the belief adaptation buys, on sensors that do not flatter the filter", ""]
    findings = out / "findings.md"
    if findings.exists():
        parts += [findings.read_text(encoding="utf-8").strip(), ""]
    for campaign_dir in CAMPAIGNS:
        res_path = out / campaign_dir / "results.json"
        if not res_path.exists():
            continue
        res = json.loads(res_path.read_text(encoding="utf-8"))
        c = res["campaign"]
        scenario = c.get("scenario") or campaign_dir  # whose rows and tuning records the campaign flew
        parts += [f"## `{campaign_dir}`", "",
                  f"Mission `{c['mission']}`, profiles {c['profiles'][0]}–{c['profiles'][-1]}, seeds "
                  f"{', '.join(map(str, c['seeds']))}: {c['flights']} flights, {c['wall_s']:.0f} s wall on "
                  f"{c['workers']} workers, {c.get('flight_cpu_s', float('nan')):.0f} s of flight CPU "
                  f"(full report: [{campaign_dir}/report.md]({campaign_dir}/report.md))"
                  + _every_row(c.get("overrides")) + ".", "",
                  flights.markdown(res["flights"]),
                  *_more_tables(res["flights"]),
                  *_paired_section(out / campaign_dir),
                  "Rows (hyper-parameters chosen on the tuning set, "
                  f"[rows-{scenario}.yaml](rows-{scenario}.yaml), sweep records "
                  f"[tuning-{scenario}.jsonl](tuning-{scenario}.jsonl)):", ""]
        for label, row in c["rows"].items():
            sets = ", ".join(f"`{k}={v}`" for k, v in row["overrides"].items()) or "defaults"
            parts.append(f"- `{label}` = `{row['method']}`: {sets}")
        parts.append("")
    sev_path = out / "severity" / "severity.json"
    if sev_path.exists():
        sev = json.loads(sev_path.read_text(encoding="utf-8"))
        levels = sorted(sev["levels"], key=float)
        labels = [k for k in sev["levels"][levels[0]] if k != sev["base"]]
        parts += ["## Where adaptation pays", "",
                  f"Error ratio (mean per-flight median horizontal error, row / `{sev['base']}`) over the "
                  f"severity of the unmodelled GNSS (0 = `realistic`, 1 = `mismatch`); 95 % paired bootstrap "
                  f"intervals; profiles {sev['profiles'][0]}–{sev['profiles'][-1]}, seeds "
                  f"{', '.join(map(str, sev['seeds']))}, {sev['wall_s']:.0f} s wall"
                  f"{_every_row(sev.get('shared'))}.", "",
                  "| severity | " + " | ".join(f"`{k}`" for k in labels) + f" | `{sev['base']}` [m] |",
                  "|---|" + "---|" * (len(labels) + 1)]
        for s in levels:
            e = sev["levels"][s]
            cells = [f"{e[k]['ratio']:.3f} [{e[k]['lo']:.3f}, {e[k]['hi']:.3f}]" for k in labels]
            parts.append(f"| {s} | " + " | ".join(cells) + f" | {e[sev['base']]['mean_m']:.3f} |")
        parts += ["", "![where adaptation pays](severity/fig_where_adaptation_pays.png)", ""]
    eff_path = out / "effects" / "effects.json"
    if eff_path.exists():
        parts += _effects_section(json.loads(eff_path.read_text(encoding="utf-8")))
    text = "\n".join(parts) + "\n"
    (out / "report.md").write_text(text, encoding="utf-8")
    return text


def _every_row(settings: Any) -> str:
    """The report's "; every row with `k=v`" for each setting all rows shared ({k: v} or pairs)."""
    return "".join(f"; every row with `{k}={v}`" for k, v in dict(settings or {}).items())


def _effects_section(eff: dict[str, Any]) -> list[str]:
    """The ``effects`` table: each row's mean error with every effect on, and with one switched off
    (the paired difference to all on, with its interval)."""
    names = list(eff["effects"])
    labels = list(eff["effects"][names[0]]["rows"])
    shared = _every_row(eff.get("shared"))
    lines = ["## What each unmodelled GNSS effect costs", "",
             f"Mean per-flight median horizontal error (m) on `mismatch`, then with one effect switched off "
             f"(off − all on, paired by flight, 95 % interval); mission `{eff['mission']}`, profiles "
             f"{eff['profiles'][0]}–{eff['profiles'][-1]}, seeds {', '.join(map(str, eff['seeds']))}, "
             f"{eff['wall_s']:.0f} s wall{shared}.", "",
             "| GNSS | " + " | ".join(f"`{k}`" for k in labels) + " |", "|---|" + "---|" * len(labels)]
    for name in names:
        e = eff["effects"][name]
        cells = []
        for k in labels:
            v = e["rows"][k]
            d, lo, hi = v["minus_all_on"]
            gap = f" ({d:+.3f} [{lo:+.3f}, {hi:+.3f}])" if e["overrides"] else ""
            cells.append(f"{v['mean_m']:.3f}{gap}")
        lines.append(f"| {name}: {e['what']} | " + " | ".join(cells) + " |")
    return lines + [""]


def _paired_section(campaign_dir: Path) -> list[str]:
    """The ``pair`` table of a campaign (``paired.json``, if any): its rows against another campaign's."""
    path = campaign_dir / "paired.json"
    if not path.exists():
        return []
    t = json.loads(path.read_text(encoding="utf-8"))
    refs = list(next(iter(t["rows"].values())))
    lines = [f"Paired against rows of `{Path(t['base']).name}`, at the settings that campaign flew (row − "
             "reference, mean per-flight median horizontal error [m], 95 % interval; `ablation pair`):", "",
             "| row | " + " | ".join(f"− `{r}`" for r in refs) + " |", "|---|" + "---|" * len(refs)]
    for row, gaps in t["rows"].items():
        lines.append(f"| `{row}` | " + " | ".join(
            f"{d:+.3f} [{lo:+.3f}, {hi:+.3f}]{' *' if lo > 0 or hi < 0 else ''}"
            for d, lo, hi in (gaps[r] for r in refs)) + " |")
    return lines + [""]


def _more_tables(block: dict[str, Any]) -> list[str]:
    """A paired table against each further reference row of the campaign (``--reference A,B``)."""
    out: list[str] = []
    for ref in block.get("paired_by_reference", {}):
        if ref != block["reference"]:
            out += [f"Paired against `{ref}` (`{ref}` − row; * = interval excludes 0):", "",
                    flights.markdown_paired(block, ref)]
    return out


def _tuning_seeds(text: str) -> tuple[int, ...]:
    seeds = choices.seeds(text)
    if not set(seeds) <= set(tuning.TUNING_SEEDS):
        raise UserError(f"--seeds: tuning seeds are {tuning.TUNING_SEEDS[0]}–{tuning.TUNING_SEEDS[-1]}")
    return seeds


def _campaign_parser(sub: Any, name: str, help_text: str) -> argparse.ArgumentParser:
    """A subcommand that flies rows of a rows file on the reported profiles (severity, effects)."""
    c: argparse.ArgumentParser = sub.add_parser(name, allow_abbrev=False, help=help_text)
    c.add_argument("--rows", type=Path, required=True)
    c.add_argument("--methods", default=None, help="row labels to fly (default: all rows of the file)")
    c.add_argument("--profiles", default="10", help="reported profiles: a count N (0..N-1) or a list/range")
    choices.add_deprecated_alias(c, "--missions", "--profiles", "profiles")
    c.add_argument("--seeds", default="0")
    c.add_argument("--workers", type=int, default=2)
    c.add_argument("--set", action="append", default=[], metavar="SECTION.FIELD=VALUE",
                   help="override for every flight (a setting shared by every row); repeatable")
    c.add_argument("--out", type=Path, default=Path(f"docs/results/ablation/{name}"))
    return c


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(allow_abbrev=False, prog="python -m gcs_tools.evaluate.ablation",
                                description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="command", required=True)
    t = sub.add_parser("tune", allow_abbrev=False,
                       help="tune every row alike on the tuning set; write rows-<scenario>.yaml")
    t.add_argument("--scenario", required=True)
    t.add_argument("--seeds", default="1000")
    t.add_argument("--profiles", default=None, help=f"profiles of {tuning.TUNING_MISSION} (default: all)")
    t.add_argument("--workers", type=int, default=2)
    t.add_argument("--out", type=Path, default=Path("docs/results/ablation"))
    t.add_argument("--only", default="", metavar="ROW[,ROW...]",
                   help="re-tune these rows only; the others and the shared value stay as "
                        "rows-<scenario>.yaml has them")
    s = _campaign_parser(sub, "severity", "error ratio against the best fixed β over mismatch severity")
    s.add_argument("--levels", default=",".join(str(v) for v in SEVERITIES))
    _campaign_parser(sub, "effects", "mismatch with each unmodelled GNSS effect switched off in turn")
    h = sub.add_parser("shared", allow_abbrev=False,
                       help="choose one setting shared by every row, on the tuning set alike")
    h.add_argument("--scenario", required=True)
    h.add_argument("--rows", type=Path, required=True)
    h.add_argument("--methods", default=None, help="row labels to fly (default: all rows of the file)")
    h.add_argument("--vary", required=True, metavar="SECTION.FIELD=V1,V2,...")
    h.add_argument("--seeds", default="1000-1004")
    h.add_argument("--profiles", default=None, help=f"profiles of {tuning.TUNING_MISSION} (default: all)")
    h.add_argument("--workers", type=int, default=2)
    h.add_argument("--out", type=Path, default=Path("docs/results/ablation"))
    q = sub.add_parser("pair", allow_abbrev=False,
                       help="rows of a campaign against rows of another, paired by flight")
    q.add_argument("new", type=Path, help="campaign directory whose rows are compared (e.g. re-tuned rows)")
    q.add_argument("base", type=Path, help="campaign directory holding the reference rows")
    q.add_argument("--reference", required=True, metavar="ROW[,ROW...]")
    r = sub.add_parser("report", allow_abbrev=False, help="write OUT/report.md from the steps' outputs")
    r.add_argument("--out", type=Path, default=Path("docs/results/ablation"))
    args = p.parse_args(argv)
    try:
        if args.command == "report":
            report(args.out)
        elif args.command == "pair":
            pair(args.new, args.base, [v for v in args.reference.split(",") if v])
        elif args.command == "shared":
            key, _, raw = args.vary.partition("=")
            values = [tuning.parse_override(f"{key}={v}")[1] for v in raw.split(",") if v]
            if not values:
                raise UserError(f"--vary: expected SECTION.FIELD=V1,V2,..., got {args.vary!r}")
            seeds = _tuning_seeds(args.seeds)
            rows = rows_mod.select(rows_mod.load_rows(args.rows), args.methods)
            shared_sweep(args.scenario, rows, tuning.parse_override(f"{key}={values[0]}")[0], values, seeds,
                         tuning.profiles(args.profiles), args.workers, args.out)
        elif args.command == "tune":
            seeds = _tuning_seeds(args.seeds)
            profiles = tuning.profiles(args.profiles)
            only = [v for v in args.only.split(",") if v]
            tune(args.scenario, seeds, profiles, args.workers, args.out, only)
        else:
            rows = rows_mod.select(rows_mod.load_rows(args.rows), args.methods)
            profiles = choices.profiles(args.profiles, len(campaign.mission("default").profiles))
            seeds = choices.seeds(args.seeds)
            shared = [tuning.parse_override(v) for v in args.set]
            if args.command == "effects":
                effects(rows, profiles, seeds, args.workers, args.out, shared=shared)
            else:
                levels = [float(v) for v in args.levels.split(",")]
                severity(rows, levels, profiles, seeds, args.workers, args.out, shared=shared)
    except UserError as exc:
        print(f"ablation: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
