"""The vehicle's ground link: parameter protocol, telemetry encoders (known answers) and the
link itself over real loopback UDP (udpout clients, udpin targets, requests answered)."""

from __future__ import annotations

import math
import os
import socket

import numpy as np
import pytest

os.environ.setdefault("MAVLINK20", "1")

from companion.domain.geodesy import LocalNedFrame  # noqa: E402
from companion.domain.rotation import euler_to_quaternion  # noqa: E402
from companion.estimator.config import EstimatorConfig  # noqa: E402
from companion.mavlink import codec  # noqa: E402
from simvehicle import ground_telemetry as gt  # noqa: E402
from simvehicle.config import GnssConfig  # noqa: E402
from simvehicle.groundlink import GroundConfig, GroundLink, parse_ground_out  # noqa: E402
from simvehicle.params import ESTIMATOR_PARAMS, ParamServer, mission_params  # noqa: E402

m = codec.mavlink
FRAME = LocalNedFrame(52.52, 13.405, 35.0)
HOME = gt.Home(FRAME, np.array([5.0, 47.0, 0.0]))


def wire(msg):
    frame = codec.pack(codec.new_link(1, 1), msg)
    return codec.new_link(255, 0).parse_buffer(frame)[0]


def _status(**over) -> gt.VehicleStatus:
    fields = dict(t_us=12_340_000, p_ned_m=np.array([105.0, 47.0, -20.0]),
                  v_ned_m_s=np.array([1.5, -0.25, 0.5]),
                  q_ned_frd=euler_to_quaternion(0.0, 0.0, math.radians(90.0)),
                  rates_frd_rad_s=np.array([0.01, -0.02, 0.03]), thrust_fraction=0.5, armed=True,
                  mode="OFFBOARD", estimate_ok=True, gnss_ok=True)
    return gt.VehicleStatus(**{**fields, **over})


# --- parameters ------------------------------------------------------------------------------


def _server() -> ParamServer:
    return ParamServer(mission_params(EstimatorConfig(eta=0.25), GnssConfig()), 1, 1)


def test_param_table_carries_the_mission_values():
    server = _server()
    assert server.value("EST_ETA") == 0.25 and server.value("EST_CHI2_GATE") == EstimatorConfig().chi2_095
    assert server.value("SIMG_LAT_CAP") == GnssConfig().latency_cap_s
    assert server.value("SIM_GPS_DISABLE") == 0.0
    assert len(server.params) == len(ESTIMATOR_PARAMS) + 13 + 1
    assert all(len(p.name) <= 16 for p in server.params)


def test_param_protocol_list_read_set_and_refusals():
    server = _server()
    n = len(server.params)
    listed, _ = server.handle(wire(m.MAVLink_param_request_list_message(1, 1)))
    assert [(p.param_index, p.param_count) for p in listed] == [(i, n) for i in range(n)]
    assert all(p.param_type == m.MAV_PARAM_TYPE_REAL32 for p in listed)
    by_name, _ = server.handle(wire(m.MAVLink_param_request_read_message(1, 1, b"EST_ETA", -1)))
    by_index, _ = server.handle(wire(m.MAVLink_param_request_read_message(1, 1, b"", by_name[0].param_index)))
    assert by_name[0].param_value == by_index[0].param_value == 0.25 and by_index[0].param_id == "EST_ETA"
    # read-only: answered with the unchanged value and a note
    answer, note = server.handle(wire(m.MAVLink_param_set_message(1, 1, b"EST_ETA", 0.9, 9)))
    assert answer[0].param_value == 0.25 and note == "EST_ETA is read-only in flight"
    # writable, valid and invalid values
    answer, note = server.handle(wire(m.MAVLink_param_set_message(1, 1, b"SIM_GPS_DISABLE", 1.0, 9)))
    assert answer[0].param_value == 1.0 and server.value("SIM_GPS_DISABLE") == 1.0
    answer, note = server.handle(wire(m.MAVLink_param_set_message(1, 1, b"SIM_GPS_DISABLE", 0.5, 9)))
    assert answer[0].param_value == 1.0 and "not a valid value" in note
    # unknown names and indices, other systems: no answer, counted
    assert server.handle(wire(m.MAVLink_param_request_read_message(1, 1, b"NOPE", -1)))[0] == []
    assert server.handle(wire(m.MAVLink_param_request_read_message(1, 1, b"", n)))[0] == []
    assert server.handle(wire(m.MAVLink_param_request_list_message(2, 1)))[0] == []
    assert server.counters == {"param_list": 1, "param_read_only": 1, "param_set": 1, "param_rejected": 1,
                               "param_unknown": 2}


# --- telemetry encoders ------------------------------------------------------------------------


def test_global_position_known_answer():
    s = _status()
    g = wire(gt.encode_global_position(s, HOME))
    lat, lon, alt = FRAME.to_geodetic(s.p_ned_m)
    assert (g.lat, g.lon, g.alt) == (round(lat * 1e7), round(lon * 1e7), round(alt * 1000))
    assert g.relative_alt == 20_000  # 20 m above the home on the ground (down = 0)
    assert (g.vx, g.vy, g.vz) == (150, -25, 50)  # cm/s, NED
    assert g.hdg == 9000 and g.time_boot_ms == 12_340
    west_q = euler_to_quaternion(0, 0, -math.pi / 2)
    west = wire(gt.encode_global_position(_status(q_ned_frd=west_q), HOME))
    assert west.hdg == 27000  # -90° is 270°, never negative
    fast = wire(gt.encode_global_position(_status(v_ned_m_s=np.array([400.0, 0, 0])), HOME))
    assert fast.vx == 32767  # clamped to int16, not wrapped


def test_attitude_local_position_vfr_hud_home_origin():
    s = _status()
    a = wire(gt.encode_attitude_euler(s))
    assert a.yaw == pytest.approx(math.pi / 2) and a.roll == pytest.approx(0.0, abs=1e-7)
    assert (a.rollspeed, a.pitchspeed, a.yawspeed) == pytest.approx((0.01, -0.02, 0.03))
    q = wire(gt.encode_attitude_quaternion(s))
    assert [q.q1, q.q2, q.q3, q.q4] == pytest.approx(list(s.q_ned_frd)) and list(q.repr_offset_q) == [0.0] * 4
    lp = wire(gt.encode_local_position(s))
    assert (lp.x, lp.y, lp.z, lp.vz) == (105.0, 47.0, -20.0, 0.5)
    hud = wire(gt.encode_vfr_hud(s, HOME))
    assert hud.groundspeed == pytest.approx(math.hypot(1.5, 0.25)) and hud.airspeed == hud.groundspeed
    assert (hud.heading, hud.throttle, hud.climb) == (90, 50, -0.5)
    assert hud.alt == pytest.approx(FRAME.to_geodetic(s.p_ned_m)[2], abs=1e-5)  # MSL (≈ 35 + 20 m)
    home = wire(gt.encode_home_position(HOME, 5))
    lat, lon, alt = FRAME.to_geodetic(HOME.home_ned_m)
    assert (home.latitude, home.longitude, home.altitude) == (round(lat * 1e7), round(lon * 1e7), 35_000)
    assert (home.x, home.y, home.z) == (5.0, 47.0, 0.0) and list(home.q) == [1.0, 0.0, 0.0, 0.0]
    origin = wire(gt.encode_gps_global_origin(HOME, 5))
    assert (origin.latitude, origin.longitude, origin.altitude) == (525_200_000, 134_050_000, 35_000)


def test_sys_status_health_follows_gnss_and_estimate():
    gps, xy = m.MAV_SYS_STATUS_SENSOR_GPS, m.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
    ok = wire(gt.encode_sys_status(_status(), 0))
    assert ok.onboard_control_sensors_health == ok.onboard_control_sensors_present == gt.SENSORS_PRESENT
    assert not ok.onboard_control_sensors_present & m.MAV_SYS_STATUS_SENSOR_3D_MAG  # not simulated
    assert (ok.voltage_battery, ok.current_battery, ok.battery_remaining) == (65535, -1, -1)  # not sent
    no_gps = wire(gt.encode_sys_status(_status(gnss_ok=False), 0)).onboard_control_sensors_health
    assert not no_gps & gps and no_gps & xy
    lost = wire(gt.encode_sys_status(_status(estimate_ok=False), 0)).onboard_control_sensors_health
    assert lost & gps and not lost & xy and not lost & m.MAV_SYS_STATUS_PREARM_CHECK


# --- the link over UDP ------------------------------------------------------------------------


def _command(command: int, *params: float, target_system: int = 1):
    padded = [*params, *[0.0] * (7 - len(params))]
    return m.MAVLink_command_long_message(target_system, 1, command, 0, *padded)


class _Client:
    """A ground station socket speaking MAVLink 2 as system 255, component 190."""

    def __init__(self, bind_port: int = 0) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", bind_port))
        self.sock.settimeout(2.0)
        self.mav = codec.new_link(255, 190)

    @property
    def port(self) -> int:
        return self.sock.getsockname()[1]

    def send(self, msg, port: int) -> None:
        self.sock.sendto(codec.pack(self.mav, msg), ("127.0.0.1", port))

    def receive(self, want: int = 100_000, quiet_s: float = 0.3):
        """Messages until ``want`` arrived or none came for ``quiet_s`` (everything sent on
        loopback is already queued when this is called)."""
        msgs: list = []
        self.sock.settimeout(quiet_s)
        try:
            while len(msgs) < want:
                msgs += self.mav.parse_buffer(self.sock.recv(65535)) or []
        except TimeoutError:
            pass
        return msgs

    def close(self) -> None:
        self.sock.close()


@pytest.fixture
def ground():
    listener = _Client()  # a udpin ground station (QGroundControl on 14550, here a free port)
    dead = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    dead.bind(("127.0.0.1", 0))
    dead_port = dead.getsockname()[1]
    dead.close()  # nobody listens there: sends to it must not break the others
    clock = [7_000]
    link = GroundLink(GroundConfig(0, (("127.0.0.1", dead_port), ("127.0.0.1", listener.port))), {},
                      _server(), HOME, lambda: clock[0])
    yield link, listener
    link.close()
    listener.close()


def test_udpin_target_and_udpout_client_both_receive_the_scheduled_telemetry(ground):
    link, listener = ground
    client = _Client()
    try:
        client.send(m.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3), link.link.port)  # udpout: talks first
        link.link.recv_all()
        link.tick(_status(t_us=0))
        link.tick(_status(t_us=50_000))  # within every period: nothing new
        got = listener.receive(want=12)
        kinds = [x.get_type() for x in got]
        assert sorted(kinds) == sorted([
            "HEARTBEAT", "SYS_STATUS", "EXTENDED_SYS_STATE", "GLOBAL_POSITION_INT", "LOCAL_POSITION_NED",
            "ATTITUDE", "ATTITUDE_QUATERNION", "VFR_HUD", "HOME_POSITION", "GPS_GLOBAL_ORIGIN",
            "STATUSTEXT", "STATUSTEXT"])
        texts = [t.text for t in got if t.get_type() == "STATUSTEXT"]
        assert texts == ["Estimator OK: following setpoints", "GNSS OK"]
        same = [x.get_msgbuf() for x in client.receive(want=12)]
        assert same == [x.get_msgbuf() for x in got]  # the same frames (one sequence number each)
        link.tick(_status(t_us=100_000))  # the 10 Hz streams again
        assert sorted(x.get_type() for x in listener.receive()) == [
            "ATTITUDE", "ATTITUDE_QUATERNION", "GLOBAL_POSITION_INT", "LOCAL_POSITION_NED"]
    finally:
        client.close()


def test_a_signed_ground_link_signs_its_own_telemetry_too():
    """With a key every frame the vehicle sends to a ground station is signed, its own telemetry as
    well as what it answers: a pymavlink client holding the key (as the ground station docs show)
    reads them all, and nothing arrives unsigned."""
    import time

    key = b"k" * 32
    client = _Client()
    client.mav.signing.secret_key = key
    client.mav.signing.sign_outgoing = True
    client.mav.signing.timestamp = int((time.time() - 1_420_070_400) * 100_000)
    link = GroundLink(GroundConfig(0, ()), {"signing_key": key}, _server(), HOME, lambda: 7_000)
    try:
        client.send(m.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3), link.link.port)  # udpout: talks first
        assert [x.get_type() for x in link.link.recv_all()] == ["HEARTBEAT"]  # signed: accepted
        link.tick(_status(t_us=0))
        got = client.receive(want=12)
        assert len(got) == 12 and "BAD_DATA" not in [x.get_type() for x in got]
        assert all(x.get_signed() for x in got)
        assert client.mav.signing.goodsig_count == 12 and client.mav.signing.unsigned_count == 0
    finally:
        link.close()
        client.close()


def test_requests_are_answered_to_the_requester(ground):
    link, listener = ground
    port = link.link.port
    c = listener  # a udpin station replies to the ground port too
    c.send(_command(m.MAV_CMD_REQUEST_MESSAGE, m.MAVLINK_MSG_ID_AUTOPILOT_VERSION), port)
    c.send(_command(m.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 10), port)
    c.send(_command(m.MAV_CMD_COMPONENT_ARM_DISARM, 0), port)
    c.send(_command(m.MAV_CMD_COMPONENT_ARM_DISARM, 0, target_system=7), port)
    c.send(m.MAVLink_timesync_message(0, 42), port)
    c.send(m.MAVLink_ping_message(99, 3, 0, 0), port)
    for msg in link.link.recv_all():
        link.handle(msg)
    got = c.receive(want=6)
    acks = [(a.command, a.result, a.target_system, a.target_component)
            for a in got if a.get_type() == "COMMAND_ACK"]
    assert acks == [(m.MAV_CMD_REQUEST_MESSAGE, m.MAV_RESULT_ACCEPTED, 255, 190),
                    (m.MAV_CMD_NAV_TAKEOFF, m.MAV_RESULT_UNSUPPORTED, 255, 190),
                    (m.MAV_CMD_COMPONENT_ARM_DISARM, m.MAV_RESULT_DENIED, 255, 190)]  # system 7's is not ours
    kinds = [x.get_type() for x in got]
    assert kinds.index("AUTOPILOT_VERSION") == kinds.index("COMMAND_ACK") + 1  # after its ACK
    sync = next(x for x in got if x.get_type() == "TIMESYNC")
    assert (sync.tc1, sync.ts1) == (7_000, 42)
    ping = next(x for x in got if x.get_type() == "PING")
    assert (ping.time_usec, ping.seq, ping.target_system, ping.target_component) == (99, 3, 255, 190)
    assert link.counters["command_not_for_us"] == 1


def test_set_message_interval_and_forwarded_frames(ground):
    link, listener = ground
    port = link.link.port
    gpi = m.MAVLINK_MSG_ID_GLOBAL_POSITION_INT
    listener.send(_command(m.MAV_CMD_SET_MESSAGE_INTERVAL, gpi, -1), port)
    listener.send(_command(m.MAV_CMD_SET_MESSAGE_INTERVAL, m.MAVLINK_MSG_ID_VFR_HUD, 1_000_000), port)
    for msg in link.link.recv_all():
        link.handle(msg)
    assert [a.result for a in listener.receive(want=2)] == [m.MAV_RESULT_ACCEPTED] * 2
    for k in range(21):  # one simulated second of control periods
        link.tick(_status(t_us=k * 50_000))
    kinds = [x.get_type() for x in listener.receive()]
    assert kinds.count("GLOBAL_POSITION_INT") == 0 and kinds.count("VFR_HUD") == 2  # t = 0 and t = 1 s
    assert kinds.count("ATTITUDE") == 11
    companion = codec.pack(codec.new_link(1, 197), codec.encode_named_value(5_000, "GNSS_BETA", 0.5))
    link.forward(companion)
    assert listener.sock.recv(65535) == companion  # byte for byte: ids, sequence number kept


def test_parse_ground_out():
    assert parse_ground_out("127.0.0.1:14550") == ("127.0.0.1", 14550)
    assert parse_ground_out("14551") == ("127.0.0.1", 14551)
    from companion.errors import UserError

    for bad in ("localhost:0", "x:y", "1.2.3.4:70000"):
        with pytest.raises(UserError, match="--ground-out"):
            parse_ground_out(bad)


def test_vehicle_status_of_a_hovering_simvehicle():
    from companion.mission import load_mission
    from simvehicle import SimVehicle
    from simvehicle.groundlink import vehicle_status

    sim = SimVehicle(load_mission("test"), 0, seed=3)
    for _ in range(20):  # one second without an estimate: the autopilot holds its start point
        out = sim.advance(None, None)
    s = vehicle_status(sim, out, gnss_ok=True)
    vehicle = sim.config.vehicle
    hover = vehicle.mass_kg * vehicle.gravity_m_s2 / vehicle.max_thrust_n  # 0.5: thrust-to-weight 2
    assert s.thrust_fraction == pytest.approx(hover, abs=0.03)
    assert (s.mode, s.estimate_ok, s.armed, s.t_us) == ("HOLD", False, True, 1_000_000)
    np.testing.assert_allclose(s.p_ned_m, sim.start_ned_m, atol=0.5)
    np.testing.assert_array_equal(s.q_ned_frd, out.q_ned_frd[-1])


def test_bad_ground_out_is_one_line_before_anything_starts(tmp_path, capsys):
    from gcs_tools.cli import main

    out = tmp_path / "run"
    argv = ["sitl", "--mission", "test", "--out", str(out), "--no-telemetry", "--ground-out", "x:y"]
    assert main(argv) == 2
    assert capsys.readouterr().err.strip() == "beliefnav: error: --ground-out: expected HOST:PORT, got 'x:y'"
    assert not out.exists()
