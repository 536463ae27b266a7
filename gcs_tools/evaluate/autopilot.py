"""``beliefnav evaluate --vehicle ardupilot|px4``: a foreign autopilot's EKF beside the companion's
methods over profiles and seeds (the vehicle's specifics: ``gcs_tools.evaluate.ardupilot``,
``gcs_tools.evaluate.px4``).

Each (profile, seed, loop) is one SITL flight (``beliefnav sitl --vehicle V``) on its own instance,
``--workers`` at a time. Every companion method is run on that flight's recorded IMU, attitude and
GNSS, so all rows share the same fixes. Statistics: pooled 20-50 Hz samples per row; with two or
more seeds, the median of per-seed medians with a percentile-bootstrap 95 % CI over seeds and the
reduction against the autopilot's EKF with its paired bootstrap CI. Errors are HORIZONTAL (the
EKFs hold height on their own references; 3-D figures are in each flight's summary).

Loops (``--feeds``), each the same profiles and seeds flown again: open loops (the autopilot flies
on its EKF fed our raw fixes, with or without a Doppler velocity; a loop without velocity keeps
only its EKF row, named by the loop) and closed loops (the autopilot flies on the companion
PROCESS's feed; row ``companion-live`` = what it sent). Closed loops are compared on tracking
error, collisions, goals reached and the estimate the autopilot flew on. Flights whose commands
reached the autopilot late (the machine's scheduler, ``valid`` False) are listed but left out of
the statistics.

Ctrl-C: every worker stops its SITL and companion and skips its remaining flights; the run ends
within seconds with "interrupted" (exit 130).
"""

from __future__ import annotations

import functools
import json
import os
import shutil
import signal
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from types import FrameType
from typing import Any

import numpy as np

from companion.estimator.methods import DEFAULT_METHOD
from companion.tight import WEIGHTINGS
from gcs_tools.evaluate import stats
from gcs_tools.jsonvalues import plain_json
from simvehicle.harness.foreign.analysis import LIVE_ROW, SPP_ROW, TIGHT_PREFIX

BOOTSTRAP_SEED = 20240917
CLOSED_LOOP_METHOD = DEFAULT_METHOD  # the closed loop's companion (the raw receiver: the tight weighting)
RAW_ROWS = (SPP_ROW, *(f"{TIGHT_PREFIX}{w}" for w in WEIGHTINGS))  # the canyon receiver's fixes, tight rows
SERIES_FILE = "errors_horizontal.csv"  # per flight: what its Result needs, at full precision (--resume)
_interrupted = False  # a worker that got Ctrl-C flies nothing more


@dataclass(frozen=True)
class Loop:
    """One way of flying the campaign's profiles."""

    name: str  # --feeds value
    label: str  # what the autopilot flies on (report)
    feed: str  # the backend's feed: "none" = open loop
    gnss_velocity: bool = True  # the raw fixes carry a Doppler velocity (open loop)
    ekf_row: str = ""  # the autopilot EKF's row in this loop ("" = the vehicle's autopilot_row)

    @property
    def open(self) -> bool:
        return self.feed == "none"


def open_loops(ekf: str, posonly_row: str) -> tuple[Loop, Loop]:
    """The two open loops every autopilot flies: its EKF on our raw fixes with a Doppler velocity
    (``none``), and without (``none-posonly``: only its EKF row is kept, as ``posonly_row``)."""
    return (Loop("none", f"{ekf} on the raw fixes (+ Doppler velocity)", "none"),
            Loop("none-posonly", f"{ekf} on the raw fixes, position only", "none", gnss_velocity=False,
                 ekf_row=posonly_row))


@dataclass(frozen=True)
class VehicleCampaign:
    """A foreign autopilot's campaign: its backend, its EKF's row and the loops it flies."""

    vehicle: str  # backend name (simvehicle.harness.backend.BACKENDS)
    title: str  # "ArduPilot", "PX4"
    ekf: str  # "EKF3", "EKF2"
    autopilot_row: str  # "ardupilot-ekf3"
    loops: tuple[Loop, ...]
    figure_title: str
    config_class: Callable[..., Any]  # the backend's flight configuration (ArduPilotConfig, Px4FlightConfig)
    speed_field: str  # its speed-up field (speedup, speed_factor)
    # --resume of a flight recorded without the series file: "module:function" scoring its recording
    # again, (out_dir, mission, methods, config, scenario) -> FlightResult ("": it is flown again)
    rescorer: str = ""

    def config(self, speed: float | None = None) -> Any:
        """The flight configuration, at this speed-up (None: its default)."""
        return self.config_class() if speed is None else self.config_class(**{self.speed_field: speed})

    @property
    def reduction_key(self) -> str:
        return f"reduction_vs_{self.ekf.lower()}"

    def rescore(self, job: Job) -> Any:
        """``job``'s flight scored again from its recording by ``rescorer`` (None: no rescorer)."""
        if not self.rescorer:
            return None
        import importlib

        module, name = self.rescorer.split(":")
        config = replace(job.config, gnss_velocity=self.loop(job.loop).gnss_velocity)
        return getattr(importlib.import_module(module), name)(job.out_dir, job.mission, job.methods, config,
                                                               job.scenario)

    def loop(self, name: str) -> Loop:
        return next(lp for lp in self.loops if lp.name == name)

    @property
    def loop_names(self) -> tuple[str, ...]:
        return tuple(lp.name for lp in self.loops)

    @property
    def rows(self) -> tuple[str, ...]:
        """The EKF rows, the vehicle's own first."""
        return (self.autopilot_row, *dict.fromkeys(lp.ekf_row for lp in self.loops if lp.ekf_row))


@dataclass(frozen=True)
class Job:
    campaign: VehicleCampaign
    mission: str
    profile: int
    seed: int
    methods: tuple[str, ...]
    out_dir: Path
    config: Any  # the backend's flight configuration (ArduPilotConfig, Px4FlightConfig)
    loop: str = "none"  # one of campaign.loops
    scenario: str | None = None  # sensor scenario (None: the mission's): paper or canyon

    @property
    def feed(self) -> str:
        return self.campaign.loop(self.loop).feed


@dataclass(frozen=True)
class Result:
    job: Job
    errors_h_m: dict[str, np.ndarray]  # row -> horizontal error per sample (route phase)
    track_error_m: np.ndarray
    reached_goal: bool
    collisions: int
    ended_by: str
    sim_s: float
    wall_s: float
    error: str = ""  # a flight that could not be flown (its rows are absent, the reason kept)
    valid: bool = True  # False: our commands reached the autopilot late, left out of the statistics
    command_delay_p95_ms: float = float("nan")
    read_back: bool = False  # --resume: read from its directory, not flown in this run

    @property
    def flown_on(self) -> np.ndarray:
        """Horizontal error of the estimate the autopilot flew on (its EKF in every loop)."""
        loop = self.job.campaign.loop(self.job.loop)
        return self.errors_h_m.get(loop.ekf_row or self.job.campaign.autopilot_row, np.zeros(0))


def run_job(job: Job, resume: bool = False) -> Result:
    """Fly one job (``resume``: read its flight back if its directory holds a complete one; an
    incomplete directory is cleared and flown again)."""
    from companion.errors import UserError
    from gcs_tools.fly.output import strict_json, write_outputs
    from simvehicle.harness.backend import FlightRequest, backend

    if _interrupted:
        return Result(job, {}, np.zeros(0), False, 0, "interrupted", 0.0, 0.0, "interrupted")
    if resume:
        done = read_back(job)
        if done is not None:
            return done
        shutil.rmtree(job.out_dir, ignore_errors=True)
    spec, loop = job.campaign, job.campaign.loop(job.loop)
    cfg = replace(job.config, gnss_velocity=loop.gnss_velocity)
    vehicle = backend(spec.vehicle, config=cfg, methods=job.methods, feed=loop.feed)
    try:
        r = vehicle.fly(FlightRequest(job.mission, job.profile, CLOSED_LOOP_METHOD, job.seed, job.out_dir,
                                      scenario=job.scenario))
    except UserError as exc:
        return Result(job, {}, np.zeros(0), False, 0, "error", 0.0, 0.0, str(exc))
    job.out_dir.mkdir(parents=True, exist_ok=True)
    if r.series:
        from companion.mission import load_mission

        write_outputs(r, load_mission(job.mission).world, job.out_dir)
    else:  # no route phase (e.g. a set-up time-out): the summary says how it ended
        (job.out_dir / "summary.json").write_text(json.dumps(strict_json(r.summary), indent=2) + "\n")
    write_series(job.out_dir / SERIES_FILE, r.series)  # last: its presence marks a complete flight
    return flight_result(job, r.summary, r.series)


def flight_result(job: Job, summary: dict[str, Any], series: dict[str, Any]) -> Result:
    """The campaign's view of one flight: its summary (as flown, or read back from summary.json)
    and its series (every row's horizontal error and the tracking error)."""
    from simvehicle.harness.foreign.scoring import HORIZONTAL_ERROR_PREFIX

    spec, loop = job.campaign, job.campaign.loop(job.loop)
    errs = {k[len(HORIZONTAL_ERROR_PREFIX):]: np.asarray(v) for k, v in series.items()
            if k.startswith(HORIZONTAL_ERROR_PREFIX)}
    if loop.ekf_row:  # the companion rows are those of the loop with velocity
        errs = {loop.ekf_row: errs[spec.autopilot_row]} if spec.autopilot_row in errs else {}
    run = summary[spec.vehicle]
    p95 = run["command_delay_ms"]["p95"]
    return Result(job, errs, np.asarray(series.get("track_error_m", np.zeros(0))),
                  # a flight recorded before reached_goal meant "without a contact" is read back by it
                  bool(summary["reached_goal"]) and int(summary["collisions"]) == 0,
                  int(summary["collisions"]), str(run["ended_by"]),
                  float(run["sim_s"]), float(run["wall_s"]), valid=bool(summary["valid"]),
                  command_delay_p95_ms=float("nan") if p95 is None else float(p95))


def write_series(path: Path, series: dict[str, Any]) -> None:
    """The series a Result needs (``track_error_m`` and every ``est_error_h_m:ROW``) as CSV at full
    precision (``%.17g``: read back bit for bit), written to a temporary file and renamed."""
    from simvehicle.harness.foreign.scoring import HORIZONTAL_ERROR_PREFIX

    keys = ["track_error_m", *(k for k in series if k.startswith(HORIZONTAL_ERROR_PREFIX))]
    n = len(series.get("track_error_m", ()))
    data = np.column_stack([np.asarray(series[k], dtype=float).reshape(n) for k in keys]) if n else \
        np.zeros((0, len(keys)))
    tmp = path.with_name(path.name + ".part")
    np.savetxt(tmp, data, delimiter=",", header=",".join(keys), comments="", fmt="%.17g")
    os.replace(tmp, path)


def read_series(path: Path) -> dict[str, np.ndarray]:
    """``write_series``'s file back (OSError/ValueError if it is missing or damaged)."""
    lines = path.read_text().splitlines()
    if not lines or lines[0].split(",")[0] != "track_error_m":
        raise ValueError(f"{path}: not a series file")
    keys = lines[0].split(",")
    data = np.loadtxt(lines[1:], delimiter=",", ndmin=2) if len(lines) > 1 else np.zeros((0, len(keys)))
    if data.shape[1] != len(keys):
        raise ValueError(f"{path}: {data.shape[1]} columns for {len(keys)} names")
    return {k: data[:, i].copy() for i, k in enumerate(keys)}


def read_back(job: Job) -> Result | None:
    """The job's flight from its directory, if complete: ``summary.json`` and the series file (or,
    for a flight recorded before campaigns kept that file, its recording scored again by the
    vehicle's ``rescore`` when that reproduces the summary's per-row statistics exactly). None:
    incomplete, to be flown again. A directory flown for another flight is a UserError."""
    d, spec = job.out_dir, job.campaign
    try:
        summary = json.loads((d / "summary.json").read_text())
    except (OSError, ValueError):
        return None
    check_same_flight(job, summary)
    try:
        series = read_series(d / SERIES_FILE)
    except (OSError, ValueError):
        rescored = spec.rescore(job) if (d / "run.tlog").is_file() else None
        if rescored is None or not same_scores(summary, rescored.summary):
            return None
        series = rescored.series
        write_series(d / SERIES_FILE, series)
    return replace(flight_result(job, summary, series), read_back=True)


def check_same_flight(job: Job, summary: dict[str, Any]) -> None:
    """A UserError if ``summary`` (of ``job``'s directory) is not of ``job``'s flight: mission,
    profile, seed, feed, and every method of ``job`` among its rows."""
    from companion.errors import UserError

    want = {"mission": mission_name(job.mission), "profile": job.profile, "seed": job.seed, "feed": job.feed}
    got = {k: summary.get(k) for k in want}
    if got != want or not set(job.methods) <= set(summary.get("methods", {})):
        rows = sorted(summary.get("methods", {}))
        raise UserError(f"--resume: {job.out_dir} holds another flight ({got}, rows {rows}); resume with the "
                        "options it was flown with, or use another --out")


def check_resumable(jobs: Sequence[Job]) -> None:
    """Before any flight: every job directory with a readable summary is of that job (UserError)."""
    for job in jobs:
        try:
            summary = json.loads((job.out_dir / "summary.json").read_text())
        except (OSError, ValueError):
            continue
        check_same_flight(job, summary)


@functools.lru_cache(maxsize=8)
def mission_name(mission: str) -> str:
    """The name a flight's summary records for ``--mission`` (``default`` -> ``default-city``)."""
    from companion.mission import load_mission

    return str(load_mission(mission).name)


def same_scores(recorded: dict[str, Any], rescored: dict[str, Any]) -> bool:
    """Two summaries of a flight agree on every row's statistics, collisions, goal and tracking (as
    stored: strict JSON numbers)."""
    keys = ("methods", "collisions", "reached_goal", "tracking_error_m")
    return all(plain_json(recorded.get(k), nan_to_none=True) == plain_json(rescored.get(k), nan_to_none=True)
               for k in keys)


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


def run(jobs: Sequence[Job], workers: int, resume: bool = False) -> list[Result]:
    if workers <= 1:
        return [run_job(j, resume) for j in jobs]
    pool = ProcessPoolExecutor(max_workers=workers, initializer=_worker_init)
    futures: list[Any] = []
    try:
        futures = [pool.submit(run_job, j, resume) for j in jobs]
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


def usable(r: Result) -> bool:
    return not r.error and r.valid


def pooled(results: Sequence[Result], row: str) -> np.ndarray:
    """Every horizontal-error sample of ``row`` over the flights that were flown."""
    parts = [r.errors_h_m[row] for r in results if usable(r) and row in r.errors_h_m]
    return np.concatenate(parts) if parts else np.zeros(0)


def aggregate(spec: VehicleCampaign, results: Sequence[Result], rows: Sequence[str],
              seeds: Sequence[int]) -> dict[str, Any]:
    """Per row: pooled horizontal error stats, per-seed CI and the reduction against the EKF."""
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    open_names = {lp.name for lp in spec.loops if lp.open}
    ok = [r for r in results if usable(r) and r.job.loop in open_names]  # open loop: the estimators compared

    def seed_medians(row: str) -> np.ndarray:
        out = []
        for seed in seeds:
            parts = [r.errors_h_m[row] for r in ok if r.job.seed == seed and row in r.errors_h_m]
            x = np.concatenate(parts) if parts else np.zeros(0)
            x = x[np.isfinite(x)]
            out.append(float(np.median(x)) if x.size else float("nan"))
        return np.array(out)

    ref = spec.autopilot_row
    ekf_seeds = seed_medians(ref)
    ekf_pooled = stats.summarize(pooled(ok, ref))
    key = spec.reduction_key
    table: dict[str, Any] = {}
    for row in rows:
        if not any(row in r.errors_h_m for r in ok):
            continue
        entry: dict[str, Any] = dict(stats.summarize(pooled(ok, row)))
        entry[key] = stats.reduction(entry["median"], ekf_pooled["median"])
        per_flight = [float(np.nanmedian(r.errors_h_m[row])) for r in ok if row in r.errors_h_m
                      and np.isfinite(r.errors_h_m[row]).any()]
        entry["flight_medians"] = per_flight
        if len(seeds) >= 2:
            m = seed_medians(row)
            entry["seed_median"] = float(np.nanmedian(m))
            entry["seed_median_ci95"] = list(stats.bootstrap_ci(m, rng))
            if row != ref:
                v, lo, hi = stats.paired_reduction_ci(m, ekf_seeds, rng)
                entry[f"{key}_seeds"] = {"value": v, "ci95": [lo, hi]}
        table[row] = entry
    flying = {}
    for loop in spec.loops:
        of_loop = [r for r in results if r.job.loop == loop.name]
        if not of_loop:
            continue
        good = [r for r in of_loop if usable(r)]
        track = np.concatenate([r.track_error_m for r in good] or [np.zeros(0)])
        flown = np.concatenate([r.flown_on for r in good] or [np.zeros(0)])
        live = np.concatenate([r.errors_h_m.get(LIVE_ROW, np.zeros(0)) for r in good] or [np.zeros(0)])
        flying[loop.name] = {
            "flies_on": loop.label, "flights": len(of_loop), "valid": len(good),
            "invalid_late_commands": sum(not r.valid for r in of_loop if not r.error),
            "errors": sum(bool(r.error) for r in of_loop),
            "reached_goal": sum(r.reached_goal for r in good),  # without a contact
            "arrived": sum(r.ended_by == "reached_goal" for r in good),  # contacts or not
            "collisions": sum(r.collisions for r in good),
            "tracking_error_m": stats.summarize(track),
            "flown_estimate_error_horizontal_m": stats.summarize(flown),  # the EKF's, in every loop
            "companion_sent_error_horizontal_m": stats.summarize(live),  # closed loop: what it sent
            "flight_tracking_medians": [float(np.median(r.track_error_m))
                                        for r in good if r.track_error_m.size],
        }
    return {"open_loop": table, "flying": flying}


def table_text(spec: VehicleCampaign, res: dict[str, Any]) -> str:
    """The Markdown tables: open-loop rows, then how each loop flew."""
    ekf, key = spec.ekf, spec.reduction_key
    lines = [f"| estimator | horizontal error median [m] | p95 [m] | vs {ekf} | per-seed median [95 % CI] |",
             "| --- | ---: | ---: | ---: | --- |"]
    for row, e in res["open_loop"].items():
        ci = e.get("seed_median_ci95")
        seed = (f"{e['seed_median']:.2f} [{ci[0]:.2f}, {ci[1]:.2f}]" if ci and np.isfinite(ci[0])
                else "n/a (one seed)")
        red = e.get(f"{key}_seeds")
        vs = "—" if row == spec.autopilot_row else f"{100 * e[key]:+.0f} %"
        if row != spec.autopilot_row and red and np.isfinite(red["ci95"][0]):
            lo, hi = (100 * x for x in red["ci95"])
            vs += f" (seeds {100 * red['value']:+.0f} % [{lo:+.0f}, {hi:+.0f}])"
        lines.append(f"| {row} | {e['median']:.2f} | {e['p95']:.2f} | {vs} | {seed} |")
    lines += ["", f"| {spec.title} flies on | flights (valid) | reached goal (arrived) | collisions "
                  f"| tracking median [m] | p95 [m] | {ekf} horizontal median [m] | companion sent [m] |",
              "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for f in res["flying"].values():
        trk, fl, cs = (f["tracking_error_m"], f["flown_estimate_error_horizontal_m"],
                       f["companion_sent_error_horizontal_m"])
        sent = f"{cs['median']:.2f}" if cs["n"] else "—"
        lines.append(f"| {f['flies_on']} | {f['flights']} ({f['valid']}) "
                     f"| {f['reached_goal']} ({f['arrived']}) | {f['collisions']} | {trk['median']:.2f} "
                     f"| {trk['p95']:.2f} | {fl['median']:.2f} | {sent} |")
    return "\n".join(lines) + "\n"


def error_figure(spec: VehicleCampaign, results: Sequence[Result], rows: Sequence[str], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = []
    open_names = {lp.name for lp in spec.loops if lp.open}
    ok = [r for r in results if r.job.loop in open_names]
    rows = [row for row in rows if any(row in r.errors_h_m for r in ok)]
    for row in rows:
        x = pooled(ok, row)
        data.append(x[np.isfinite(x)])
    fig, ax = plt.subplots(figsize=(7.0, 3.8))
    ax.boxplot(data, whis=(5, 95), showfliers=False)
    ax.set_xticks(range(1, len(rows) + 1), rows, rotation=20, fontsize=8)
    ax.set_ylabel("horizontal estimation error [m]")
    ax.set_title(spec.figure_title, fontsize=9)
    ax.grid(alpha=0.25, axis="y")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def check_feeds(spec: VehicleCampaign, text: str) -> tuple[str, ...]:
    """``--feeds`` as distinct loop names of ``spec`` (a one-line UserError otherwise)."""
    from companion.errors import UserError

    feeds = tuple(f.strip() for f in text.split(",") if f.strip())
    if not feeds or any(f not in spec.loop_names for f in feeds) or len(set(feeds)) != len(feeds):
        raise UserError(f"--feeds: expected distinct values of {', '.join(spec.loop_names)}, got {text!r}")
    return feeds


def evaluate(spec: VehicleCampaign, mission: str, profiles: Sequence[int], methods: Sequence[str],
             seeds: Sequence[int], workers: int, out: Path, config: Any,
             feeds: Sequence[str] | None = None, scenario: str | None = None,
             resume: bool = False) -> dict[str, Any]:
    """Fly every (seed, profile, loop) into ``out/flights`` and write ``results.json``, ``report.md``
    and the figure. ``resume``: flights already complete there are read back, not flown."""
    out.mkdir(parents=True, exist_ok=True)
    flights = out / "flights"
    loops = tuple(feeds) if feeds is not None else spec.loop_names
    jobs = [Job(spec, mission, p, s, tuple(methods), flights / f"{loop}-profile{p:02d}-seed{s}", config, loop,
                scenario) for s in seeds for p in profiles for loop in loops]
    if resume:
        check_resumable(jobs)
    t0 = time.perf_counter()
    results = run(jobs, workers, resume)
    wall_s = time.perf_counter() - t0
    rows = (*spec.rows, *methods, *RAW_ROWS)  # the raw receiver's rows: scenario canyon only
    res = aggregate(spec, results, rows, seeds)
    res["info"] = {
        "vehicle": spec.vehicle, "mission": mission, "profiles": list(profiles), "seeds": list(seeds),
        "methods": list(methods), "workers": workers,
        "wall_s": wall_s, "read_back": sum(r.read_back for r in results),  # this run's, and how many read
        "config": asdict(config),
        "scenario": scenario,
        "gnss_velocity": ("the receiver's Doppler solution" if scenario == "canyon" else
                          f"truth + N(0, {config.gnss_velocity_sigma_m_s:g} m/s) per axis")
                         + ", in the loops "
                         + ", ".join(lp.name for lp in spec.loops if lp.gnss_velocity and lp.name in loops),
        "flights": [{"profile": r.job.profile, "seed": r.job.seed, "feed": r.job.loop, "valid": r.valid,
                     "command_delay_p95_ms": r.command_delay_p95_ms, "ended_by": r.ended_by,
                     "reached_goal": r.reached_goal, "collisions": r.collisions, "sim_s": r.sim_s,
                     "wall_s": r.wall_s, "error": r.error, "read_back": r.read_back} for r in results],
    }
    (out / "results.json").write_text(json.dumps(plain_json(res, nan_to_none=True), indent=2) + "\n")
    error_figure(spec, results, rows, out / "errors_horizontal.png")
    (out / "report.md").write_text(table_text(spec, res))
    return res
