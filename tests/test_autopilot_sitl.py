"""``beliefnav companion`` beside a real ArduCopter SITL (speedup 10, a free -I): discovery, streams,
TIMESYNC, the estimate against EKF3, and ArduPilot flying on our GPS_INPUT."""

from __future__ import annotations

import json
import math
import time

import numpy as np
from ardupilot_helpers import GroundStation, require_ardupilot, run_companion, stop, tlog_messages
from pymavlink import mavutil

from gcs_tools.ardupilot.sitl import ArduPilotSitl, SitlConfig

M = mavutil.mavlink


def test_companion_beside_arducopter_discovers_streams_and_matches_ekf3(tmp_path):
    """... and when the autopilot reboots (SITL restarted mid-run, parameters kept): reconnect,
    a fresh estimator, the streams asked for again and arriving again."""
    require_ardupilot()
    out = tmp_path / "companion"
    with ArduPilotSitl(SitlConfig(work_dir=tmp_path / "ap", speedup=10)) as sitl:
        proc = run_companion(sitl.url, out, "--duration-s", "15")
        other = mavutil.mavlink_connection(sitl.wait_serial(1), source_system=42, source_component=190)
        try:
            start = time.monotonic()
            while time.monotonic() - start < 8 and proc.poll() is None:
                # another system on SERIAL1; ArduPilot routes it to SERIAL0
                other.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
                time.sleep(0.3)
            other.close()
            sitl.restart()
            proc.wait(timeout=30)
        finally:
            code, err = stop(proc)
    assert code == 0, err
    s = json.loads((out / "summary.json").read_text())
    ap = s["autopilot"]
    assert (ap["system_id"], ap["component_id"], ap["autopilot_type"], ap["vehicle_type"]) == (1, 1, 3, 2)
    asks = s["streams"]["requests"]  # at start, and again after the reboot
    assert asks in (2, 3)
    assert s["streams"]["acks"] == {"MAV_CMD_SET_MESSAGE_INTERVAL:MAV_RESULT_ACCEPTED": 8 * asks}
    assert s["streams"]["fallback_requests"] == 0
    received = s["samples"]["received"]
    for kind in ("HIGHRES_IMU", "ATTITUDE_QUATERNION", "GPS_RAW_INT", "SYSTEM_TIME", "GLOBAL_POSITION_INT",
                 "LOCAL_POSITION_NED", "GPS_GLOBAL_ORIGIN", "HOME_POSITION"):
        assert received.get(kind, 0) > 0, kind
    used = s["samples"]["used"]
    assert used["imu"] > 1000 and used["gnss"] > 50
    assert s["samples"]["rejected"].get("autopilot_other_system", 0) > 0
    err = s["errors"]["autopilot_estimate"]
    assert err["alignment"]["reference"] == "GLOBAL_POSITION_INT" and err["error_horizontal_m"]["count"] > 100
    assert err["error_horizontal_m"]["median"] < 1.0  # open sky: within 1 m of EKF3
    ts = s["timesync"]
    assert ts["requests_answered"] >= 1 and ts["responses_used"] >= 1 and ts["rtt_ms"] < 50
    assert s["node"]["autopilot_reboots"] == 1 and s["link"]["reconnects"] == 1

    msgs = tlog_messages(out / "run.tlog")  # both directions
    ours = [m for m in msgs if (m.get_srcSystem(), m.get_srcComponent()) == (1, 197)]
    theirs = [m for m in msgs if (m.get_srcSystem(), m.get_srcComponent()) == (1, 1)]
    hb = [m for m in ours if m.get_type() == "HEARTBEAT"]
    assert hb and all(m.type == M.MAV_TYPE_ONBOARD_CONTROLLER and m.autopilot == M.MAV_AUTOPILOT_INVALID
                      for m in hb)
    asked = {int(m.param1): m.param2 for m in ours if m.get_type() == "COMMAND_LONG"
             and m.command == M.MAV_CMD_SET_MESSAGE_INTERVAL}
    assert asked[M.MAVLINK_MSG_ID_HIGHRES_IMU] == 20_000
    imu_t = np.array([m.time_usec for m in theirs if m.get_type() == "HIGHRES_IMU"])
    reboot = int(np.argmax(np.diff(imu_t) < 0)) + 1  # boot time went back here
    assert reboot > 100 and imu_t.size - reboot > 100  # streams arriving before and again after the reboot
    # at the 50 Hz asked for, on the autopilot's clock (measured 19 992 µs: its 400 Hz loop's ticks)
    assert abs(np.median(np.diff(imu_t)) - 20_000) < 100
    requests = {m.ts1 for m in theirs if m.get_type() == "TIMESYNC" and m.tc1 == 0}
    answers = {m.ts1 for m in ours if m.get_type() == "TIMESYNC" and m.tc1 > 0}
    assert requests and requests <= answers  # every TIMESYNC request of the autopilot answered


def test_arducopter_takes_off_and_holds_on_our_gps_input(tmp_path):
    """GPS1 = our GPS_INPUT (GPS1_TYPE 14, the only GPS EKF3 uses: no auto switch); the companion's
    own raw GNSS is the SITL's simulated receiver on GPS2 (GPS2_RAW, --gnss-instance 2)."""
    require_ardupilot()
    out = tmp_path / "companion"
    params = {"GPS1_TYPE": 14, "GPS2_TYPE": 1, "SIM_GPS2_ENABLE": 1, "GPS_AUTO_SWITCH": 0, "GPS_PRIMARY": 0}
    with ArduPilotSitl(SitlConfig(work_dir=tmp_path / "ap", speedup=10, params=params)) as sitl:
        gcs = None
        proc = run_companion(sitl.url, out, "--feed", "gps-input", "--gnss-instance", "2",
                             "--duration-s", "120")
        try:
            gcs = GroundStation(sitl.wait_serial(1))
            flight = _arm_take_off_and_hold(gcs, altitude_m=10.0, hold_s=10.0, wall_limit_s=90.0)
        finally:
            if gcs is not None:
                gcs.close()
            code, err = stop(proc)
    assert code in (0, 143, -15), err
    assert flight["armed"], flight
    assert flight["reached_altitude"], flight
    alts = np.array(flight["hold_alt_m"])
    assert alts.size > 20 and np.all(np.abs(alts - 10.0) < 1.0), flight
    assert flight["hold_truth_drift_m"] < 1.5, flight  # SIMSTATE truth: held position
    s = json.loads((out / "summary.json").read_text())
    assert s["node"]["feed_gps_input_sent"] > 100 and s["samples"]["received"].get("GPS2_RAW", 0) > 0
    sent = [m for m in tlog_messages(out / "run.tlog") if m.get_type() == "GPS_INPUT"]
    last = flight["last_gps1"]  # ArduPilot's GPS1 report = what we sent (within one feed period of motion)
    near = [abs(m.lat - last[0]) <= 20 and abs(m.lon - last[1]) <= 20 for m in sent[-20:]]  # degE7
    assert any(near), (last, sent[-1])


def _arm_take_off_and_hold(gcs: GroundStation, altitude_m: float, hold_s: float, wall_limit_s: float) -> dict:
    state: dict = {"armed": False, "reached_altitude": False, "hold_alt_m": [],
                   "hold_truth_drift_m": math.nan, "last_gps1": None, "statustext": []}
    start = time.monotonic()
    next_try = 0.0
    hold_from_ms = None
    truth0 = None
    drift = 0.0
    while time.monotonic() - start < wall_limit_s:
        msg = gcs.conn.recv_match(blocking=True, timeout=0.5)
        now = time.monotonic()
        if now >= next_try:
            next_try = now + 1.0
            gcs.heartbeat()
            if not state["armed"]:
                gcs.try_arm_guided()
        if msg is None:
            continue
        kind = msg.get_type()
        if kind == "STATUSTEXT":
            state["statustext"].append(msg.text)
        elif kind == "HEARTBEAT" and msg.get_srcComponent() == 1 and not state["armed"]:
            if msg.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED:
                state["armed"] = True
                gcs.takeoff(altitude_m)
        elif kind == "GPS_RAW_INT":
            state["last_gps1"] = (msg.lat, msg.lon)
        elif kind == "SIMSTATE" and hold_from_ms is not None:
            here = np.array((msg.lat, msg.lng), float) * 1e-7
            truth0 = here if truth0 is None else truth0
            d = (here - truth0) * (111_320.0, 111_320.0 * math.cos(math.radians(here[0])))
            drift = max(drift, float(np.hypot(*d)))
        elif kind == "GLOBAL_POSITION_INT" and state["armed"]:
            alt = msg.relative_alt / 1000.0
            if hold_from_ms is None and alt >= altitude_m - 0.5:
                state["reached_altitude"] = True
                hold_from_ms = msg.time_boot_ms + 2000  # let the climb settle
            elif hold_from_ms is not None and msg.time_boot_ms >= hold_from_ms:
                state["hold_alt_m"].append(alt)
                if msg.time_boot_ms >= hold_from_ms + hold_s * 1000:
                    break
    state["hold_truth_drift_m"] = drift if truth0 is not None else math.nan
    return state
