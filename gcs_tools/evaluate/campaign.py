"""The campaign grid (mission profiles × methods × seeds) on a process pool or a Dask cluster.

Each job flies one in-process flight (``backend("inprocess")``: ``simvehicle.harness.fly``) and
returns a compact ``JobResult``: the flight summary, belief metrics computed at full rate, the 20 Hz error
samples (float32) and 5 Hz belief and trajectory series for the figures — never the full
arrays. Every job is a pure function of its ``Job`` (the seed drives all randomness), so the
local pool and a Dask cluster give identical results for the same grid, returned in grid
order whatever order the jobs finish in.
"""

from __future__ import annotations

import functools
import multiprocessing
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from tqdm import tqdm

from companion.errors import UserError
from gcs_tools.evaluate import stats
from gcs_tools.jsonvalues import plain_json

FIGURE_DECIMATION = 4  # 20 Hz flight series → 5 Hz for belief and trajectory figures


@dataclass(frozen=True)
class Job:
    """One flight of the grid."""

    mission: str  # mission name ("default", "test", "default-tuning") or path to a mission YAML
    profile_index: int
    method: str
    seed: int
    max_duration_s: float | None = None
    overrides: tuple[tuple[str, Any], ...] = ()  # ("estimator.eta", 0.3), see tuning.parse_override
    scenario: str | None = None  # sensor scenario (None: the mission file's)
    label: str = ""  # the results row (an ablation row: a method with its own overrides); "" = method

    @property
    def row(self) -> str:
        return self.label or self.method


@dataclass(frozen=True)
class Row:
    """One results row: an estimator method with its own hyper-parameters (on top of the campaign's)."""

    label: str
    method: str
    overrides: tuple[tuple[str, Any], ...] = ()


@dataclass(frozen=True)
class JobResult:
    """What a job sends back: small enough to ship thousands through a pool."""

    job: Job
    summary: dict[str, Any]  # the flight summary without its wall time (so results compare exactly)
    wall_s: float
    settling_time_s: float
    oscillation_rms: float
    est_error_m: np.ndarray = field(repr=False)  # (N,) float32 at 20 Hz
    track_error_m: np.ndarray = field(repr=False)  # (N,) float32 at 20 Hz
    t_fig_s: np.ndarray = field(repr=False)  # (M,) float32 at 5 Hz
    beta_fig: np.ndarray = field(repr=False)  # (M,)
    p_true_ne_m: np.ndarray = field(repr=False)  # (M, 2)
    p_ref_ne_m: np.ndarray = field(repr=False)  # (M, 2)
    flight: dict[str, float] = field(default_factory=dict)  # per-flight statistics (flight_stats)


JobFn = Callable[[Job], JobResult]


def grid(
    mission: str,
    profiles: Sequence[int],
    methods: Sequence[str],
    seeds: Sequence[int],
    max_duration_s: float | None = None,
    overrides: Sequence[tuple[str, Any]] = (),
    scenario: str | None = None,
) -> list[Job]:
    """Jobs in a fixed order: profile-major, then method, then seed."""
    rows = [Row(m, m) for m in methods]
    return grid_rows(mission, profiles, rows, seeds, max_duration_s, overrides, scenario)


def grid_rows(
    mission: str,
    profiles: Sequence[int],
    rows: Sequence[Row],
    seeds: Sequence[int],
    max_duration_s: float | None = None,
    overrides: Sequence[tuple[str, Any]] = (),
    scenario: str | None = None,
) -> list[Job]:
    """Jobs in a fixed order: profile-major, then row, then seed; a row's overrides follow (win over)
    the campaign's. A row named like its method keeps ``label`` empty (the plain-method grid)."""
    o = tuple(overrides)
    return [
        Job(mission, p, r.method, s, max_duration_s, o + r.overrides, scenario,
            "" if r.label == r.method else r.label)
        for p in profiles for r in rows for s in seeds
    ]


@functools.lru_cache(maxsize=16)
def mission(name: str, overrides: tuple[tuple[str, Any], ...] = (), scenario: str | None = None) -> Any:
    """The mission of a job with its overrides (and sensor scenario), loaded once per process."""
    from companion.mission import with_scenario
    from gcs_tools.evaluate import tuning

    m = tuning.load(name, overrides)
    return m if scenario is None else with_scenario(m, scenario)


def compact(job: Job, summary: dict[str, Any], series: dict[str, np.ndarray]) -> JobResult:
    """Reduce a flight's 20 Hz series to the compact result the campaign keeps."""
    t = np.asarray(series["t_s"], dtype=float)
    beta = np.asarray(series["beta"], dtype=float)
    d = FIGURE_DECIMATION
    return JobResult(
        job=job,
        summary=jsonable({k: v for k, v in summary.items() if k != "wall_s"}),
        wall_s=float(summary.get("wall_s", float("nan"))),
        settling_time_s=stats.settling_time_s(t, beta),
        oscillation_rms=stats.oscillation_rms(t, beta),
        est_error_m=np.asarray(series["est_error_m"], dtype=np.float32),
        track_error_m=np.asarray(series["track_error_m"], dtype=np.float32),
        t_fig_s=t[::d].astype(np.float32),
        beta_fig=beta[::d].astype(np.float32),
        p_true_ne_m=np.asarray(series["p_true_ned_m"])[::d, :2].astype(np.float32),
        p_ref_ne_m=np.asarray(series["p_ref_ned_m"])[::d, :2].astype(np.float32),
        flight=stats.flight_stats(series),
    )


def run_job(job: Job) -> JobResult:
    """Fly one job in this process (the default job function, importable by pool workers)."""
    from simvehicle.harness.backend import FlightRequest, backend

    cpu0 = time.process_time()
    m = mission(job.mission, job.overrides, job.scenario)
    res = backend("inprocess").fly(FlightRequest(m, job.profile_index, job.method, job.seed,
                                                 max_duration_s=job.max_duration_s))
    out = compact(job, res.summary, res.series)
    out.flight["cpu_s"] = time.process_time() - cpu0
    return out


def run(
    jobs: Sequence[Job],
    workers: int = 1,
    scheduler: str | None = None,
    progress: bool = True,
    job_fn: JobFn = run_job,
) -> list[JobResult]:
    """Run every job; results come back in the order of ``jobs``.

    ``scheduler`` (a Dask scheduler address) runs the jobs on that cluster; otherwise
    ``workers`` > 1 uses a local process pool and ``workers == 1`` runs them in this process.
    """
    if workers < 1:
        raise UserError(f"--workers: expected ≥ 1, got {workers}")
    bar = tqdm(total=len(jobs), desc="flights", unit="flight", disable=not progress, leave=False)
    try:
        if scheduler is not None:
            done = _run_dask(jobs, scheduler, job_fn)
        elif workers == 1:
            done = ((i, job_fn(job)) for i, job in enumerate(jobs))
        else:
            done = _run_pool(jobs, workers, job_fn)
        out: list[JobResult | None] = [None] * len(jobs)
        for i, result in done:
            out[i] = result
            bar.update()
    finally:
        bar.close()
    return [r for r in out if r is not None]


def _run_pool(jobs: Sequence[Job], workers: int, job_fn: JobFn) -> Iterator[tuple[int, JobResult]]:
    ctx = multiprocessing.get_context("forkserver")
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
        futures = {pool.submit(job_fn, job): i for i, job in enumerate(jobs)}
        for fut in as_completed(futures):
            yield futures[fut], fut.result()


def _run_dask(jobs: Sequence[Job], address: str, job_fn: JobFn) -> Iterator[tuple[int, JobResult]]:
    from distributed import Client
    from distributed import as_completed as dask_as_completed

    try:
        client = Client(address, timeout="10s")
    except (OSError, TimeoutError) as exc:
        raise UserError(f"--scheduler: cannot connect to Dask scheduler {address!r}: {exc}") from None
    with client:
        futures = client.map(job_fn, list(jobs), pure=False)
        index = {fut.key: i for i, fut in enumerate(futures)}
        for fut in dask_as_completed(futures):
            yield index[fut.key], fut.result()


def jsonable(value: Any) -> Any:
    """Summary dicts may carry numpy scalars/arrays; make them plain JSON values (NaN kept)."""
    return plain_json(value, nan_to_none=False)

