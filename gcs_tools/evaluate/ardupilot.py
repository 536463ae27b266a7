"""``beliefnav evaluate --vehicle ardupilot``: EKF3 beside the companion's methods over profiles and seeds.

Each (profile, seed) is one ArduCopter SITL flight in open loop (it flies on EKF3; ``sitl
--vehicle ardupilot``), on its own ``-I`` instance, ``--workers`` at a time. Every companion
method is run on that flight's recorded IMU, attitude and GNSS, so all rows share the same
fixes. Statistics as the simulated campaign's (``aggregate``): pooled 20-50 Hz samples per row;
with two or more seeds, the median of per-seed medians with a percentile-bootstrap 95 % CI over
seeds and the reduction against EKF3 with its paired bootstrap CI. Errors are HORIZONTAL (EKF3
holds height on the barometer, which the companion does not have; 3-D figures are in each
flight's summary). Closed loop (``gps-input``): the same profiles and seeds flown again with
ArduPilot on the second-order companion's cleaned fixes; compared on tracking error,
collisions and goals reached. Flights whose commands reached ArduPilot late (the machine's
scheduler, ``valid`` False) are listed but left out of the statistics.
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from gcs_tools.ardupilot.analysis import AUTOPILOT_ROW
from gcs_tools.ardupilot.config import ArduPilotConfig
from gcs_tools.evaluate import stats
from gcs_tools.jsonvalues import plain_json

BOOTSTRAP_SEED = 20240917
CLOSED_LOOP_METHOD = "second-order"


@dataclass(frozen=True)
class ApJob:
    mission: str
    profile: int
    seed: int
    methods: tuple[str, ...]
    out_dir: Path
    config: ArduPilotConfig
    feed: str = "none"  # "gps-input": closed loop, ArduPilot flies on CLOSED_LOOP_METHOD's cleaned fixes


@dataclass(frozen=True)
class ApResult:
    job: ApJob
    errors_h_m: dict[str, np.ndarray]  # row -> horizontal error per sample (route phase)
    track_error_m: np.ndarray
    reached_goal: bool
    collisions: int
    ended_by: str
    sim_s: float
    wall_s: float
    error: str = ""  # a flight that could not be flown (its rows are absent, the reason kept)
    valid: bool = True  # False: our commands reached ArduPilot late (scheduler), left out of the statistics
    command_delay_p95_ms: float = float("nan")


def run_job(job: ApJob) -> ApResult:
    from companion.errors import UserError
    from gcs_tools.ardupilot.flight import HORIZONTAL_ERROR_PREFIX, ArduPilotFlightOptions, fly_ardupilot
    from gcs_tools.fly.output import write_outputs

    opts = ArduPilotFlightOptions(mission=job.mission, profile=job.profile, method=CLOSED_LOOP_METHOD,
                                  seed=job.seed, out_dir=job.out_dir, config=job.config, methods=job.methods,
                                  feed=job.feed)
    try:
        r = fly_ardupilot(opts)
    except UserError as exc:
        return ApResult(job, {}, np.zeros(0), False, 0, "error", 0.0, 0.0, str(exc))
    s, series = r.summary, r.series
    if series:
        from companion.mission import load_mission

        write_outputs(r, load_mission(job.mission).world, job.out_dir)
    errs = {k[len(HORIZONTAL_ERROR_PREFIX):]: np.asarray(v) for k, v in series.items()
            if k.startswith(HORIZONTAL_ERROR_PREFIX)}
    ap = s["ardupilot"]
    return ApResult(job, errs, np.asarray(series.get("track_error_m", np.zeros(0))), bool(s["reached_goal"]),
                    int(s["collisions"]), str(ap["ended_by"]), float(ap["sim_s"]), float(ap["wall_s"]),
                    valid=bool(s["valid"]), command_delay_p95_ms=float(ap["command_delay_ms"]["p95"]))


def run(jobs: Sequence[ApJob], workers: int) -> list[ApResult]:
    if workers <= 1:
        return [run_job(j) for j in jobs]
    with ProcessPoolExecutor(max_workers=workers) as pool:
        return list(pool.map(run_job, jobs))


def usable(r: ApResult) -> bool:
    return not r.error and r.valid


def pooled(results: Sequence[ApResult], row: str) -> np.ndarray:
    """Every horizontal-error sample of ``row`` over the flights that were flown."""
    parts = [r.errors_h_m[row] for r in results if usable(r) and row in r.errors_h_m]
    return np.concatenate(parts) if parts else np.zeros(0)


def aggregate(results: Sequence[ApResult], rows: Sequence[str], seeds: Sequence[int]) -> dict[str, Any]:
    """Per row: pooled horizontal error stats, per-seed CI and the reduction against EKF3."""
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    ok = [r for r in results if usable(r) and r.job.feed == "none"]  # open loop: the estimators compared

    def seed_medians(row: str) -> np.ndarray:
        out = []
        for seed in seeds:
            parts = [r.errors_h_m[row] for r in ok if r.job.seed == seed and row in r.errors_h_m]
            x = np.concatenate(parts) if parts else np.zeros(0)
            x = x[np.isfinite(x)]
            out.append(float(np.median(x)) if x.size else float("nan"))
        return np.array(out)

    ekf_seeds = seed_medians(AUTOPILOT_ROW)
    ekf_pooled = stats.summarize(pooled(ok, AUTOPILOT_ROW))
    table: dict[str, Any] = {}
    for row in rows:
        entry: dict[str, Any] = dict(stats.summarize(pooled(ok, row)))
        entry["reduction_vs_ekf3"] = stats.reduction(entry["median"], ekf_pooled["median"])
        per_flight = [float(np.nanmedian(r.errors_h_m[row])) for r in ok if row in r.errors_h_m
                      and np.isfinite(r.errors_h_m[row]).any()]
        entry["flight_medians"] = per_flight
        if len(seeds) >= 2:
            m = seed_medians(row)
            entry["seed_median"] = float(np.nanmedian(m))
            entry["seed_median_ci95"] = list(stats.bootstrap_ci(m, rng))
            if row != AUTOPILOT_ROW:
                v, lo, hi = stats.paired_reduction_ci(m, ekf_seeds, rng)
                entry["reduction_vs_ekf3_seeds"] = {"value": v, "ci95": [lo, hi]}
        table[row] = entry
    flying = {}
    labels = {"none": "EKF3 on the raw fixes", "gps-input": f"EKF3 on {CLOSED_LOOP_METHOD}'s cleaned fixes"}
    for feed, label in labels.items():
        of_feed = [r for r in results if r.job.feed == feed]
        if not of_feed:
            continue
        good = [r for r in of_feed if usable(r)]
        track = np.concatenate([r.track_error_m for r in good] or [np.zeros(0)])
        flying[feed] = {
            "flies_on": label, "flights": len(of_feed), "valid": len(good),
            "reached_goal": sum(r.reached_goal for r in good),
            "collisions": sum(r.collisions for r in good),
            "tracking_error_m": stats.summarize(track),
            "flight_tracking_medians": [float(np.median(r.track_error_m))
                                        for r in good if r.track_error_m.size],
        }
    return {"open_loop": table, "flying": flying}


def table_text(res: dict[str, Any]) -> str:
    """The Markdown table of the open-loop rows."""
    lines = ["| estimator | horizontal error median [m] | p95 [m] | vs EKF3 | per-seed median [95 % CI] |",
             "| --- | ---: | ---: | ---: | --- |"]
    for row, e in res["open_loop"].items():
        ci = e.get("seed_median_ci95")
        seed = (f"{e['seed_median']:.2f} [{ci[0]:.2f}, {ci[1]:.2f}]" if ci and np.isfinite(ci[0])
                else "n/a (one seed)")
        red = e.get("reduction_vs_ekf3_seeds")
        vs = "—" if row == AUTOPILOT_ROW else f"{100 * e['reduction_vs_ekf3']:+.0f} %"
        if row != AUTOPILOT_ROW and red and np.isfinite(red["ci95"][0]):
            lo, hi = (100 * x for x in red["ci95"])
            vs += f" (seeds {100 * red['value']:+.0f} % [{lo:+.0f}, {hi:+.0f}])"
        lines.append(f"| {row} | {e['median']:.2f} | {e['p95']:.2f} | {vs} | {seed} |")
    lines += ["", "| ArduPilot flies on | flights (valid) | reached goal | collisions "
                  "| tracking median [m] | p95 [m] |",
              "| --- | ---: | ---: | ---: | ---: | ---: |"]
    for f in res["flying"].values():
        trk = f["tracking_error_m"]
        lines.append(f"| {f['flies_on']} | {f['flights']} ({f['valid']}) | {f['reached_goal']} "
                     f"| {f['collisions']} | {trk['median']:.2f} | {trk['p95']:.2f} |")
    return "\n".join(lines) + "\n"


def error_figure(results: Sequence[ApResult], rows: Sequence[str], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = []
    for row in rows:
        x = pooled(results, row)
        data.append(x[np.isfinite(x)])
    fig, ax = plt.subplots(figsize=(7.0, 3.8))
    ax.boxplot(data, whis=(5, 95), showfliers=False)
    ax.set_xticks(range(1, len(rows) + 1), rows, rotation=20, fontsize=8)
    ax.set_ylabel("horizontal estimation error [m]")
    ax.set_title("ArduCopter SITL on our urban GNSS: EKF3 vs the companion (open loop; whiskers p5-p95)",
                 fontsize=9)
    ax.grid(alpha=0.25, axis="y")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def evaluate(mission: str, profiles: Sequence[int], methods: Sequence[str], seeds: Sequence[int],
             workers: int, out: Path, config: ArduPilotConfig | None = None,
             feeds: Sequence[str] = ("none", "gps-input")) -> dict[str, Any]:
    cfg = config or ArduPilotConfig()
    out.mkdir(parents=True, exist_ok=True)
    flights = out / "flights"
    jobs = [ApJob(mission, p, s, tuple(methods), flights / f"{feed}-profile{p:02d}-seed{s}", cfg, feed)
            for s in seeds for p in profiles for feed in feeds]
    t0 = time.perf_counter()
    results = run(jobs, workers)
    wall_s = time.perf_counter() - t0
    rows = (AUTOPILOT_ROW, *methods)
    res = aggregate(results, rows, seeds)
    res["info"] = {
        "mission": mission, "profiles": list(profiles), "seeds": list(seeds), "methods": list(methods),
        "workers": workers, "wall_s": wall_s, "speedup": cfg.speedup, "gnss_rate_hz": cfg.gnss_rate_hz,
        "flights": [{"profile": r.job.profile, "seed": r.job.seed, "feed": r.job.feed, "valid": r.valid,
                     "command_delay_p95_ms": r.command_delay_p95_ms, "ended_by": r.ended_by,
                     "reached_goal": r.reached_goal, "collisions": r.collisions, "sim_s": r.sim_s,
                     "wall_s": r.wall_s, "error": r.error} for r in results],
    }
    (out / "results.json").write_text(json.dumps(plain_json(res, nan_to_none=True), indent=2) + "\n")
    error_figure(results, rows, out / "errors_horizontal.png")
    (out / "report.md").write_text(table_text(res))
    return res


def with_speedup(cfg: ArduPilotConfig, speedup: float | None) -> ArduPilotConfig:
    return cfg if speedup is None else replace(cfg, speedup=speedup)
