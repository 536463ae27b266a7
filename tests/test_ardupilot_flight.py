"""End to end beside a real autopilot: ArduCopter SITL flies the test city's cross street in
GUIDED on GPS_INPUT from our urban GNSS model; EKF3 and the companion are scored on the same fixes."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from ardupilot_helpers import require_ardupilot
from pymavlink import mavutil

pytestmark = pytest.mark.slow


@pytest.mark.timeout(300)
def test_sitl_vehicle_ardupilot_flies_the_route_and_scores_ekf3_and_the_companion(tmp_path):
    require_ardupilot()
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "gcs_tools", "sitl", "--vehicle", "ardupilot", "--mission", "test",
           "--profile", "2", "--method", "second-order", "--seed", "0", "--out", str(out),
           "--wall-timeout-s", "200", "--speedup", "5"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=280)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    s = json.loads((out / "summary.json").read_text())
    # --speedup 5: SITL does not wait for us; at 5x a loaded 2-core machine still keeps our commands
    # on time (command_delay_ms, measured in ArduPilot's time)
    assert s["valid"], s["ardupilot"]["command_delay_ms"]
    assert s["reached_goal"] and s["vehicle"] == "ardupilot" and s["feed"] == "none"
    ap = s["ardupilot"]
    assert ap["ended_by"] == "reached_goal"
    assert ap["parameters"]["GPS1_TYPE"] == 14
    assert ap["messages_received"]["HIGHRES_IMU"] > 1000 and ap["messages_received"]["SIM_STATE"] > 1000
    # GPS_INPUT at 10 Hz of ArduPilot time from the first truth sample on (the last few still queued)
    assert abs(ap["gps_input_sent"] - 10 * ap["sim_s"]) < 0.02 * 10 * ap["sim_s"] + 15
    assert s["gnss"]["sent"] == ap["gps_input_sent"]
    # EKF3 and every companion method were scored along the route on the same samples. How well
    # each does is the measurement (docs/ardupilot-vs-ekf3.md: EKF3 can declare a GPS glitch in a
    # canyon and drift), so only "an estimate, not a lost filter" is asserted here.
    ekf = s["autopilot_estimation_error_horizontal_m"]
    assert 0.05 < ekf["median"] < 10.0
    for name, row in s["methods"].items():
        assert 0.01 < row["estimation_error_horizontal_m"]["median"] < 10.0, name
    assert s["estimation_error_m"] == s["methods"]["second-order"]["estimation_error_m"]
    assert s["autopilot_estimation_error_m"] == s["methods"]["ardupilot-ekf3"]["estimation_error_m"]
    assert np.isfinite(s["tracking_error_m"]["median"]) and s["min_clearance_m"] >= 0.0
    assert s["duration_s"] > s["route_duration_s"] - 0.05  # reached once the reference arrived
    # files: the time series has EKF3's track; the tlog carries both directions
    header = (out / "timeseries.csv").read_text().splitlines()[0].split(",")
    assert "p_autopilot_n_m" in header and "est_error_m" in header
    table = np.loadtxt(out / "timeseries.csv", delimiter=",", skiprows=1)
    assert np.isfinite(table[:, header.index("autopilot_error_m")]).mean() > 0.95
    for name in ("map.png", "belief.png"):
        assert (out / name).stat().st_size > 10_000
    log = mavutil.mavlink_connection(str(out / "run.tlog"))  # a standard tlog, as MAVProxy reads it
    kinds: dict[str, int] = {}
    wanted = ["GPS_INPUT", "SIM_STATE", "SET_POSITION_TARGET_LOCAL_NED"]
    while (msg := log.recv_match(type=wanted)) is not None:
        kinds[msg.get_type()] = kinds.get(msg.get_type(), 0) + 1
    assert kinds.get("GPS_INPUT") == ap["gps_input_sent"]
    assert kinds.get("SET_POSITION_TARGET_LOCAL_NED", 0) > 500 and kinds.get("SIM_STATE", 0) > 1000


@pytest.mark.timeout(300)
def test_closed_loop_ardupilot_flies_on_the_companions_cleaned_fixes(tmp_path):
    """--feed gps-input: every GPS_INPUT ArduPilot got is the companion's estimate at its stamp, the
    very estimate the analysis scores (same samples, same order), and the vehicle reaches the goal."""
    require_ardupilot()
    from companion.mission import load_mission

    out = tmp_path / "closed"
    cmd = [sys.executable, "-m", "gcs_tools", "sitl", "--vehicle", "ardupilot", "--feed", "gps-input",
           "--mission", "test", "--profile", "2", "--seed", "0", "--out", str(out), "--wall-timeout-s", "200",
           "--speedup", "5"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=280)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    s = json.loads((out / "summary.json").read_text())
    assert s["valid"], s["ardupilot"]["command_delay_ms"]
    assert s["reached_goal"] and s["feed"] == "gps-input"
    assert s["ardupilot"]["parameters"] == {"GPS1_TYPE": 14, "GPS1_DELAY_MS": 1}
    header = (out / "timeseries.csv").read_text().splitlines()[0].split(",")
    table = np.loadtxt(out / "timeseries.csv", delimiter=",", skiprows=1)
    t0_us = round(s["ardupilot"]["phase_times_s"]["route"] * 1e6)
    t_us = np.round(table[:, header.index("t_s")] * 1e6).astype(np.int64) + t0_us
    est = table[:, [header.index(c) for c in ("p_est_n_m", "p_est_e_m")]]
    frame = load_mission("test").frame
    log = mavutil.mavlink_connection(str(out / "run.tlog"))
    checked = 0
    while (msg := log.recv_match(type="GPS_INPUT")) is not None:
        i = int(np.argmin(np.abs(t_us - msg.time_usec)))
        if abs(int(t_us[i]) - msg.time_usec) <= 1000:  # a route-phase sample (t_s has 6 digits; 20 ms apart)
            p = frame.to_ned_m(msg.lat * 1e-7, msg.lon * 1e-7, msg.alt)
            np.testing.assert_allclose(p[:2], est[i], atol=0.02)  # degE7 and the CSV's 6 digits
            checked += 1
    # most IMU ticks carry a truth sample (the CSV's rows); those that do must all agree
    assert checked > 0.6 * 10 * s["route_duration_s"]
