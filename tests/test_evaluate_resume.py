"""``beliefnav evaluate --vehicle ardupilot|px4 --resume``: a flight read back from its directory is
the Result it was when flown, bit for bit; incomplete directories are cleared and flown again; a
flight recorded without its series file is taken from the vehicle's re-scoring only when that
reproduces its recorded statistics. The SITL is replaced by a fake backend that returns a flight
with awkward numbers (NaN, 17-digit values) and writes it through the campaign's own writers."""

from __future__ import annotations

import json
import math
from dataclasses import fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from companion.errors import UserError
from companion.mission import load_mission
from gcs_tools.evaluate import autopilot
from gcs_tools.evaluate.autopilot import SERIES_FILE, Job, Result, read_back, run
from gcs_tools.evaluate.px4 import CAMPAIGN
from gcs_tools.fly.output import COLUMNS
from simvehicle.harness.backend import FlightResult
from simvehicle.harness.fly import planned_route
from simvehicle.harness.foreign.scoring import HORIZONTAL_ERROR_PREFIX
from simvehicle.harness.px4.config import Px4FlightConfig

METHODS = ("naive", "second-order")
MISSION = "test"


def fake_flight(job: Job, samples: int = 40) -> FlightResult:
    """What ``fly_px4`` returns, with numbers that a 6-digit CSV would not keep (seeded by the job)."""
    rng = np.random.default_rng([job.seed, job.profile, len(job.loop)])
    closed = not job.campaign.loop(job.loop).open
    rows = (*METHODS, "px4-ekf2", *(["companion-live"] if closed else []))
    series: dict[str, Any] = {}
    if samples:
        for key, cols in COLUMNS.items():
            series[key] = rng.normal(0.0, 30.0, (samples, len(cols))).squeeze()
        series["t_s"] = np.arange(samples) * 0.02
        for row in rows:
            e = rng.exponential(1.3, samples) * (1 + 1e-12 * rng.random(samples))
            e[rng.random(samples) < 0.1] = np.nan  # an EKF with no estimate yet
            series[f"{HORIZONTAL_ERROR_PREFIX}{row}"] = e
        series["track_error_m"] = rng.exponential(2.0, samples) + 0.1
    summary = {"mission": load_mission(MISSION).name, "profile": job.profile, "method": "second-order",
               "seed": job.seed,
               "vehicle": "px4", "feed": job.feed, "reached_goal": bool(samples), "valid": job.seed != 1,
               "collisions": int(rng.integers(0, 5)),
               "methods": {row: {"estimation_error_horizontal_m": {"median": 1.0}} for row in rows},
               "px4": {"ended_by": "reached_goal" if samples else "setup_timeout:climb",
                       "sim_s": float(rng.uniform(50, 150)), "wall_s": float(rng.uniform(20, 80)),
                       "command_delay_ms": {"p95": float(rng.uniform(1, 90)) if samples else math.nan}}}
    return FlightResult(summary, series, planned_route(load_mission(MISSION), job.profile, 0.0))


class FakeVehicle:
    def __init__(self, flown: list[Job], jobs: list[Job]) -> None:
        self.flown, self.jobs = flown, jobs

    def fly(self, request: Any) -> FlightResult:
        job = next(j for j in self.jobs if j.out_dir == request.out_dir)
        self.flown.append(job)
        return fake_flight(job, samples=0 if job.profile == 1 else 40)


@pytest.fixture
def fake_backend(monkeypatch):
    """(jobs, flown): every ``backend(...).fly`` of a job is a fake flight, recorded in ``flown``. The
    flight's figures are not drawn (seconds of matplotlib, not what is tested here)."""
    flown: list[Job] = []
    jobs: list[Job] = []
    monkeypatch.setattr("simvehicle.harness.backend.backend", lambda *a, **k: FakeVehicle(flown, jobs))
    monkeypatch.setattr("gcs_tools.figures.map_figure", lambda *a, **k: None)
    monkeypatch.setattr("gcs_tools.figures.belief_figure", lambda *a, **k: None)
    return jobs, flown


def campaign_jobs(out: Path, spec: Any = CAMPAIGN) -> list[Job]:
    return [Job(spec, MISSION, p, s, METHODS, out / f"{loop}-profile{p:02d}-seed{s}", Px4FlightConfig(), loop)
            for s in (0, 1) for p in (0, 1) for loop in spec.loop_names]


def assert_same(a: Result, b: Result) -> None:
    """Every field equal (arrays bit for bit, NaN where NaN), apart from how the Result was obtained."""
    for f in fields(Result):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if f.name == "read_back":
            continue
        if f.name == "errors_h_m":
            assert list(x) == list(y)
            for row in x:
                assert x[row].dtype == y[row].dtype == np.float64
                assert np.array_equal(x[row], y[row], equal_nan=True), row
        elif isinstance(x, np.ndarray):
            assert np.array_equal(x, y, equal_nan=True) and x.dtype == y.dtype, f.name
        elif isinstance(x, float) and math.isnan(x):
            assert math.isnan(y), f.name
        else:
            assert x == y, f.name


def test_a_flight_read_back_is_the_result_it_was_when_flown(tmp_path, fake_backend):
    jobs, flown = fake_backend
    jobs += campaign_jobs(tmp_path)
    first = run(jobs, workers=1)
    assert len(flown) == len(jobs) and not any(r.read_back for r in first)
    assert first[0].errors_h_m["naive"].size == 40 and np.isnan(first[0].errors_h_m["naive"]).any()
    assert list(first[1].errors_h_m) == ["px4-ekf2-posonly"]  # the position-only loop keeps its EKF row
    assert "companion-live" in first[2].errors_h_m
    assert first[3].errors_h_m == {} and first[3].ended_by == "setup_timeout:climb"  # no route phase
    again = run(jobs, workers=1, resume=True)
    assert len(flown) == len(jobs)  # nothing flown again
    assert all(r.read_back for r in again)
    for a, b in zip(first, again, strict=True):
        assert_same(a, b)
    # the campaign's statistics are those of the flights as flown
    rows = ("px4-ekf2", "px4-ekf2-posonly", *METHODS)
    assert json.dumps(autopilot.aggregate(CAMPAIGN, again, rows, (0, 1))) == \
        json.dumps(autopilot.aggregate(CAMPAIGN, first, rows, (0, 1)))


def test_incomplete_flights_are_cleared_and_flown_again(tmp_path, fake_backend):
    jobs, flown = fake_backend
    jobs += campaign_jobs(tmp_path)[:4]
    first = run(jobs, workers=1)
    (jobs[0].out_dir / SERIES_FILE).unlink()  # stopped before its series were written
    text = (jobs[1].out_dir / SERIES_FILE).read_text()
    (jobs[1].out_dir / SERIES_FILE).write_text(text[: len(text) // 2])  # cut short mid-line
    (jobs[2].out_dir / "summary.json").unlink()  # Ctrl-C during the flight: only its logs
    (jobs[2].out_dir / "run.tlog").write_bytes(b"partial")
    flown.clear()
    again = run(jobs, workers=1, resume=True)
    assert flown == jobs[:3] and [r.read_back for r in again] == [False, False, False, True]
    assert not (jobs[2].out_dir / "run.tlog").exists()  # cleared before it was flown again
    for a, b in zip(first, again, strict=True):
        assert_same(a, b)  # the fake flies the same flight again


def test_resume_refuses_a_directory_of_another_flight(tmp_path, fake_backend):
    jobs, _ = fake_backend
    jobs += campaign_jobs(tmp_path)[:1]
    run(jobs, workers=1)
    other = replace(jobs[0], seed=7)
    with pytest.raises(UserError, match="holds another flight"):
        read_back(other)
    with pytest.raises(UserError, match="holds another flight"):  # checked before anything flies
        autopilot.check_resumable([replace(jobs[0], out_dir=tmp_path / "none"), other])
    with pytest.raises(UserError, match="holds another flight"):
        read_back(replace(jobs[0], methods=(*METHODS, "adaptive")))  # a row it was not scored with


RESCORED: list[Path] = []  # the flights fake_rescore was asked for
DRIFT = {"m": 0.0}  # what it changes in a row's recorded median (0: it reproduces the flight)


def fake_rescore(out_dir: Path, mission: str, methods: tuple[str, ...], config: Any,
                 scenario: str | None) -> FlightResult:
    """A vehicle's rescorer (``VehicleCampaign.rescorer``): the fake flight's series again, with
    the summary as recorded (or with one median moved by ``DRIFT``, as a changed estimator would)."""
    RESCORED.append(out_dir)
    summary = json.loads((out_dir / "summary.json").read_text())
    summary["methods"]["naive"]["estimation_error_horizontal_m"]["median"] += DRIFT["m"]
    job = Job(CAMPAIGN, mission, int(summary["profile"]), int(summary["seed"]), methods, out_dir, config)
    r = fake_flight(job)
    return FlightResult(summary, r.series, r.route)


def test_a_flight_without_its_series_is_rescored_only_when_that_reproduces_it(tmp_path, fake_backend,
                                                                               monkeypatch):
    jobs, _ = fake_backend
    plain = campaign_jobs(tmp_path)[0]
    jobs.append(plain)
    flown_result = run(jobs, workers=1)[0]
    (plain.out_dir / SERIES_FILE).unlink()
    job = replace(plain, campaign=replace(CAMPAIGN, rescorer=f"{__name__}:fake_rescore"))
    RESCORED.clear()
    assert read_back(job) is None and RESCORED == []  # no tlog: nothing to score again
    (plain.out_dir / "run.tlog").write_bytes(b"recorded")
    monkeypatch.setitem(DRIFT, "m", 1e-9)
    assert read_back(job) is None and [plain.out_dir] == RESCORED  # the code changed since: fly it again
    assert not (plain.out_dir / SERIES_FILE).exists()
    monkeypatch.setitem(DRIFT, "m", 0.0)
    got = read_back(job)
    assert got is not None and got.read_back
    assert_same(replace(got, job=plain), flown_result)
    assert (plain.out_dir / SERIES_FILE).exists()  # kept: read directly next time
    RESCORED.clear()
    assert read_back(job) is not None and RESCORED == []


@pytest.mark.parametrize("collisions, reached", [(0, True), (2, False)])
def test_a_flight_recorded_as_arrived_after_contacts_is_not_a_goal_reached(tmp_path, collisions, reached):
    """Flights recorded before reached_goal meant "without a contact" said True after contacts; read
    back, such a flight counts as arrived (ended_by) but not as a goal reached."""
    job = campaign_jobs(tmp_path)[0]
    flight = fake_flight(job)
    summary = {**flight.summary, "reached_goal": True, "collisions": collisions}
    r = autopilot.flight_result(job, summary, flight.series)
    assert r.reached_goal is reached and r.ended_by == "reached_goal" and r.collisions == collisions
    res = autopilot.aggregate(CAMPAIGN, [r], ("px4-ekf2",), (job.seed,))
    assert res["flying"][job.loop]["reached_goal"] == int(reached) and res["flying"][job.loop]["arrived"] == 1
