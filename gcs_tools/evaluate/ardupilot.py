"""``beliefnav evaluate --vehicle ardupilot``: EKF3 beside the companion's methods over profiles and seeds.

Each (profile, seed) is one ArduCopter SITL flight in open loop (it flies on EKF3; ``sitl
--vehicle ardupilot``), on its own ``-I`` instance, ``--workers`` at a time. Every companion
method is run on that flight's recorded IMU, attitude and GNSS, so all rows share the same
fixes. Statistics as the simulated campaign's (``aggregate``): pooled 20-50 Hz samples per row;
with two or more seeds, the median of per-seed medians with a percentile-bootstrap 95 % CI over
seeds and the reduction against EKF3 with its paired bootstrap CI. Errors are HORIZONTAL (EKF3
holds height on the barometer, which the companion does not have; 3-D figures are in each
flight's summary).

Loops (``--feeds``), each the same profiles and seeds flown again:

- ``none``: open loop, EKF3 fed our raw fixes WITH a Doppler velocity (truth + 0.1 m/s noise);
- ``none-posonly``: open loop, EKF3 fed positions only; only its EKF3 row is kept
  (``ardupilot-ekf3-posonly``: the companion rows would repeat those of ``none``);
- ``gps-input`` / ``vision``: closed loop, ArduPilot flies on the second-order companion PROCESS
  (its cleaned fixes as GPS1, or its position as ExternalNav); row ``companion-live`` = what it sent.

Closed loops are compared on tracking error, collisions, goals reached and the estimate ArduPilot
flew on. Flights whose commands reached ArduPilot late (the machine's scheduler, ``valid`` False)
are listed but left out of the statistics.

Ctrl-C: every worker stops its SITL and companion and skips its remaining flights; the run ends
within seconds with "interrupted" (exit 130).
"""

from __future__ import annotations

import json
import os
import signal
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path
from types import FrameType
from typing import Any

import numpy as np

from companion.estimator.methods import DEFAULT_METHOD
from gcs_tools.evaluate import stats
from gcs_tools.jsonvalues import plain_json
from simvehicle.harness.ardupilot.analysis import AUTOPILOT_ROW, LIVE_ROW
from simvehicle.harness.ardupilot.config import ArduPilotConfig

BOOTSTRAP_SEED = 20240917
CLOSED_LOOP_METHOD = DEFAULT_METHOD
POSONLY_ROW = "ardupilot-ekf3-posonly"  # EKF3 without the GNSS velocity
LOOPS = ("none", "none-posonly", "gps-input", "vision")
OPEN_LOOPS = ("none", "none-posonly")
LOOP_LABELS = {"none": "EKF3 on the raw fixes (+ Doppler velocity)",
               "none-posonly": "EKF3 on the raw fixes, position only",
               "gps-input": f"EKF3 on {CLOSED_LOOP_METHOD}'s cleaned fixes (GPS_INPUT)",
               "vision": f"EKF3 on {CLOSED_LOOP_METHOD}'s position as ExternalNav"}
_interrupted = False  # a worker that got Ctrl-C flies nothing more


@dataclass(frozen=True)
class ApJob:
    mission: str
    profile: int
    seed: int
    methods: tuple[str, ...]
    out_dir: Path
    config: ArduPilotConfig
    loop: str = "none"  # one of LOOPS

    @property
    def feed(self) -> str:
        return "none" if self.loop in OPEN_LOOPS else self.loop


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

    @property
    def flown_on(self) -> np.ndarray:
        """Horizontal error of the estimate ArduPilot flew on (EKF3 in every loop)."""
        return self.errors_h_m.get(POSONLY_ROW if self.job.loop == "none-posonly" else AUTOPILOT_ROW,
                                   np.zeros(0))


def run_job(job: ApJob) -> ApResult:
    from companion.errors import UserError
    from gcs_tools.fly.output import write_outputs
    from simvehicle.harness.ardupilot.flight import HORIZONTAL_ERROR_PREFIX
    from simvehicle.harness.backend import FlightRequest, backend

    if _interrupted:
        return ApResult(job, {}, np.zeros(0), False, 0, "interrupted", 0.0, 0.0, "interrupted")
    cfg = replace(job.config, gnss_velocity=job.loop != "none-posonly")
    vehicle = backend("ardupilot", config=cfg, methods=job.methods, feed=job.feed)
    try:
        r = vehicle.fly(FlightRequest(job.mission, job.profile, CLOSED_LOOP_METHOD, job.seed, job.out_dir))
    except UserError as exc:
        return ApResult(job, {}, np.zeros(0), False, 0, "error", 0.0, 0.0, str(exc))
    s, series = r.summary, r.series
    if series:
        from companion.mission import load_mission

        write_outputs(r, load_mission(job.mission).world, job.out_dir)
    errs = {k[len(HORIZONTAL_ERROR_PREFIX):]: np.asarray(v) for k, v in series.items()
            if k.startswith(HORIZONTAL_ERROR_PREFIX)}
    if job.loop == "none-posonly":  # the companion rows are those of the "none" loop
        errs = {POSONLY_ROW: errs[AUTOPILOT_ROW]} if AUTOPILOT_ROW in errs else {}
    ap = s["ardupilot"]
    return ApResult(job, errs, np.asarray(series.get("track_error_m", np.zeros(0))), bool(s["reached_goal"]),
                    int(s["collisions"]), str(ap["ended_by"]), float(ap["sim_s"]), float(ap["wall_s"]),
                    valid=bool(s["valid"]), command_delay_p95_ms=float(ap["command_delay_ms"]["p95"]))


def _worker_init() -> None:
    """In each worker: the first Ctrl-C (the terminal's, or the parent's) ends the current flight
    (its SITL and companion are stopped on the way out); later ones are ignored, so that clean-up
    is not cut short, and every remaining flight is skipped."""
    def interrupt(signum: int, frame: FrameType | None) -> None:
        global _interrupted
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        _interrupted = True
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, interrupt)


def run(jobs: Sequence[ApJob], workers: int) -> list[ApResult]:
    if workers <= 1:
        return [run_job(j) for j in jobs]
    pool = ProcessPoolExecutor(max_workers=workers, initializer=_worker_init)
    futures: list[Any] = []
    try:
        futures = [pool.submit(run_job, j) for j in jobs]
        return [f.result() for f in futures]
    except KeyboardInterrupt:
        for f in futures:
            f.cancel()
        for proc in list(getattr(pool, "_processes", {}).values()):  # SIGINT only reached us (kill -INT)
            if proc.is_alive() and proc.pid is not None:
                os.kill(proc.pid, signal.SIGINT)
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def usable(r: ApResult) -> bool:
    return not r.error and r.valid


def pooled(results: Sequence[ApResult], row: str) -> np.ndarray:
    """Every horizontal-error sample of ``row`` over the flights that were flown."""
    parts = [r.errors_h_m[row] for r in results if usable(r) and row in r.errors_h_m]
    return np.concatenate(parts) if parts else np.zeros(0)


def aggregate(results: Sequence[ApResult], rows: Sequence[str], seeds: Sequence[int]) -> dict[str, Any]:
    """Per row: pooled horizontal error stats, per-seed CI and the reduction against EKF3."""
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    ok = [r for r in results if usable(r) and r.job.loop in OPEN_LOOPS]  # open loop: the estimators compared

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
        if not any(row in r.errors_h_m for r in ok):
            continue
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
    for loop, label in LOOP_LABELS.items():
        of_loop = [r for r in results if r.job.loop == loop]
        if not of_loop:
            continue
        good = [r for r in of_loop if usable(r)]
        track = np.concatenate([r.track_error_m for r in good] or [np.zeros(0)])
        flown = np.concatenate([r.flown_on for r in good] or [np.zeros(0)])
        live = np.concatenate([r.errors_h_m.get(LIVE_ROW, np.zeros(0)) for r in good] or [np.zeros(0)])
        flying[loop] = {
            "flies_on": label, "flights": len(of_loop), "valid": len(good),
            "invalid_late_commands": sum(not r.valid for r in of_loop if not r.error),
            "errors": sum(bool(r.error) for r in of_loop),
            "reached_goal": sum(r.reached_goal for r in good),
            "collisions": sum(r.collisions for r in good),
            "tracking_error_m": stats.summarize(track),
            "flown_estimate_error_horizontal_m": stats.summarize(flown),  # EKF3's, in every loop
            "companion_sent_error_horizontal_m": stats.summarize(live),  # closed loop: what it sent
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
                  "| tracking median [m] | p95 [m] | EKF3 horizontal median [m] | companion sent [m] |",
              "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for f in res["flying"].values():
        trk, fl, cs = (f["tracking_error_m"], f["flown_estimate_error_horizontal_m"],
                       f["companion_sent_error_horizontal_m"])
        sent = f"{cs['median']:.2f}" if cs["n"] else "—"
        lines.append(f"| {f['flies_on']} | {f['flights']} ({f['valid']}) | {f['reached_goal']} "
                     f"| {f['collisions']} | {trk['median']:.2f} | {trk['p95']:.2f} | {fl['median']:.2f} "
                     f"| {sent} |")
    return "\n".join(lines) + "\n"


def error_figure(results: Sequence[ApResult], rows: Sequence[str], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = []
    ok = [r for r in results if r.job.loop in OPEN_LOOPS]
    rows = [row for row in rows if any(row in r.errors_h_m for r in ok)]
    for row in rows:
        x = pooled(ok, row)
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
             feeds: Sequence[str] = LOOPS) -> dict[str, Any]:
    cfg = config or ArduPilotConfig()
    out.mkdir(parents=True, exist_ok=True)
    flights = out / "flights"
    jobs = [ApJob(mission, p, s, tuple(methods), flights / f"{loop}-profile{p:02d}-seed{s}", cfg, loop)
            for s in seeds for p in profiles for loop in feeds]
    t0 = time.perf_counter()
    results = run(jobs, workers)
    wall_s = time.perf_counter() - t0
    rows = (AUTOPILOT_ROW, POSONLY_ROW, *methods)
    res = aggregate(results, rows, seeds)
    res["info"] = {
        "mission": mission, "profiles": list(profiles), "seeds": list(seeds), "methods": list(methods),
        "workers": workers, "wall_s": wall_s, "speedup": cfg.speedup, "gnss_rate_hz": cfg.gnss_rate_hz,
        "gnss_velocity": f"truth + N(0, {cfg.gnss_velocity_sigma_m_s:g} m/s) per axis "
                         "(loops none, gps-input, vision); none-posonly: none",
        "flights": [{"profile": r.job.profile, "seed": r.job.seed, "feed": r.job.loop, "valid": r.valid,
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
