"""``beliefnav fly``: a real in-process flight on the test city (vehicle, planner, estimator)."""

import csv
import json

import numpy as np
import pytest

from companion.errors import UserError
from companion.mission import load_mission
from gcs_tools.cli import main
from gcs_tools.fly.output import COLUMNS, OPTIONAL_COLUMNS
from simvehicle.harness.fly import fly

TEST_CITY = load_mission("test")


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    out = tmp_path_factory.mktemp("fly")
    rc = main(["fly", "--mission", "test", "--profile", "2", "--method", "second-order", "--seed", "1",
               "--out", str(out)])
    assert rc == 0
    return out


def test_short_flight_reaches_the_goal_and_writes_every_file(flight):
    summary = json.loads((flight / "summary.json").read_text())  # strict JSON (no NaN)
    assert summary["reached_goal"] is True and summary["collisions"] == 0
    assert summary["duration_s"] >= summary["route_duration_s"]
    for key in ("estimation_error_m", "tracking_error_m"):
        stats = summary[key]
        assert 0 < stats["median"] <= stats["p95"] and stats["rmse"] > 0
        assert stats["median"] < 2.0  # the estimator really closes the loop (GNSS bias std <= 1.2 m)
    g = summary["gnss"]
    assert g["sent"] == round(summary["duration_s"] * 20) and 0.9 * g["sent"] <= g["fused"] <= g["sent"]
    assert summary["min_clearance_m"] > 0.3
    with open(flight / "timeseries.csv", newline="") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == [c for cols in COLUMNS.values() for c in cols] + OPTIONAL_COLUMNS["q_true_ned_frd"]
    assert len(rows) - 1 == g["sent"]  # one row per control period
    # gnss.csv: every fix the filter received (those still in the receiver's latency at the end are not)
    fixes = np.genfromtxt(flight / "gnss.csv", delimiter=",", names=True)
    assert len(fixes) == g["fused"] + g["rejected"] and (np.diff(fixes["t_s"]) >= 0).all()
    assert (fixes["t_validity_s"] <= fixes["t_s"]).all()  # a fix arrives once it was valid
    for name in ("map.png", "belief.png"):
        assert (flight / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_without_figures_the_same_files_but_the_figures_and_stale_ones_removed(tmp_path):
    """``write_outputs(..., figures=False)`` (``beliefnav sitl --no-figures``): summary.json, timeseries.csv
    and gnss.csv as with figures; no map.png or belief.png, and a previous run's are removed."""
    from gcs_tools.fly.output import write_outputs

    res = fly(TEST_CITY, 2, "second-order", 0, max_duration_s=2.0)
    stale = tmp_path / "map.png"
    stale.write_bytes(b"old")
    paths = write_outputs(res, TEST_CITY.world, tmp_path, figures=False)
    assert [p.name for p in paths] == ["summary.json", "timeseries.csv", "gnss.csv"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["gnss.csv", "summary.json", "timeseries.csv"]


def test_rejected_fixes_add_up_to_the_gate_counter():
    """Each fix carries whether the innovation gate refused it (what map.png and belief.png mark):
    they add up to the navigator's counter (this flight has one)."""
    from companion.mission import with_scenario

    res = fly(with_scenario(TEST_CITY, "mismatch"), 0, "second-order", 0)
    n = res.summary["estimator_counters"]["gnss_rejected_innovation"]
    assert n >= 1 and res.fixes["rejected"].sum() == n
    assert len(res.fixes["t_s"]) == res.summary["gnss"]["fused"] + res.summary["gnss"]["rejected"]


def test_same_seed_same_flight_bit_for_bit_and_seeds_differ():
    a, b, c = (fly(TEST_CITY, 0, "second-order", s, max_duration_s=8.0) for s in (4, 4, 5))
    for key in a.series:
        np.testing.assert_array_equal(a.series[key], b.series[key], err_msg=key)
    assert {k: v for k, v in a.summary.items() if k != "wall_s"} == {
        k: v for k, v in b.summary.items() if k != "wall_s"
    }
    assert not np.array_equal(a.series["p_true_ned_m"], c.series["p_true_ned_m"])
    assert a.summary["duration_s"] == pytest.approx(8.0) and a.summary["reached_goal"] is False


def test_bad_arguments_give_one_line_errors(tmp_path, capsys):
    with pytest.raises(UserError, match="method 'magic'"):
        fly(TEST_CITY, 0, "magic", 0)
    assert main(["fly", "--mission", str(tmp_path / "nope.yaml"), "--out", str(tmp_path)]) == 2
    assert main(["fly", "--mission", "test", "--profile", "9", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(line.startswith("beliefnav: error: ") for line in err)
    assert "nope.yaml" in err[0] and "profile" in err[1]


def test_routes_are_planned_once_per_mission_object_and_profile():
    from companion.planning import plan_route
    from simvehicle.harness.fly import planned_route

    a = planned_route(TEST_CITY, 1, 2.0)
    assert planned_route(TEST_CITY, 1, 2.0) is a
    other = load_mission("test")  # an equal but distinct mission object plans its own
    b = planned_route(other, 1, 2.0)
    assert b is not a
    np.testing.assert_array_equal(b.waypoints_ned_m, plan_route(TEST_CITY, 1, t_start_s=2.0).waypoints_ned_m)
    assert planned_route(TEST_CITY, 1, 3.0).t_start_s == 3.0


def test_fixes_carry_the_accuracy_the_receiver_reports(monkeypatch):
    """fly hands each fix to the filter with the h_acc/v_acc the simulated receiver puts on the wire
    (its white-noise std in force; NaN when the mission's GNSS reports none), as SITL does; a receiver
    with a Doppler velocity (gnss.velocity) hands it over with its speed accuracy."""
    from companion.estimator import Navigator
    from gcs_tools.evaluate.tuning import with_overrides
    from simvehicle.gnss import GnssModel

    made, pushed = {}, []
    sample, push = GnssModel.sample, Navigator.push_fix_ned

    def spy_sample(self, t_validity_us, *a):
        fix = sample(self, t_validity_us, *a)
        made[fix.t_validity_us] = fix.sigma_noise_m
        return fix

    def spy_push(self, t_validity_us, p_ned_m, h_acc_m=np.nan, v_acc_m=np.nan, v_ned_m_s=None,
                 vel_acc_m_s=np.nan):
        pushed.append((t_validity_us, h_acc_m, v_acc_m, v_ned_m_s, vel_acc_m_s))
        return push(self, t_validity_us, p_ned_m, h_acc_m, v_acc_m, v_ned_m_s, vel_acc_m_s)

    monkeypatch.setattr(GnssModel, "sample", spy_sample)
    monkeypatch.setattr(Navigator, "push_fix_ned", spy_push)
    noisy = with_overrides(TEST_CITY, [("gnss.sigma_noise_m", 0.25)])  # not the filter's configured 0.08
    fly(noisy, 0, "second-order", 4, max_duration_s=3.0)
    assert len(pushed) > 40 and all(h == v == made[t] >= 0.25 and vel is None for t, h, v, vel, _ in pushed)
    pushed.clear()
    silent = with_overrides(TEST_CITY, [("gnss.report_accuracy", False)])
    fly(silent, 0, "second-order", 4, max_duration_s=3.0)
    assert pushed and all(np.isnan(h) and np.isnan(v) for _, h, v, _, _ in pushed)
    pushed.clear()
    doppler = with_overrides(TEST_CITY, [("gnss.velocity", True)])
    fly(doppler, 0, "second-order", 4, max_duration_s=3.0)
    assert pushed and all(vel is not None and np.isfinite(vel).all() and sv >= 0.05 for *_, vel, sv in pushed)
