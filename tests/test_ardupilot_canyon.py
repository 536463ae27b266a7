"""ArduCopter SITL on the calibrated canyon receiver, closed loop: the harness measures raw epochs from
ArduPilot's truth, sends the receiver's own fixes to GPS2 and serves the epochs as UBX on TCP;
``beliefnav companion --coupling tight --ubx tcp:…`` reads them and feeds EKF3 (GPS1 = its GPS_INPUT).
The flight's record (receiver.ubx) holds exactly the epochs and fixes sent; EKF3 gets a position from
the companion's fixes (the driver reaches its arming phase). Whether ArduPilot then arms is the
measurement, not asserted: in a canyon its arming checks often refuse ("GPS glitching", "GPS positions
differ": the raw receiver on GPS2 and the companion on GPS1 more than 50 m apart); when the route is
flown, the open-loop rows (the receiver's fixes, the tightly coupled filter) and what the companion
sent are scored (the scoring itself: tests/test_foreign_canyon.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from ardupilot_helpers import require_ardupilot, tlog_messages
from canyon_helpers import fly_canyon, ubx_record

from companion.gnss.timescale import week_tow

pytestmark = pytest.mark.slow


@pytest.mark.timeout(150)
def test_closed_loop_ardupilot_flies_on_the_tight_companion_reading_the_canyon_receiver(tmp_path):
    require_ardupilot()
    proc, out = fly_canyon(tmp_path, "ardupilot", 140, "--feed", "gps-input", "--wall-timeout-s", "100",
                           "--speedup", "10", "--no-figures")  # no check reads them
    assert proc.returncode in (0, 1), proc.stdout + proc.stderr  # 1: flew, did not reach the goal
    s = json.loads((out / "summary.json").read_text())
    ap = s["ardupilot"]
    assert ap["ended_by"] in ("reached_goal", "timeout", "setup_timeout:arm"), ap["ended_by"]
    assert "arm" in ap["phase_times_s"]  # EKF3 had an absolute position: the companion's fixes on GPS1
    assert ap["parameters"]["EK3_GPS_CHECK"] == 0 and ap["parameters"]["GPS2_TYPE"] == 14
    rx = ap["receiver"]
    assert rx["epochs"] > 4 * ap["sim_s"] and rx["unsolved"] == 0 and rx["fixes"] >= ap["gps_input_sent"]
    # the companion owned the receiver: the UBX stream over TCP into the tightly coupled filter
    comp = ap["companion"]
    assert "--coupling tight --ubx tcp:127.0.0.1:" in comp["command"] and comp["problems"] == []
    csum = json.loads((out / "companion" / "summary.json").read_text())
    assert csum["coupling"] == "tight" and csum["receiver"]["lnav_ephemerides"] > 0
    # the mission's map (--mission), and the raw epochs put before ArduPilot's clock by the receiver's
    # latency, which the second receiver declares (GPS2_DELAY_MS)
    assert csum["mission"] == "test-city" and "--mission" in comp["command"]
    assert ap["parameters"]["GPS2_DELAY_MS"] == 80 and csum["clock"]["system_time_lag_ms"] == 80.0
    assert csum["receiver"].get("glonass_ephemerides", 0) > 0  # GLONASS's too (strings 1-4)
    assert csum["node"]["raw_epochs"] > 0.5 * rx["epochs_released"]
    assert csum["node"]["feed_gps_input_sent"] > 5 * ap["phase_times_s"]["arm"] * 0.1
    # the record: receiver.ubx decodes to the epochs released and the fixes sent to GPS2, same GPS time
    n_epochs, solutions = ubx_record(out)
    pvts = {round(week_tow(p.t_gps_s)[1] * 1000): p for p in solutions}
    assert n_epochs == rx["epochs_released"]
    msgs = tlog_messages(out / "run.tlog")
    sent = [m for m in msgs if m.get_type() == "GPS_INPUT" and m.get_srcSystem() == 255]
    assert len(sent) == ap["gps_input_sent"] and {m.gps_id for m in sent} == {1}
    for m in sent:
        pvt = pvts[m.time_week_ms]  # the receiver's own solution of that epoch
        assert abs(m.lat - round(pvt.lat_deg * 1e7)) <= 1 and abs(m.lon - round(pvt.lon_deg * 1e7)) <= 1
    # EKF3 flew on the companion (GPS1), which sent a fix with its own accuracy
    ours = [m for m in msgs if m.get_type() == "GPS_INPUT" and m.get_srcComponent() == 197]
    assert {m.gps_id for m in ours} == {0} and any(m.fix_type == 3 and m.horiz_accuracy > 0 for m in ours)
    if ap["ended_by"] == "setup_timeout:arm":  # refused by ArduPilot's GPS arming checks, as it said
        texts = [t.split(" s ", 1)[1] for t in ap["statustext"]]
        assert any(t.startswith(("Arm: GPS", "PreArm: GPS")) for t in texts), texts
        return
    # scored on the same epochs: the receiver's fixes, the tight rows, and what the companion sent. The
    # bound checks the scoring (a wrong frame or origin gives kilometres; the scoring's known answers:
    # tests/test_foreign_canyon.py), not the accuracy: a real-time flight between walls may end up behind
    # buildings, where the receiver's own fixes have read 61 m median in a green run of everything else
    rows = s["methods"]
    for name in ("spp", "tight-second-order", "tight-cn0-elevation", "companion-live", "ardupilot-ekf3"):
        med = rows[name]["estimation_error_horizontal_m"]["median"]
        assert np.isfinite(med) and 0.01 < med < 200.0, (name, med)
    assert s["estimation_error_m"] == rows["companion-live"]["estimation_error_m"]
    # the route at the mission's altitude above the ground, whatever EKF3's origin altitude (its first
    # fix's): the local frame is placed by EKF3's barometric height on the ground
    assert ap["phase_times_s"]["route"] > 0
    h = -np.array([float(r.split(",")[3]) for r in (out / "timeseries.csv").read_text().splitlines()[1:]])
    assert np.median(h) > 10.0, np.median(h)
