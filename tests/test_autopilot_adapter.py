"""The foreign-autopilot adapter's pure parts: connection strings, discovery, time base, TIMESYNC,
feeds, comparison — known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from companion.autopilot import compare, feeds
from companion.autopilot.connection import Endpoint, parse_connection
from companion.autopilot.discovery import Discovery, DiscoveryConfig
from companion.autopilot.streams import StreamRates, data_stream_requests, interval_requests
from companion.autopilot.timesync import Timesync
from companion.autopilot.translate import TranslateConfig, Translator
from companion.domain.geodesy import LocalNedFrame
from companion.domain.rotation import euler_to_quaternion
from companion.domain.samples import AttitudeSample, GnssFix, ImuSample, NavEstimate
from companion.errors import UserError

HOME = LocalNedFrame(-35.363261, 149.165230, 584.0)


@pytest.mark.parametrize(("text", "expected"), [
    ("tcp:127.0.0.1:5760", Endpoint("tcp", "127.0.0.1", 5760)),
    ("tcp://10.0.0.2:5762", Endpoint("tcp", "10.0.0.2", 5762)),
    ("udpin::14550", Endpoint("udpin", "127.0.0.1", 14550)),
    ("udp://:14540", Endpoint("udpin", "127.0.0.1", 14540)),
    ("udpin:0.0.0.0:14550", Endpoint("udpin", "0.0.0.0", 14550)),
    ("udpout:192.168.1.5:14555", Endpoint("udpout", "192.168.1.5", 14555)),
    ("serial:/dev/ttyACM0:921600", Endpoint("serial", device="/dev/ttyACM0", baud=921600)),
    ("serial:///dev/ttyUSB1:57600", Endpoint("serial", device="/dev/ttyUSB1", baud=57600)),
])
def test_connection_strings(text, expected):
    assert parse_connection(text) == expected


@pytest.mark.parametrize(("text", "why"), [
    ("127.0.0.1:5760", "expected tcp"), ("tcp:localhost", "missing :PORT"), ("tcp:h:99999", "out of range"),
    ("udpout::14550", "needs the host"), ("serial:/dev/ttyACM0:fast", "not a number"),
    ("serial::57600", "serial device"), ("zmq:h:1", "expected tcp"),
])
def test_bad_connection_strings_are_one_line_errors(text, why):
    with pytest.raises(UserError, match=why):
        parse_connection(text)


def _from(msg, system, component):
    msg.pack(mavlink.MAVLink(None, srcSystem=system, srcComponent=component))
    return msg


QUAD = mavlink.MAV_TYPE_QUADROTOR


def _hb(autopilot=mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, vehicle=QUAD):
    return mavlink.MAVLink_heartbeat_message(vehicle, autopilot, 0, 0, 0, 3)


def test_discovery_elects_the_autopilot_the_link_carries_not_the_first_heartbeat():
    """A forged HEARTBEAT first (system 42), then the real autopilot's stream: the real one wins
    after the election window, 42 is an alarm (reported once), never used."""
    d = Discovery()
    gcs = mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3)
    assert not d.accept(_from(gcs, 255, 190), 0.0)  # a ground station is not an autopilot
    assert not d.accept(_from(_hb(), 42, 1), 0.0)  # the forged one comes first: nothing chosen yet
    imu = mavlink.MAVLink_highres_imu_message(1_000_000, 0, 0, -9.8, *[0] * 10, 0b111111, 0)
    assert not d.accept(_from(_hb(), 7, 1), 0.1)
    for k in range(20):
        assert not d.accept(_from(imu, 7, 1), 0.2 + k * 0.05)
    assert not d.accept(_from(_hb(), 42, 1), 1.0)  # 42 qualifies too (2 HEARTBEATs) but carries nothing
    assert d.accept(_from(_hb(), 7, 1), 1.6)  # the window is over: the stream's autopilot
    assert d.autopilot is not None and (d.autopilot.system_id, d.autopilot.component_id) == (7, 1)
    assert d.autopilot.as_dict()["autopilot"] == "MAV_AUTOPILOT_ARDUPILOTMEGA"
    assert len(d.alarms) == 1 and "system 42" in d.alarms[0]
    assert not d.accept(_from(_hb(mavlink.MAV_AUTOPILOT_PX4), 42, 1), 2.0)  # never a switch
    assert not d.accept(_from(_hb(mavlink.MAV_AUTOPILOT_PX4), 42, 1), 3.0)
    assert d.counters["conflicting_autopilot"] == 2 and len(d.alarms) == 1  # counted, reported once
    assert not d.accept(_from(_hb(), 7, 154), 2.5)  # a gimbal of the same system
    assert d.counters["other_system"] == 2 and d.counters["other_component"] == 1
    assert not d.heartbeat_lost(4.5) and d.heartbeat_lost(4.7) and not d.given_up(16.5) and d.given_up(16.7)


def test_discovery_needs_component_1_a_vehicle_type_and_consistent_heartbeats():
    d = Discovery(DiscoveryConfig(election_s=0.0))
    assert not d.accept(_from(_hb(), 3, 154), 0.0)  # not the autopilot component
    assert not d.accept(_from(_hb(vehicle=mavlink.MAV_TYPE_ONBOARD_CONTROLLER), 3, 1), 0.1)
    assert not d.accept(_from(_hb(), 3, 1), 0.2)  # one HEARTBEAT is not enough
    assert not d.accept(_from(_hb(mavlink.MAV_AUTOPILOT_PX4), 3, 1), 0.3)  # changed: its count restarts
    assert d.autopilot is None and d.counters["inconsistent_heartbeat"] == 1
    assert d.accept(_from(_hb(mavlink.MAV_AUTOPILOT_PX4), 3, 1), 0.4)
    assert d.autopilot is not None and d.autopilot.autopilot_type == mavlink.MAV_AUTOPILOT_PX4
    assert not d.accept(_from(_hb(), 3, 1), 0.5)  # a HEARTBEAT of it saying ArduPilot now: not believed
    assert d.last_heartbeat_s == 0.4 and d.counters["inconsistent_heartbeat"] == 2 and len(d.alarms) == 1


def test_a_streaming_autopilot_is_chosen_at_once_unless_another_is_close():
    imu = mavlink.MAVLink_highres_imu_message(1_000_000, 0, 0, -9.8, *[0] * 10, 0b111111, 0)

    def elect(rival_frames: int) -> float | None:
        d = Discovery()
        for k in range(rival_frames):
            d.accept(_from(_hb() if k < 2 else imu, 42, 1), 0.001 * k)
        for k in range(300):  # a SITL at x10: HEARTBEATs every 0.1 s and its streams, 0.3 s
            t = 0.1 + 0.001 * k
            if d.accept(_from(_hb() if k % 100 == 0 else imu, 7, 1), t):
                return t
        return None

    # 100 frames and 3 HEARTBEATs: decided 0.25 s after its first; 2 forged frames (a burst: one
    # HEARTBEAT) are beaten 10x just the same
    assert elect(0) == pytest.approx(0.35, abs=0.002) and elect(2) == pytest.approx(0.35, abs=0.002)
    assert elect(50) is None  # a rival with 50 frames: the window (1.5 s) decides

    burst = Discovery()  # a forged burst before the autopilot's first frame decides nothing
    assert not any(burst.accept(_from(_hb(), 42, 1), 0.0) for _ in range(10))
    assert burst.autopilot is None and burst._candidates[(42, 1)].heartbeats == 1


def test_target_system_pins_the_autopilot_and_other_vehicles_are_only_counted():
    d = Discovery(DiscoveryConfig(target_system=5, election_s=0.0))
    for t in (0.0, 0.1, 0.2):
        assert not d.accept(_from(_hb(), 4, 1), t)  # a busier vehicle: never a candidate
    assert not d.accept(_from(_hb(), 5, 1), 0.3)
    assert d.accept(_from(_hb(), 5, 1), 0.4) and d.autopilot is not None and d.autopilot.system_id == 5
    pinned = Discovery(DiscoveryConfig(target_system=5))  # the default window: no wait when pinned
    assert not pinned.accept(_from(_hb(), 5, 1), 0.0) and pinned.accept(_from(_hb(), 5, 1), 0.1)
    assert not d.accept(_from(_hb(), 4, 1), 0.5)
    assert d.alarms == [] and d.counters["conflicting_autopilot"] == 0  # a swarm: expected
    with pytest.raises(ValueError):
        DiscoveryConfig(target_system=0)


def test_stream_requests_ask_each_message_by_interval_then_legacy_groups():
    reqs = interval_requests(7, 1, StreamRates(imu_hz=100, gnss_hz=5), gnss_instance=2)
    by_id = {int(r.param1): r.param2 for r in reqs}
    assert all(r.command == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL and r.target_system == 7 for r in reqs)
    assert by_id[mavlink.MAVLINK_MSG_ID_HIGHRES_IMU] == 10_000
    assert by_id[mavlink.MAVLINK_MSG_ID_GPS2_RAW] == 200_000
    assert mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN in by_id and mavlink.MAVLINK_MSG_ID_SYSTEM_TIME in by_id
    legacy = data_stream_requests(7, 1, StreamRates())
    groups = {r.req_stream_id: r.req_message_rate for r in legacy}
    assert groups[mavlink.MAV_DATA_STREAM_RAW_SENSORS] == 50 and all(r.start_stop == 1 for r in legacy)


def _gps(time_usec, lat=-353632610, fix=3):
    return mavlink.MAVLink_gps_raw_int_message(time_usec, fix, lat, 1491652300, 584_000, 80, 120, 0, 0, 10)


def test_translator_one_time_base_receiver_delay_repeats_and_unix_stamps():
    tr = Translator(TranslateConfig(gnss_delay_us=100_000))
    fix = tr.sample(_gps(20_000_000))
    assert isinstance(fix, GnssFix) and fix.t_validity_us == 19_900_000 and fix.hdop == 0.8
    assert tr.sample(_gps(20_000_000)) is None and tr.counters["gnss_repeated"] == 1
    assert tr.sample(_gps(0, fix=1)) is None and tr.counters["gnss_no_stamp"] == 1
    unix_us = 1_700_000_000_000_000
    assert tr.sample(_gps(unix_us + 30_000_000)) is None and tr.counters["gnss_no_time_base"] == 1
    tr.system_time(mavlink.MAVLink_system_time_message(unix_us + 25_000_000, 25_000))  # boot 25 s
    fix = tr.sample(_gps(unix_us + 31_000_000))
    assert fix is not None and fix.t_validity_us == 31_000_000 - 100_000


def test_translator_gnss_carries_the_receiver_velocity_and_reads_gps_input_when_told():
    fix = Translator(TranslateConfig(gnss_delay_us=0)).sample(_gps(20_000_000))
    assert fix is not None and fix.v_ned_m_s is not None and math.isnan(fix.v_ned_m_s[2])  # no vertical
    gi = mavlink.MAVLink_gps_input_message(7_000_000, 0, 0, 0, 0, 3, 10_000_000, 20_000_000, 31.5, 0.8, 1.1,
                                           1.5, -2.0, 0.4, 0.35, 2.5, 4.0, 12, 0)
    assert Translator(TranslateConfig(gnss_delay_us=0)).sample(gi) is None  # not the configured source
    told = Translator(TranslateConfig(gnss_delay_us=0, gnss_message="GPS_INPUT"))
    f = told.sample(gi)
    assert f is not None and f.t_validity_us == 7_000_000
    np.testing.assert_allclose(f.v_ned_m_s, (1.5, -2.0, 0.4), rtol=1e-6)
    with pytest.raises(ValueError, match="gnss_message"):
        Translator(TranslateConfig(gnss_message="GPS_BOGUS"))


def test_system_time_is_range_checked_and_a_lone_jump_is_not_believed():
    tr = Translator()
    unix_us = 1_700_000_000_000_000

    def pair(unix_s: float, boot_s: float) -> None:
        msg = mavlink.MAVLink_system_time_message(unix_us + round(unix_s * 1e6), round(boot_s * 1000))
        tr.system_time(msg)

    pair(10.0, 10.0)
    assert tr.unix_minus_boot_us == unix_us
    tr.system_time(mavlink.MAVLink_system_time_message(2**63 - 1, 11_000))  # spoofed: 2^63
    pair(3611.0, 11.0)  # a lone pair one hour ahead
    pair(5.0, 11.0)  # ... or 6 s back
    assert tr.unix_minus_boot_us == unix_us
    assert tr.counters["rejected_system_time_range"] == 1 and tr.counters["rejected_system_time_clock"] == 2
    for k in range(5):  # a SITL at x5: its boot time runs 5x its UNIX clock (wall): the offset drifts
        pair(11.0 + k, 15.0 + 5 * k)
    assert tr.unix_minus_boot_us == unix_us + 15_000_000 - 35_000_000
    pair(18.0, 36.0)  # UNIX time running faster than boot time (3 s in 1 s): not a clock
    assert tr.counters["rejected_system_time_clock"] == 3
    for k in range(3):  # the clock really was set: three agreeing pairs over 2 s of boot time
        pair(100.0 + k, 40.0 + k)
    assert tr.unix_minus_boot_us == unix_us + 60_000_000 and tr.counters["system_time_clock_set"] == 1


def test_translator_units_and_source_ranking():
    tr = Translator()
    raw = mavlink.MAVLink_raw_imu_message(5_000_000, 0, 0, -1000, 10, 0, -20, 0, 0, 0)
    s = tr.sample(raw)  # ArduPilot RAW_IMU: mG and mrad/s
    assert isinstance(s, ImuSample) and s.t_us == 5_000_000
    np.testing.assert_allclose(s.acc_frd_m_s2, (0, 0, -9.80665))
    np.testing.assert_allclose(s.gyro_frd_rad_s, (0.01, 0, -0.02))
    hr = mavlink.MAVLink_highres_imu_message(5_020_000, 0.1, 0, -9.8, *[0] * 10, 0b111111, 0)
    assert isinstance(tr.sample(hr), ImuSample)
    assert tr.sample(raw) is None and tr.counters["imu_other_source"] == 1  # HIGHRES_IMU ranks first now
    att = mavlink.MAVLink_attitude_message(5_000, 0.0, 0.0, math.pi / 2, 0, 0, 0)
    a = tr.sample(att)
    assert a is not None and a.t_us == 5_000_000
    np.testing.assert_allclose(a.q_ned_frd, euler_to_quaternion(0, 0, math.pi / 2), atol=1e-7)


def test_timesync_answers_requests_and_estimates_the_offset_exactly():
    ts = Timesync()
    req = mavlink.MAVLink_timesync_message(tc1=0, ts1=123)
    answer = ts.handle(req, now_ns=5_000)
    # answered on the autopilot's boot time (the base of every stamp we send it), not our clock
    assert answer is not None and (answer.tc1, answer.ts1) == (123, 123)
    remote_minus_local = 7_000_000_000
    ours = ts.request(now_ns=1_000_000)
    # the remote clock reads local + offset when it answers, 300 µs after, and we get it 300 µs later
    reply = mavlink.MAVLink_timesync_message(tc1=1_300_000 + remote_minus_local, ts1=ours.ts1)
    assert ts.handle(reply, now_ns=1_600_000) is None
    assert ts.offset_ns == remote_minus_local and ts.rtt_ns == 600_000
    stranger = mavlink.MAVLink_timesync_message(tc1=99, ts1=42)
    assert ts.handle(stranger, now_ns=2_000_000) is None and ts.counters["responses_not_ours"] == 1


def _estimate(p, v=(0.0, 0.0, 0.0), var=(0.04, 0.05, 0.09, 0.01, 0.01, 0.02, 0.1, 0.1, 0.1), beta=0.9):
    return NavEstimate(t_us=12_000_000, p_ned_m=np.array(p, float), v_ned_m_s=np.array(v, float),
                       b_ned_m=np.zeros(3), cov_diag=np.array(var), beta=beta, nis=1.0, method="second-order")


def test_gps_input_is_the_filter_position_with_covariance_accuracy():
    e = _estimate((10.0, -5.0, -20.0), v=(1.0, 2.0, -0.5))
    msg = feeds.gps_input(e, HOME, feeds.FeedConfig(), hdop=0.9, satellites=12, unix_s=1_700_000_000.0)
    back = HOME.to_ned_m(msg.lat / 1e7, msg.lon / 1e7, msg.alt)
    np.testing.assert_allclose(back, e.p_ned_m, atol=0.01)  # degE7 = 1 cm resolution
    assert msg.fix_type == 3 and msg.satellites_visible == 12 and msg.hdop == pytest.approx(0.9)
    assert msg.horiz_accuracy == pytest.approx(math.sqrt(0.09)) and msg.vert_accuracy == pytest.approx(0.3)
    assert msg.speed_accuracy == pytest.approx(math.sqrt(0.04))
    assert (msg.vn, msg.ve, msg.vd) == (1.0, 2.0, -0.5) and msg.ignore_flags == 0
    assert (msg.time_week, msg.time_week_ms) == (2288, 252_818_000)  # 2023-11-14 22:13:20 UTC + 18 leap s
    from dataclasses import replace

    stale = feeds.gps_input(replace(e, pos_valid=False), HOME, feeds.FeedConfig())
    assert stale.fix_type == 0 and stale.horiz_accuracy == 0.0 and stale.satellites_visible == 0  # no fix


def test_odometry_in_the_frames_ardupilot_fuses_velocity_in_body_frd():
    q = euler_to_quaternion(0.0, 0.0, math.pi / 2)  # nose east
    config = feeds.FeedConfig()
    msg = feeds.odometry(_estimate((1.0, 2.0, -3.0), v=(0.0, 4.0, 0.0)), q, np.array((0.0, 0.0, 0.1)), config)
    assert (msg.frame_id, msg.child_frame_id) == (mavlink.MAV_FRAME_LOCAL_FRD, mavlink.MAV_FRAME_BODY_FRD)
    assert msg.estimator_type == mavlink.MAV_ESTIMATOR_TYPE_VIO and msg.quality == 90
    np.testing.assert_allclose((msg.vx, msg.vy, msg.vz), (4.0, 0.0, 0.0), atol=1e-6)  # flying forward
    assert (msg.x, msg.y, msg.z) == (1.0, 2.0, -3.0) and msg.pose_covariance[0] == pytest.approx(0.04)
    assert msg.velocity_covariance[11] == pytest.approx(0.02)
    assert msg.pose_covariance[15] == pytest.approx(config.attitude_sigma_rad**2)
    vis = feeds.vision_position(_estimate((1.0, 2.0, -3.0)), q, config)
    assert vis.yaw == pytest.approx(math.pi / 2) and vis.covariance[6] == pytest.approx(0.05)
    for cov in (msg.pose_covariance, msg.velocity_covariance, vis.covariance):  # ArduPilot: NaN = error
        assert all(math.isfinite(c) for c in cov) and sum(c != 0 for c in cov) == 6


def test_compare_known_offset_and_fitted_translation():
    t = np.arange(0, 10_000_000, 40_000, dtype=np.int64)
    p = np.column_stack((t * 1e-6, np.zeros_like(t, float), np.zeros_like(t, float)))  # 1 m/s north
    ref_t = np.arange(20_000, 9_000_000, 100_000, dtype=np.int64)
    ref = np.column_stack((ref_t * 1e-6 + 0.3, np.full(ref_t.size, 0.4), np.full(ref_t.size, 1.2)))
    r = compare.compare(t, p, ref_t, ref)
    assert r["error_horizontal_m"]["median"] == pytest.approx(0.5)  # interpolation exact on a line
    assert r["error_3d_m"]["max"] == pytest.approx(1.3) and r["error_3d_m"]["count"] == ref_t.size
    fitted = compare.compare(t, p, ref_t, ref, fit_translation=True)
    assert fitted["error_3d_m"]["max"] == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose(fitted["fitted_translation_ned_m"], (-0.3, -0.4, -1.2))
    gap_t = np.concatenate((t[:10], t[-10:]))  # a 9 s hole: nothing compared inside it
    assert compare.compare(gap_t, p[np.r_[:10, -10:0]], ref_t, ref)["error_3d_m"]["count"] < 10


class _FakeConn:
    """Stands in for MavConnection: records what the node sends."""

    def __init__(self) -> None:
        self.sent: list = []
        self.counters: dict = {}
        self.source = (0, 0)

    def send(self, msg) -> bool:
        self.sent.append(msg)
        return True

    def note_peer(self, msg, now_s) -> None:
        pass

    def arrival_us(self, msg) -> None:
        return None

    def set_source(self, system_id: int, component_id: int) -> None:
        self.source = (system_id, component_id)

    def kinds(self) -> list[str]:
        kinds = [m.get_type() for m in self.sent]
        self.sent.clear()
        return kinds


def test_node_streams_state_machine_fallback_and_reask(tmp_path):
    from companion.autopilot.node import AutopilotCompanion, CompanionConfig

    conn = _FakeConn()
    node = AutopilotCompanion(CompanionConfig(master="udpin::14550", out_dir=tmp_path), conn)  # type: ignore[arg-type]
    node.tick(0.0)
    assert conn.kinds() == []  # nothing before discovery
    hb = mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, 0, 0, 0, 3)
    node.handle(_from(hb, 3, 1), -2.0)
    assert conn.source == (0, 0)  # one HEARTBEAT: not yet
    node.handle(_from(hb, 3, 1), 0.0)
    assert conn.source == (3, 197)
    node.tick(0.0)
    first = conn.kinds()
    assert first.count("COMMAND_LONG") == 8 and "HEARTBEAT" in first and "TIMESYNC" in first
    assert "PARAM_REQUEST_READ" in first  # EKF2_GPS_DELAY
    node.tick(2.0)
    assert "REQUEST_DATA_STREAM" not in conn.kinds()
    node.tick(3.5)  # no IMU 3 s after asking: the legacy groups too
    assert conn.kinds().count("REQUEST_DATA_STREAM") == 4
    node.tick(4.0)
    assert "REQUEST_DATA_STREAM" not in conn.kinds()  # once
    node.handle(_from(hb, 3, 1), 6.4)
    imu = mavlink.MAVLink_highres_imu_message(1_000_000, 0, 0, -9.8, *[0] * 10, 0b111111, 0)
    node.handle(_from(imu, 3, 1), 6.5)  # no fix yet: counted, the stream is alive all the same
    node.tick(6.6)
    assert "COMMAND_LONG" in conn.kinds()  # still no IMU used after 3 s of silence: asked again
    assert node.counters["samples_before_first_fix"] == 1 and node.counters["stream_requests"] == 2


def test_sitl_estimator_answers_timesync_per_spec_unless_step_markers(tmp_path):
    """The estimator of ``beliefnav sitl`` treats a TIMESYNC request as a lockstep step marker only
    with ``--step-markers``; otherwise (a real autopilot, MAVSDK, ...) it just answers it."""
    from companion.mavlink.lockstep import step_marker
    from companion.mission import load_mission
    from companion.nodes.estimator_node import EstimatorNode, make_navigator

    class Link:
        sent: list = []
        last_rx_ns = 0

        def send(self, msg) -> None:
            self.sent.append(msg)

    mission = load_mission("test")
    navigator, gate = make_navigator(mission, "second-order")
    level, rest = np.array((1.0, 0.0, 0.0, 0.0)), np.array((0.0, 0.0, -9.80665))
    home = mission.frame
    for t_us in range(1_000_000, 1_300_000, 5_000):  # an initialised estimate to answer with
        navigator.push(AttitudeSample(t_us, level))
        navigator.push(ImuSample(t_us, rest, np.zeros(3)))
        if t_us == 1_100_000:
            navigator.push(GnssFix(t_us, home.home_lat_deg, home.home_lon_deg, home.home_alt_m, 3, 10))
    assert navigator.estimate() is not None
    for step_markers in (False, True):
        link = Link()
        link.sent = []
        node = EstimatorNode(link, navigator, gate, step_markers=step_markers)  # type: ignore[arg-type]
        node.handle(step_marker(1_250_000))
        kinds = [m.get_type() for m in link.sent]
        assert kinds == (["ODOMETRY", "TIMESYNC"] if step_markers else ["TIMESYNC"])
        assert link.sent[-1].ts1 == 1_250_000_000 and link.sent[-1].tc1 > 0
        assert node.counters == ({"step_markers": 1} if step_markers else {"timesync_answered": 1})


def _heartbeat_frame(system_id: int) -> bytes:
    link = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=1)
    return bytes(mavlink.MAVLink_heartbeat_message(2, 3, 0, 0, 0, 3).pack(link))


def test_udpout_connection_both_ways_recorded_in_the_tlog(tmp_path):
    import socket

    from companion.autopilot.connection import open_connection
    from companion.mavlink.tlog import read_tlog

    peer = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    peer.bind(("127.0.0.1", 0))
    peer.settimeout(5)
    conn = open_connection(f"udpout:127.0.0.1:{peer.getsockname()[1]}", 1, 197, tmp_path / "run.tlog")
    try:
        conn.send(mavlink.MAVLink_timesync_message(0, 5))
        data, ours = peer.recvfrom(512)
        peer.sendto(_heartbeat_frame(7) + b"\x00junk", ours)
        got = []
        for _ in range(50):
            got += conn.recv(0.05)
            if got:
                break
    finally:
        conn.close()
        assert conn.tlog is not None
        conn.tlog.close()
        peer.close()
    assert data[0] == 0xFD and [m.get_type() for m in got] == ["HEARTBEAT"] and got[0].get_srcSystem() == 7
    assert [m.get_type() for _, m in read_tlog(tmp_path / "run.tlog")] == ["TIMESYNC", "HEARTBEAT"]
    assert conn.counters["sent"] == 1 and conn.counters["received"] == 1


def test_serial_connection_reads_a_pseudo_terminal(tmp_path):
    """``serial:DEVICE:BAUD`` through pymavlink/pyserial, on a pty pair (no hardware needed)."""
    import os

    from companion.autopilot.connection import open_connection

    controller, device = os.openpty()
    conn = open_connection(f"serial:{os.ttyname(device)}:921600", 1, 197, None)
    try:
        os.write(controller, _heartbeat_frame(3))
        got = []
        for _ in range(50):
            got += conn.recv(0.05)
            if got:
                break
        conn.send(mavlink.MAVLink_timesync_message(0, 9))
        echoed = os.read(controller, 512)
    finally:
        conn.close()
        os.close(controller)
        os.close(device)
    assert [m.get_type() for m in got] == ["HEARTBEAT"] and got[0].get_srcSystem() == 3
    assert echoed[0] == 0xFD and echoed[7:10] == bytes((111, 0, 0))  # TIMESYNC, msgid 111


def test_node_counts_implausible_and_broken_messages_and_never_raises(tmp_path):
    from companion.autopilot.node import AutopilotCompanion, CompanionConfig

    conn = _FakeConn()
    node = AutopilotCompanion(CompanionConfig(master="udpin::14550", out_dir=tmp_path), conn)  # type: ignore[arg-type]
    _discover(node, 3, mavlink.MAV_AUTOPILOT_PX4)
    node.handle(_from(mavlink.MAVLink_gps_global_origin_message(950_000_000, 0, 0, 0), 3, 1), 2.1)
    node.handle(_from(mavlink.MAVLink_local_position_ned_message(1000, math.nan, 0, 0, 0, 0, 0), 3, 1), 2.1)

    class Broken:  # a SYSTEM_TIME without its fields
        def get_type(self):
            return "SYSTEM_TIME"

        def get_srcSystem(self):
            return 3

        def get_srcComponent(self):
            return 1

    node.handle(Broken(), 2.2)
    node.handle(Broken(), 2.3)
    assert node.frames.origins == {} and node.comparison.local_references == 0
    assert node.frames.counters["rejected_gps_global_origin"] == 1
    assert node.counters["rejected_local_position_ned"] == 1
    assert node.counters["handler_error_SYSTEM_TIME_AttributeError"] == 2 and len(node.errors) == 1


def _discover(node, system_id: int, autopilot: int) -> None:
    """Two HEARTBEATs across the election window: ``node`` has found its autopilot at t = 2 s."""
    hb = mavlink.MAVLink_heartbeat_message(2, autopilot, 0, 0, 0, 3)
    node.handle(_from(hb, system_id, 1), 0.0)
    node.handle(_from(hb, system_id, 1), 2.0)
    assert node.discovery.autopilot is not None


def test_receiver_delay_read_from_the_autopilot_only_as_the_answer_to_our_request(tmp_path):
    from companion.autopilot.node import AutopilotCompanion, CompanionConfig

    def node_for(autopilot: int, delay_us: int | None = None):
        conn = _FakeConn()
        config = CompanionConfig(master="udpin::14550", out_dir=tmp_path,
                                 translate=TranslateConfig(gnss_delay_us=delay_us))
        node = AutopilotCompanion(config, conn)  # type: ignore[arg-type]
        _discover(node, 1, autopilot)
        node.tick(2.0)
        asked = [m.param_id for m in conn.sent if m.get_type() == "PARAM_REQUEST_READ"]
        return node, asked

    def value(name: str, v: float):
        return _from(mavlink.MAVLink_param_value_message(name.encode(), v, 9, 1000, 65535), 1, 1)

    node, asked = node_for(mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA)
    tr = node.translator
    assert asked == ["GPS1_DELAY_MS"] and tr.gnss_delay_us == 120_000  # its default until read
    node.handle(value("GPS2_DELAY_MS", 30.0), 2.1)  # not the receiver we read
    node.handle(value("GPS1_DELAY_MS", 60.0), 2.2)
    assert tr.gnss_delay_us == 60_000 and tr.gnss_delay_source == "autopilot parameter GPS1_DELAY_MS"
    node.handle(value("GPS1_DELAY_MS", 200.0), 2.3)  # answered already: a later one is not ours
    assert tr.gnss_delay_us == 60_000 and node.counters["param_value_unsolicited"] == 2
    fix = tr.sample(_gps(20_000_000))
    assert fix is not None and fix.t_validity_us == 19_940_000

    node, asked = node_for(mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA)
    node.handle(value("GPS1_DELAY_MS", 0.0), 2.1)
    assert node.translator.gnss_delay_us == 120_000 and "= 0" in node.translator.gnss_delay_source

    node, asked = node_for(mavlink.MAV_AUTOPILOT_PX4)
    assert asked == ["EKF2_GPS_DELAY"] and node.translator.gnss_delay_us == 110_000
    node.handle(value("EKF2_GPS_DELAY", 1000.0), 2.1)  # beyond its own range (0..300 ms): not believed
    assert node.translator.gnss_delay_us == 110_000 and "outside its range" in node.errors[0]
    node.tick(6.0)
    assert node.counters["param_value_unsolicited"] == 0  # and not asked again: it did answer

    conn = _FakeConn()  # no answer: asked again 3 s later, 3 times in all
    node = AutopilotCompanion(CompanionConfig(master="udpin::14550", out_dir=tmp_path), conn)  # type: ignore[arg-type]
    _discover(node, 1, mavlink.MAV_AUTOPILOT_PX4)
    for t in (2.0, 3.0, 5.1, 8.2, 11.3, 14.4):
        node.tick(t)
    assert [m.get_type() for m in conn.sent].count("PARAM_REQUEST_READ") == 3

    node, asked = node_for(mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, delay_us=0)  # --gps-delay-ms 0
    assert asked == [] and (node.translator.gnss_delay_us, node.translator.gnss_delay_source) == (0, "option")
    node, asked = node_for(mavlink.MAV_AUTOPILOT_GENERIC)  # who knows: no delay assumed
    assert asked == [] and (node.translator.gnss_delay_us, node.translator.gnss_delay_source) == (0, "none")


def test_local_feeds_are_about_the_autopilots_ekf_origin_and_read_back_so(tmp_path):
    """ArduPilot set its EKF origin from its own first fix, 7.9 m south, 0.7 m west and 10.5 m above
    our home (the canyon flight, profile 0): VISION_POSITION_ESTIMATE / ODOMETRY are NED in ITS local
    frame, so our position is sent horizontally about that origin (before: about our home, and the
    vehicle flew 7.9 m off), vertically about our home (its height is the barometer's). The flight
    tool reads what was sent back through the same origin from the companion's tlog."""
    from companion.autopilot.node import AutopilotCompanion, CompanionConfig
    from companion.mavlink.tlog import TlogWriter
    from simvehicle.harness.foreign.companion_process import COMPANION_COMPONENT_ID, sent_track

    conn = _FakeConn()
    node = AutopilotCompanion(CompanionConfig(master="udpin::14550", out_dir=tmp_path, feed="vision",
                                              home=HOME), conn)  # type: ignore[arg-type]
    _discover(node, 1, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA)
    lat, lon, alt = HOME.to_geodetic(np.array([-7.9, -0.7, -10.5]))
    origin = _from(mavlink.MAVLink_gps_global_origin_message(round(lat * 1e7), round(lon * 1e7),
                                                             round(alt * 1e3), 0), 1, 1)
    tr = node.translator
    tr.last_attitude = AttitudeSample(12_000_000, euler_to_quaternion(0.0, 0.0, 0.3))
    tr.last_imu = ImuSample(12_000_000, np.array([0.0, 0.0, -9.8]), np.zeros(3))
    e = _estimate((10.0, -5.0, -20.0))
    node._send_feed(e)  # no origin reported yet: about our home
    node.handle(origin, 2.5)
    assert node.counters["feed_about_autopilot_origin"] == 1
    node._send_feed(e)
    before, after = conn.sent[-2:]
    assert (before.x, before.y, before.z) == (10.0, -5.0, -20.0)
    np.testing.assert_allclose((after.x, after.y, after.z), (17.9, -4.3, -20.0), atol=0.01)
    node.config = CompanionConfig(master="udpin::14550", out_dir=tmp_path, feed="odometry", home=HOME)
    node._send_feed(e)
    np.testing.assert_allclose((conn.sent[-1].x, conn.sent[-1].y, conn.sent[-1].z), (17.9, -4.3, -20.0),
                               atol=0.01)

    from companion.mavlink.codec import new_link, pack

    ours, autopilot = new_link(1, COMPANION_COMPONENT_ID), new_link(1, 1)
    path = tmp_path / "companion.tlog"  # the companion's tlog: our feed, the origin arrives, our feed
    with TlogWriter(path) as tlog:
        tlog.write_frame(1, pack(ours, before))
        tlog.write_frame(2, pack(autopilot, origin))
        tlog.write_frame(3, pack(ours, after))
    t, p = sent_track(path, "vision", HOME, HOME)
    assert t.tolist() == [12_000_000, 12_000_000]
    np.testing.assert_allclose(p, [[10.0, -5.0, -20.0], [10.0, -5.0, -20.0]], atol=0.01)


def test_companion_mission_gives_the_navigator_the_missions_map(tmp_path, capsys):
    """``--mission NAME``: the tight filter's line-of-sight prior and the map methods get the mission's
    buildings (moved into our frame: ``--home`` when given, else the mission's home), and with
    ``--free-space`` an estimate inside a building is fed outside it; without a mission there is no
    map; an unknown mission is a one-line error."""
    import argparse

    from companion.autopilot.node import AutopilotCompanion
    from companion.autopilot.options import add_master_arguments
    from companion.autopilot.service import config_from_args
    from companion.mission import load_mission

    parser = argparse.ArgumentParser()
    add_master_arguments(parser, master_required=True)
    parser.add_argument("--method", default="second-order")
    base = ["--master", "udpin::14550", "--out", str(tmp_path), "--coupling", "tight",
            "--ubx", "tcp:127.0.0.1:1"]
    m = load_mission("test")
    start = m.frame.to_geodetic(np.array([47.0, 5.0, 0.0]))  # a profile's start, as the flight tool's --home
    for extra, home, mapped in (([], None, False), (["--mission", "test"], m.frame, True),
                                (["--mission", "test", "--home", ",".join(map(str, start))], None, True)):
        config = config_from_args(parser.parse_args(base + extra))
        assert (config.mission is not None) == mapped
        if home is not None:
            assert config.home == home
        node = AutopilotCompanion(config, _FakeConn())  # type: ignore[arg-type]
        if node.frame is None:
            continue  # no --home, no mission: the frame comes from the autopilot
        node._start_navigator()
        assert (node.nav.engine.line_of_sight is not None) == mapped
    loose = config_from_args(parser.parse_args(["--master", "udpin::14550", "--out", str(tmp_path),
                                                "--mission", "test", "--method", "map-beta", "--free-space"]))
    node = AutopilotCompanion(loose, _FakeConn())  # type: ignore[arg-type]
    node._start_navigator()  # map-beta without a map refuses to start
    assert node.nav.method == "map-beta"
    r = m.world.rects_m[0]  # an estimate in the middle of a building, σ 10 m: fed outside it
    inside = _estimate(((r[0] + r[2]) / 2, (r[1] + r[3]) / 2, -20.0), var=(100.0, 100.0, 4.0, *[0.1] * 6))
    fed = node._in_free_space(inside)
    assert m.world.clearance_m(*fed.p_ned_m[:2]) > 0.0 and fed.p_ned_m[2] == -20.0
    assert fed.cov_diag[2] == 4.0 and node.counters["free_space_constrained"] == 1
    off = config_from_args(parser.parse_args(["--master", "udpin::14550", "--out", str(tmp_path), "--mission",
                                              "test"]))  # without --free-space
    node = AutopilotCompanion(off, _FakeConn())  # type: ignore[arg-type]
    node._start_navigator()
    assert node._in_free_space(inside) is inside
    with pytest.raises(UserError, match="nowhere.yaml"):
        config_from_args(parser.parse_args(base + ["--mission", str(tmp_path / "nowhere.yaml")]))
    with pytest.raises(UserError, match="--free-space needs --mission"):  # not silently ignored
        config_from_args(parser.parse_args(base + ["--free-space"]))
    for lag in ("nan", "-1", "1001", "inf"):
        with pytest.raises(UserError, match="--clock-lag-ms"):
            config_from_args(parser.parse_args(base + ["--clock-lag-ms", lag]))
