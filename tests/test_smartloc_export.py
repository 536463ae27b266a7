"""The smartLoc writer (the reader's inverse) and the simulator's flights exported as smartLoc drives,
through ``evaluate.tight`` end to end (a short flight: seconds)."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import pytest

from companion.gnss import SppConfig, System
from companion.gnss.observations import make_epoch
from gcs_tools.evaluate import smartloc_export as sx
from gcs_tools.gnss import baseline, smartloc

SMARTLOC = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "urban" / "smartloc"
if not SMARTLOC.is_dir() and os.environ.get("BELIEFNAV_SHARED"):
    SMARTLOC = Path(os.environ["BELIEFNAV_SHARED"]) / "data" / "urban" / "smartloc"


def _epoch(t: float, pr0: float) -> object:
    return make_epoch(t, [System.GPS, System.GLONASS, System.GALILEO], [12, 20, 3],
                      [pr0, pr0 + 1234.5678901, pr0 - 0.125],
                      pseudorange_var_m2=[25.0, 0.1024, 121.0],
                      sat_pos_ecef_m=[[14567933.924248, 2809850.9686675, 21875628.068424],
                                      [18145814.939546, 11532054.185286, 13684003.65378],
                                      [-5941116.7502364, -9510788.700834, 22950281.255622]],
                      elevation_deg=[85.146780644512, 58.0, 17.773620523915], cn0_dbhz=[49.0, 40.0, 28.0],
                      corrected=True, time_base="dataset")


def test_write_then_read_gives_the_same_epochs_odometry_and_truth(tmp_path):
    epochs = [_epoch(0.0, 19949087.65382), _epoch(0.2, 19949090.12345678)]
    odo = np.array([[0.0, 5.85, -0.0059341194567807], [0.2, 6.0777777777778, 0.016929693744345]])
    inp, gt = tmp_path / "X_Input.txt", tmp_path / "X_GT.txt"
    smartloc.write_input(inp, epochs, odo)
    t_gt = np.array([0.0, 0.2, 0.4])
    steps = np.array([[0, 0, 0], [1.5, -2.25, 3.0], [3.0, -4.5, 6.0]])
    p_gt = np.array([3785108.1107158, 899901.49390314, 5037234.4571748]) + steps
    smartloc.write_truth(gt, t_gt, p_gt)
    lines = inp.read_text().splitlines()
    # the data set's layout: odometry rows first, GLONASS as 300 + slot, system codes 1 / 4 / 8
    assert lines[0] == ("odom3 0 5.85 0 0 0 0 -0.0059341194567807 0.0025 0.0009 0.0009 4e-06 4e-06 4e-06")
    assert lines[2].split()[:4] == ["pseudorange3", "0", "19949087.65382", "25"]
    assert [ln.split()[7:9] for ln in lines[2:5]] == [["12", "1"], ["320", "4"], ["3", "8"]]
    data, truth = smartloc.read_drive(inp)  # the *_GT.txt beside it
    assert data.rows == 8 and not data.rejected
    assert len(data.epochs) == 2
    for a, b in zip(data.epochs, epochs, strict=True):
        assert a.t_gps_s == b.t_gps_s and a.time_base == "dataset" and a.corrected
        np.testing.assert_array_equal(a.system, b.system)
        np.testing.assert_array_equal(a.prn, b.prn)  # GLONASS slot 20 back from id 320
        for f in ("pseudorange_m", "pseudorange_var_m2", "sat_pos_ecef_m", "elevation_deg", "cn0_dbhz"):
            np.testing.assert_allclose(getattr(a, f), getattr(b, f), rtol=1e-14, atol=0, err_msg=f)
    np.testing.assert_allclose(data.odometry, odo, rtol=1e-14)
    np.testing.assert_allclose(truth.t_s, t_gt, rtol=1e-14)
    np.testing.assert_allclose(truth.p_ecef_m, p_gt, rtol=1e-14)
    with pytest.raises(ValueError, match="corrected"):
        smartloc.write_input(inp, [epochs[0].replace(corrected=False)], odo)


@pytest.mark.skipif(not SMARTLOC.is_dir(), reason="smartLoc data set not beside the repository")
def test_berlin_round_trips_through_the_writer(tmp_path):
    data, truth = smartloc.read_drive(SMARTLOC / "Berlin_Potsdamer_Platz_Input.txt")
    smartloc.write_input(tmp_path / "B_Input.txt", data.epochs, data.odometry)
    smartloc.write_truth(tmp_path / "B_GT.txt", truth.t_s, truth.p_ecef_m)
    again, truth2 = smartloc.read_drive(tmp_path / "B_Input.txt")
    assert again.rows == data.rows and len(again.epochs) == len(data.epochs) == 1372
    pr = np.concatenate([e.pseudorange_m for e in again.epochs])
    np.testing.assert_allclose(pr, np.concatenate([e.pseudorange_m for e in data.epochs]), rtol=1e-14)
    np.testing.assert_array_equal(np.concatenate([e.prn for e in again.epochs]),
                                  np.concatenate([e.prn for e in data.epochs]))
    np.testing.assert_allclose(again.odometry, data.odometry, rtol=1e-14)
    np.testing.assert_allclose(truth2.p_ecef_m, truth.p_ecef_m, rtol=1e-14)


def test_course_odometry_of_a_circle_and_a_stop():
    # a circle flown clockwise seen from above at 4 m/s, 0.1 rad/s: course rate +0.1 (NED), smartLoc's yaw
    # rate (counter-clockwise) −0.1
    t = np.arange(0.0, 20.0, 0.2)
    v = np.column_stack([4 * np.cos(0.1 * t), 4 * np.sin(0.1 * t), np.zeros_like(t)])
    o = sx.course_odometry(t, v)
    np.testing.assert_allclose(o[:, 1], 4.0, atol=1e-12)
    np.testing.assert_allclose(o[:, 2], -0.1, atol=1e-3)
    # north, a stop, then east: the quarter turn is spread over the stop and integrates to −π/2
    t = np.arange(0.0, 10.0, 0.2)
    v = np.zeros((len(t), 3))
    v[t < 4.0, 0] = 3.0
    v[t >= 6.0, 1] = 3.0
    o = sx.course_odometry(t, v)
    assert abs(np.trapezoid(o[:, 2], t) + math.pi / 2) < 1e-9
    assert np.abs(o[(t < 3.7) | (t > 6.3), 2]).max() < 1e-12
    noisy = sx.course_odometry(t, v, np.random.default_rng(1))
    assert 0 < np.std(noisy[t > 6.3, 1] - 3.0) < 0.1 and np.all(noisy[:, 1] >= 0)


def test_a_short_exported_flight_runs_through_evaluate_tight(tmp_path):
    """The export reproduces the receiver's own fixes: the smartLoc SPP row equals the simulator's fix
    errors epoch by epoch (to a millimetre), and ``evaluate.tight`` runs on it."""
    from gcs_tools.evaluate import simcal, tight

    out = tmp_path / "drives"
    assert sx.main(["--mission", "mild", "--profiles", "3", "--seeds", "0", "--max-duration-s", "30",
                    "--out", str(out)]) == 0
    info = json.loads((out / "results.json").read_text())["drives"][0]
    inp = out / info["input"]
    data, truth = smartloc.read_drive(inp)
    assert len(data.epochs) == info["epochs"] >= 140 and len(data.odometry) == info["epochs"]
    # the same flight's receiver fixes (simcal flies it identically: seeded)
    (series,) = simcal.simulate("mild", simcal.SCENARIO, [3], [0], 30.0)
    spp = baseline.solve_series(data.epochs, SppConfig())
    origin = truth.p_ecef_m[0]
    err = baseline.ned_errors(spp.p_ecef_m, truth.at(spp.t_s), origin)
    ok = np.isfinite(series.err_ned_m).all(axis=1)
    assert ok.sum() >= 0.9 * len(ok)
    np.testing.assert_allclose(np.hypot(*err[ok, :2].T), np.hypot(*series.err_ned_m[ok, :2].T), atol=1e-3)
    r = tight.run(inp, None, n_resamples=100, rows=("second-order",), loose=False, no_odometry=False)
    rows = r["rows"]
    assert rows["spp"]["n"] >= 0.9 * info["epochs"]
    assert abs(rows["spp"]["median_m"] - info["receiver_fix_median_m"]) < 0.3
    # not diverging: the belief stays within the single-point solution's worst error
    assert rows["tight-second-order"]["max_m"] < rows["spp"]["max_m"]
    assert r["resets"] == {"tight-second-order": 0}
