"""The companion beside an autopilot publishes what a ground station shows first: flight mode and
armed state from its HEARTBEAT, fix type / satellites / HDOP / altitude from its GPS_RAW_INT, and its
frame's origin (the dashboard places the fixes with it). Known answers on hand-made messages, then
a real ArduCopter SITL, a real companion process and real Zenoh into the dashboard's state."""

from __future__ import annotations

import json
import math
import time
from contextlib import ExitStack
from pathlib import Path

import numpy as np
import pytest
from ardupilot_helpers import GroundStation, require_ardupilot, stop, tlog_messages
from pymavlink.dialects.v20 import common as mavlink2
from telemetry_helpers import child, free_port, hub_env
from test_dashboard_browser import ARGS, CHROMIUM

from companion.autopilot.status import AutopilotStatus, flight_mode
from companion.domain.geodesy import LocalNedFrame
from companion.domain.samples import GnssFix
from companion.telemetry import codec as zc

M = mavlink2
ARMED = M.MAV_MODE_FLAG_SAFETY_ARMED | M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED


class Recorder:
    def __init__(self) -> None:
        self.sent: list[tuple[str, object]] = []

    def publish(self, topic: str, obj: object) -> None:
        zc.encode(topic, obj, 0)  # every payload must encode
        self.sent.append((topic, obj))

    def topics(self) -> list[str]:
        return [t for t, _ in self.sent]


def heartbeat(autopilot: int, custom_mode: int, base_mode: int = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
              vehicle: int = M.MAV_TYPE_QUADROTOR):
    return M.MAVLink_heartbeat_message(vehicle, autopilot, base_mode, custom_mode, 0, 3)


def gps_raw(time_usec: int, fix_type: int, satellites: int, eph: int = 121):
    return M.MAVLink_gps_raw_int_message(time_usec, fix_type, -353632620, 1491652370, 584_000, eph, 200,
                                         0, 0, satellites)


def test_mode_names_are_pymavlinks_for_ardupilot_and_px4():
    ap = M.MAV_AUTOPILOT_ARDUPILOTMEGA
    assert [flight_mode(heartbeat(ap, m)) for m in (0, 4, 5, 6, 9)] == ["STABILIZE", "GUIDED", "LOITER",
                                                                        "RTL", "LAND"]
    px4 = M.MAV_AUTOPILOT_PX4
    # PX4 custom_mode: main mode in bits 16-23, sub mode in 24-31 (px4_custom_mode.h)
    assert flight_mode(heartbeat(px4, 3 << 16)) == "POSCTL"
    assert flight_mode(heartbeat(px4, 6 << 16)) == "OFFBOARD"
    assert flight_mode(heartbeat(px4, (4 << 16) | (3 << 24))) == "LOITER"
    assert flight_mode(heartbeat(px4, (4 << 16) | (4 << 24))) == "MISSION"
    assert flight_mode(heartbeat(ap, 99)) == "Mode(99)"  # unknown: shown as a number, not guessed


def test_status_once_a_second_and_at_once_on_a_change():
    rec = Recorder()
    st = AutopilotStatus(rec)
    ap = M.MAV_AUTOPILOT_ARDUPILOTMEGA
    frame = LocalNedFrame(-35.36, 149.16, 584.0)
    for i in range(25):  # a SITL at x10: ten HEARTBEATs a wall second
        base_mode = ARMED if i >= 13 else M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        st.heartbeat(heartbeat(ap, 4 if i >= 7 else 0, base_mode), 1_000_000 * i, 0.1 * i,
                     frame if i >= 20 else None)
    got = [(o.t_us, o.mode, o.armed) for t, o in rec.sent if t == "status"]
    assert got == [(0, "STABILIZE", False), (7_000_000, "GUIDED", False), (13_000_000, "GUIDED", True),
                   (23_000_000, "GUIDED", True)]
    routes = [o for t, o in rec.sent if t == "route"]  # with the status, once the frame is known
    assert len(routes) == 1 and routes[0].waypoints_ned_m.shape == (0, 3)
    np.testing.assert_array_equal(routes[0].home_lla, [-35.36, 149.16, 584.0])


def test_gnss_every_new_fix_and_the_no_fix_state_once_a_second():
    rec = Recorder()
    st = AutopilotStatus(rec)
    # before a first fix ArduPilot stamps nothing: the state at 1 Hz, at once on a change
    for i in range(12):
        st.gnss(gps_raw(0, 1, 3 if i < 8 else 5, eph=9999), None, 100_000 * i, 0.1 * i)
    no_fix = [o for _, o in rec.sent]
    assert [(r.t_us, r.fix.fix_type, r.fix.satellites_visible) for r in no_fix] == [
        (0, 1, 3), (800_000, 1, 5)]
    assert no_fix[0].latency_s == 0.0 and no_fix[0].fix.alt_m == 584.0
    assert no_fix[0].fix.hdop == 99.99 and math.isnan(no_fix[0].fix.h_acc_m)  # not reported: NaN
    # fixes: every one the translator took; a repeated one (its None) is not re-sent
    rec.sent.clear()
    fix = GnssFix(2_000_000, -35.36, 149.16, 584.0, 3, 10, hdop=1.21)
    st.gnss(gps_raw(2_120_000, 3, 10), fix, 2_200_000, 2.2)
    st.gnss(gps_raw(2_120_000, 3, 10), None, 2_300_000, 2.3)
    st.gnss(gps_raw(2_120_000, 3, 10), None, 3_500_000, 3.5)
    assert len(rec.sent) == 1 and rec.sent[0][1].fix is fix
    assert rec.sent[0][1].latency_s == pytest.approx(0.2)
    # the fix lost: ArduPilot repeats its last stamp with fix type 1; shown at once
    st.gnss(gps_raw(2_120_000, 1, 2), None, 4_000_000, 4.0)
    assert [(r.fix.fix_type, r.fix.satellites_visible) for _, r in rec.sent[1:]] == [(1, 2)]


@pytest.mark.timeout(120)
def test_beside_arducopter_sitl_the_dashboard_state_shows_mode_armed_and_fix(tmp_path):
    """ArduCopter SITL (x10), ``beliefnav companion`` publishing on a private Zenoh hub, the
    dashboard's LiveState subscribed: STABILIZE and disarmed first, then GUIDED and ARMED as a
    ground station commands them; fix type, satellites, HDOP and altitude as the autopilot's last
    GPS_RAW_INT in the companion's own tlog; fixes placed on the map; "ended" after the clean stop."""
    require_ardupilot()
    import subprocess
    import sys

    from companion.telemetry.pubsub import TelemetryConfig, TelemetrySubscriber
    from gcs_tools.dashboard.state import LiveState
    from simvehicle.harness.ardupilot.sitl import ArduPilotSitl, SitlConfig

    env = hub_env()
    state = LiveState()
    out = tmp_path / "companion"
    cfg = TelemetryConfig.from_env(env)
    port = free_port()
    with ExitStack() as stack:
        page = None
        if Path(CHROMIUM).exists():  # and the page itself, in headless Chromium, beside it
            dash = stack.enter_context(child(["-m", "gcs_tools", "dashboard", "--port", str(port)], env))
            assert dash.stdout.readline().startswith("dashboard on http://127.0.0.1:")
            pw = stack.enter_context(pytest.importorskip("playwright.sync_api").sync_playwright())
            browser = pw.chromium.launch(executable_path=CHROMIUM, args=ARGS)
            stack.callback(browser.close)
            page = browser.new_page(viewport={"width": 1300, "height": 900})
            page.goto(f"http://127.0.0.1:{port}/")
        sub = stack.enter_context(TelemetrySubscriber(state.ingest, cfg))
        sitl = stack.enter_context(ArduPilotSitl(SitlConfig(work_dir=tmp_path / "ap", speedup=10)))
        proc = subprocess.Popen([sys.executable, "-m", "gcs_tools", "companion", "--master", sitl.url,
                                 "--out", str(out), "--vehicle-id", "ap1", "--duration-s", "25"],
                                env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        seen: list[tuple[str, bool]] = []

        def latest() -> dict:
            return state.summary().get("ap1", {})

        def wait(cond, timeout_s: float) -> bool:
            deadline = time.monotonic() + timeout_s
            while time.monotonic() < deadline and proc.poll() is None:
                s = latest()
                if "mode" in s and (not seen or seen[-1] != (s["mode"], s["armed"])):
                    seen.append((s["mode"], s["armed"]))
                if cond(s):
                    return True
                time.sleep(0.05)
            return False

        gcs = None
        try:
            assert wait(lambda s: s.get("fix_type", 0) >= 3 and s.get("mode") == "STABILIZE", 40), latest()
            gcs = GroundStation(sitl.wait_serial(1))
            gcs.conn.mav.set_mode_send(1, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4)  # GUIDED
            assert wait(lambda s: s.get("mode") == "GUIDED", 10), latest()
            # forced arming (21196: no pre-arm checks), asked again each second until it is armed
            for _ in range(10):
                gcs.heartbeat()
                gcs.conn.mav.command_long_send(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 21196, *[0] * 5)
                if wait(lambda s: s.get("armed") is True, 1.0):
                    break
            texts = [m.text for m in iter(lambda: gcs.conn.recv_match(type="STATUSTEXT"), None)]
            assert latest().get("armed") is True or ("GUIDED", True) in seen, (latest(), texts)
            gcs.conn.mav.command_long_send(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 21196, *[0] * 5)
            assert wait(lambda s: s.get("armed") is False, 10), latest()
            if page is not None:
                page.wait_for_function("() => document.getElementById('f-mode').textContent === 'GUIDED'"
                                       " && document.getElementById('f-armed').textContent === 'disarmed'"
                                       " && window.dashboardVehicles.ap1.series.fix.length > 10",
                                       timeout=10_000)
                tiles = ("mode", "armed", "fix", "sats", "hdop", "alt")
                shown = {k: page.inner_text(f"#f-{k}") for k in tiles}
        finally:
            if gcs is not None:
                gcs.close()
            code, err = stop(proc)
        time.sleep(0.5)  # the last messages through Zenoh
        assert code in (0, 143), err  # 143: our SIGTERM, a clean stop (summary written)
        assert sub.malformed_total == 0
    assert seen[0] == ("STABILIZE", False) and seen[-1] == ("GUIDED", False)
    assert ("GUIDED", True) in seen
    s = latest()
    gps = [m for m in tlog_messages(out / "run.tlog") if m.get_type() == "GPS_RAW_INT"
           and (m.get_srcSystem(), m.get_srcComponent()) == (1, 1)]
    last = gps[-1]
    assert (s["fix_type"], s["satellites"]) == (last.fix_type, last.satellites_visible)
    assert s["hdop"] == pytest.approx(last.eph / 100) and s["gnss_alt_m"] == pytest.approx(last.alt / 1000)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["autopilot"]["autopilot_type"] == 3
    # altitude above home: the estimate's, near the ground at rest (ArduPilot's home altitude)
    assert abs(s["altitude_m"]) < 2.0, s["altitude_m"]
    msgs = s["messages"]
    print(f"modes seen {seen}; messages {msgs}; last GPS_RAW_INT fix {last.fix_type} sats "
          f"{last.satellites_visible} eph {last.eph}")
    # 1 Hz of ~25 s and the changes (a x10 SITL sends 10 HEARTBEATs a second)
    assert 5 <= msgs["companion/status"] <= 25 + 5, msgs
    new_fixes = len({m.time_usec for m in gps if m.time_usec})
    assert abs(msgs["companion/gnss"] - new_fixes) <= 3, (msgs["companion/gnss"], new_fixes)
    assert msgs.get("companion/route", 0) >= 3
    view = state.vehicles["ap1"]
    fixes = list(view.series["fix"]) + view.pending["fix"]
    assert len(fixes) > 50
    est = np.array([p[1:] for p in list(view.series["est"]) + view.pending["est"]][-50:], dtype=float)
    placed = np.array([p[1:] for p in fixes[-10:]], dtype=float)
    # at rest: the fixes on the map where the estimates are (same frame), within the SITL's noise
    assert np.linalg.norm(placed.mean(axis=0) - est.mean(axis=0)) < 2.0
    assert s["status"]["companion"] == "ended"
    if page is not None:  # the page shows the state's values as QGroundControl would
        assert shown["mode"] == "GUIDED" and shown["armed"] == "disarmed", shown
        assert shown["fix"] == {3: "3D fix", 6: "RTK fixed"}[s["fix_type"]], shown
        assert shown["sats"] == str(s["satellites"]) and shown["hdop"] == f"{s['hdop']:.1f}", shown
        assert abs(float(shown["alt"].removesuffix(" m"))) < 2.0, shown
