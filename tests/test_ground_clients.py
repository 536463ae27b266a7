"""Real ground stations against one real-time SITL flight: MAVSDK-Python and MAVProxy connect
to the ground port (udpout), a pymavlink client listens where the vehicle sends by default
(udpin, here on a free port given with --ground-out). One flight serves every test below."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from sitl_helpers import require_pieces

pytestmark = [pytest.mark.slow, pytest.mark.timeout(150)]
MISSION = "test"
PROBES = Path(__file__).with_name("ground_probes.py")
VEHICLE, AUTOPILOT_COMPONENT = 1, 1
GCS_SYSTEM, GCS_COMPONENT = 255, 190  # the ids our pymavlink client speaks with


class Flight:
    """The SITL run, the probes' results and the pymavlink (udpin) client's observations."""

    def __init__(self, root: Path) -> None:
        from simvehicle.harness.sitl.supervisor import free_udp_ports

        self.root = root
        *self.ports, self.udpin_port = free_udp_ports(4)
        self.results: dict[str, dict] = {}
        self.pymavlink: dict[str, object] = {}


def _pymavlink_session(conn, flight: Flight, deadline: float) -> None:  # noqa: C901 - one scripted session
    """Everything the udpin client checks, in order, while the others watch."""
    from pymavlink import mavutil

    m = mavutil.mavlink
    seen = flight.pymavlink

    def recv(kind: str, timeout_s: float = 10.0, condition=None):
        end = min(deadline, time.monotonic() + timeout_s)
        while time.monotonic() < end:
            msg = conn.recv_match(type=kind, blocking=True, timeout=0.5)
            if msg is not None and msg.get_srcSystem() == VEHICLE and (condition is None or condition(msg)):
                return msg
        return None

    hb = recv("HEARTBEAT", 40.0, lambda h: h.get_srcComponent() == AUTOPILOT_COMPONENT)
    seen["heartbeat"] = None if hb is None else hb.to_dict()
    conn.target_system, conn.target_component = VEHICLE, AUTOPILOT_COMPONENT
    seen["location"] = conn.location()  # blocks until GLOBAL_POSITION_INT and VFR_HUD arrived
    seen["gps_raw"] = recv("GPS_RAW_INT") is not None
    conn.mav.command_long_send(VEHICLE, AUTOPILOT_COMPONENT, m.MAV_CMD_REQUEST_MESSAGE, 0,
                               m.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0, 0, 0)
    ack = recv("COMMAND_ACK", condition=lambda a: a.command == m.MAV_CMD_REQUEST_MESSAGE)
    seen["ack"] = None if ack is None else ack.to_dict()
    seen["autopilot_version"] = recv("AUTOPILOT_VERSION") is not None
    conn.mav.command_long_send(VEHICLE, AUTOPILOT_COMPONENT, m.MAV_CMD_COMPONENT_ARM_DISARM, 0,
                               0, 0, 0, 0, 0, 0, 0)  # disarm in the air: refused
    disarm = recv("COMMAND_ACK", condition=lambda a: a.command == m.MAV_CMD_COMPONENT_ARM_DISARM)
    seen["disarm_result"] = None if disarm is None else disarm.result
    conn.mav.timesync_send(0, 123_456_789)
    sync = recv("TIMESYNC", condition=lambda t: t.ts1 == 123_456_789)
    seen["timesync_tc1"] = None if sync is None else sync.tc1
    # read-only parameter: the answer carries the unchanged value
    conn.mav.param_set_send(VEHICLE, AUTOPILOT_COMPONENT, b"EST_CHI2_GATE", 99.0, m.MAV_PARAM_TYPE_REAL32)
    value = recv("PARAM_VALUE", condition=lambda p: p.param_id == "EST_CHI2_GATE")
    seen["chi2_after_set"] = None if value is None else value.param_value
    # wait for the MAVSDK probe before an outage, so its health readings see a healthy vehicle
    while "mavsdk" not in flight.results and time.monotonic() < deadline:
        conn.recv_match(blocking=True, timeout=0.2)
    conn.mav.param_set_send(VEHICLE, AUTOPILOT_COMPONENT, b"SIM_GPS_DISABLE", 1.0, m.MAV_PARAM_TYPE_REAL32)
    lost = recv("STATUSTEXT", condition=lambda t: "GNSS lost" in t.text)
    seen["gnss_lost_text"] = None if lost is None else lost.text
    gps_bit = m.MAV_SYS_STATUS_SENSOR_GPS
    status = recv("SYS_STATUS", 5.0, lambda s: not s.onboard_control_sensors_health & gps_bit)
    seen["gps_unhealthy_reported"] = status is not None and bool(
        status.onboard_control_sensors_present & gps_bit)
    conn.mav.param_set_send(VEHICLE, AUTOPILOT_COMPONENT, b"SIM_GPS_DISABLE", 0.0, m.MAV_PARAM_TYPE_REAL32)
    back = recv("STATUSTEXT", condition=lambda t: t.text == "GNSS OK")
    seen["gnss_back"] = back is not None


@pytest.fixture(scope="module")
def flight(tmp_path_factory) -> Flight:
    require_pieces()
    import threading

    os.environ["MAVLINK20"] = "1"
    from pymavlink import mavutil

    f = Flight(tmp_path_factory.mktemp("ground"))
    out = f.root / "run"
    conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{f.udpin_port}", source_system=GCS_SYSTEM,
                                      source_component=GCS_COMPONENT)
    sitl = subprocess.Popen(
        [sys.executable, "-m", "gcs_tools", "sitl", "--no-progress", "--mission", MISSION, "--realtime",
         "--max-duration-s", "60", "--out", str(out), "--ports", ",".join(map(str, f.ports)),
         "--ground-out", f"127.0.0.1:{f.udpin_port}", "--no-telemetry", "--no-signing"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
    )
    ground = str(f.ports[2])
    deadline = time.monotonic() + 100.0
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    probes = {
        "mavsdk": subprocess.Popen([sys.executable, str(PROBES), "mavsdk", ground,
                                    str(f.root / "mavsdk.json")], **quiet),
        "mavproxy": subprocess.Popen([sys.executable, str(PROBES), "mavproxy", ground,
                                      str(f.root / "mavproxy.json"), str(f.root), "80"], **quiet),
    }

    def collect() -> None:
        for name, proc in probes.items():
            try:
                proc.wait(timeout=max(1.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                proc.kill()
            path = f.root / f"{name}.json"
            f.results[name] = json.loads(path.read_text()) if path.exists() else {"error": "no result"}

    collector = threading.Thread(target=collect, daemon=True)
    collector.start()
    try:
        _pymavlink_session(conn, f, deadline)
        collector.join(timeout=max(1.0, deadline - time.monotonic()))
    finally:
        for proc in probes.values():
            if proc.poll() is None:
                proc.kill()
        os.killpg(sitl.pid, signal.SIGINT)  # the launcher stops its three processes
        try:
            sitl.communicate(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(sitl.pid, signal.SIGKILL)
        conn.close()
    f.results.setdefault("mavsdk", {"error": "not collected"})
    f.results.setdefault("mavproxy", {"error": "not collected"})
    f.results["vehicle"] = json.loads((out / "vehicle.json").read_text())
    return f


def test_mavsdk_sees_position_attitude_armed_in_air_mode_health_home_and_parameters(flight):
    r = flight.results["mavsdk"]
    home_lat, home_lon = 52.52, 13.405  # the test mission's home (near it: the start is 47 m east)
    # (autopilot_type is not checked: MAVSDK reads it from whichever component it hears first)
    pos = r["position"]
    assert abs(pos["latitude_deg"] - home_lat) < 0.01 and abs(pos["longitude_deg"] - home_lon) < 0.01, r
    assert pos["relative_altitude_m"] == pytest.approx(15.0, abs=3.0)  # the test mission flies at 15 m
    q = r["attitude_quaternion"]
    assert math.hypot(q["w"], q["x"], q["y"], q["z"]) == pytest.approx(1.0, abs=1e-3), r
    assert r["armed"] is True and r["in_air"] is True and r["landed_state"] == "IN_AIR"
    assert r["flight_mode"] == "OFFBOARD"
    health = r["health"]
    for ok in ("is_gyrometer_calibration_ok", "is_accelerometer_calibration_ok", "is_local_position_ok",
               "is_global_position_ok", "is_home_position_ok", "is_armable"):
        assert health[ok] is True, (ok, health)
    assert health["is_magnetometer_calibration_ok"] is False  # no magnetometer is simulated: not claimed
    home = r["home"]
    assert home["relative_altitude_m"] == 0.0 and home["local_down_m"] == 0.0
    assert abs(home["latitude_deg"] - home_lat) < 0.01
    assert r["EST_CHI2_GATE"] == pytest.approx(7.815, rel=1e-6)
    assert len(r["params"]) == 28 and r["params"]["SIM_GPS_DISABLE"] == 0.0


def test_mavproxy_shows_the_mode_downloads_parameters_and_counts_no_loss(flight):
    r = flight.results["mavproxy"]
    assert r.get("ready"), r
    text = "\n".join(r["output"])
    assert "Mode OFFBOARD" in text and "ARMED" in text
    parm = (flight.root / "mav.parm").read_text().split("\n")
    assert len([line for line in parm if line.strip()]) == 28
    link = [line for line in r["output"] if "packets" in line and "loss" in line]
    assert link, text
    packets = int(link[-1].split("(")[1].split()[0])
    assert packets > 300 and " 0 lost, 0.0% loss" in link[-1], link[-1]  # companions' frames forwarded


def test_pymavlink_udpin_client_locates_the_vehicle_and_gets_answers(flight):
    from pymavlink import mavutil

    m = mavutil.mavlink
    seen = flight.pymavlink
    hb = seen["heartbeat"]
    assert hb is not None and hb["base_mode"] & m.MAV_MODE_FLAG_SAFETY_ARMED
    assert hb["autopilot"] == m.MAV_AUTOPILOT_PX4 and hb["type"] == m.MAV_TYPE_QUADROTOR
    loc = seen["location"]
    assert abs(loc.lat - 52.52) < 0.01 and abs(loc.lng - 13.405) < 0.01
    assert loc.alt == pytest.approx(35.0 + 15.0, abs=3.0)  # MSL: home 35 m + flight altitude 15 m
    assert seen["gps_raw"] and seen["autopilot_version"]
    ack = seen["ack"]
    assert ack == {**ack, "result": m.MAV_RESULT_ACCEPTED, "target_system": GCS_SYSTEM,
                   "target_component": GCS_COMPONENT}
    assert seen["disarm_result"] == m.MAV_RESULT_DENIED
    assert seen["timesync_tc1"] is not None and seen["timesync_tc1"] > 0
    assert seen["chi2_after_set"] == pytest.approx(7.815, rel=1e-6)  # read-only: unchanged


def test_gnss_outage_set_from_the_ground_is_reported_and_withheld(flight):
    seen = flight.pymavlink
    assert seen["gnss_lost_text"] == "GNSS lost (SIM_GPS_DISABLE)"
    assert seen["gps_unhealthy_reported"] and seen["gnss_back"]
    v = flight.results["vehicle"]
    assert v["node"].get("gnss_withheld", 0) > 0  # the vehicle really held fixes back
    requests = v["ground_requests"]
    assert requests["param_set"] == 2 and requests["param_read_only"] == 1


def test_realtime_tlog_stamps_are_monotonic_wall_time(flight):
    from companion.mavlink.tlog import read_tlog

    stamps = [stamp for stamp, _ in read_tlog(flight.root / "run" / "run.tlog")]
    assert len(stamps) > 1000 and all(b >= a for a, b in zip(stamps, stamps[1:], strict=False))
    assert time.time() - 600 < stamps[0] / 1e6 < stamps[-1] / 1e6 <= time.time()
