"""The NLOS probe: known-answer statistics, and its twin reproduces the offsets a flight's fixes carried."""

import numpy as np
import pytest

from gcs_tools.evaluate import campaign
from gcs_tools.evaluate.nlos_probe import main, nlos_stats


def test_stats_of_a_known_offset_series():
    t = np.arange(0.0, 10.0, 0.05)  # 200 fixes at 20 Hz
    off = np.zeros((200, 3))
    off[40:140, 0] = 0.8  # one episode of 5 s: a 0.8 m step north and back
    off[60:80, 1] = 0.3  # a 0.3 m east step inside it
    s = nlos_stats(t, off)
    assert s["mean_h_m"] == pytest.approx((80 * 0.8 + 20 * np.hypot(0.8, 0.3)) / 200)
    assert s["fraction_above_0_5_m"] == pytest.approx(0.5)
    assert s["steps_above_0_5_m"] == 2 and s["median_step_m"] == pytest.approx(0.55)  # 0.8, 0.3, 0.3, 0.8
    assert s["takeoff_h_m"] == 0.0 and s["duration_s"] == pytest.approx(9.95)
    assert 0.5 < s["correlation_time_s"] < 5.0
    assert np.isnan(nlos_stats(t, np.zeros((200, 3)))["correlation_time_s"])


def test_twin_reproduces_the_offsets_of_the_flight(monkeypatch):
    from simvehicle import SimVehicle
    from simvehicle.harness.fly import fly
    from simvehicle.nlos import UnmodelledGnss

    seen = []
    step = UnmodelledGnss.step

    def spy(self, p_ned_m):
        u = step(self, p_ned_m)
        seen.append(u.offset_ned_m)
        return u

    m = campaign.mission("test", (), "mismatch")
    monkeypatch.setattr(UnmodelledGnss, "step", spy)
    series = fly(m, 1, "fixed-beta", 3, max_duration_s=20.0).series
    monkeypatch.setattr(UnmodelledGnss, "step", step)
    twin = SimVehicle(m, 1, 3).gnss.unmodelled
    replay = np.array([twin.step(x).offset_ned_m for x in series["p_true_ned_m"]])
    assert len(seen) == len(replay) and np.array_equal(np.array(seen), replay)
    assert np.abs(replay).max() > 0.1  # the test city blocks satellites on this profile


def test_cli_prints_one_record_per_flight(capsys):
    assert main(["--mission", "test", "--profiles", "1", "--seeds", "1"]) == 0
    import json

    rows = json.loads(capsys.readouterr().out)
    assert [(r["profile"], r["seed"]) for r in rows] == [(0, 1)] and rows[0]["duration_s"] > 0


@pytest.mark.parametrize("args, message", [
    (["--profiles", "x"], "--profiles: expected a count or a range, got 'x'"),
    (["--profiles", "0-99"], "--profiles"),
    (["--seeds", "3-1"], "--seeds: expected e.g. 0-49"),
    (["--mission", "atlantis"], "atlantis"),
])
def test_cli_bad_arguments_are_one_line_errors(args, message, capsys):
    assert main([*args]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and message in captured.err and captured.err.count("\n") == 1
