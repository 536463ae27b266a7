"""The foreign-autopilot adapter's pure parts: connection strings, discovery, time base, TIMESYNC,
feeds, comparison — known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from companion.autopilot import compare, feeds
from companion.autopilot.connection import Endpoint, parse_connection
from companion.autopilot.discovery import Discovery
from companion.autopilot.streams import StreamRates, data_stream_requests, interval_requests
from companion.autopilot.timesync import Timesync
from companion.autopilot.translate import TranslateConfig, Translator
from companion.domain.geodesy import LocalNedFrame
from companion.domain.samples import GnssFix, ImuSample, NavEstimate
from companion.errors import UserError
from companion.mavlink.codec import euler_to_quaternion

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


def test_discovery_takes_the_first_autopilot_and_counts_the_rest():
    d = Discovery()
    gcs = mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3)
    quad = mavlink.MAV_TYPE_QUADROTOR
    ap = mavlink.MAVLink_heartbeat_message(quad, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 0, 3)
    assert not d.accept(_from(gcs, 255, 190), 0.0)  # a ground station is not an autopilot
    assert d.accept(_from(ap, 7, 1), 0.0)
    assert d.autopilot is not None and (d.autopilot.system_id, d.autopilot.component_id) == (7, 1)
    assert d.autopilot.as_dict()["autopilot"] == "MAV_AUTOPILOT_ARDUPILOTMEGA"
    other = mavlink.MAVLink_heartbeat_message(quad, mavlink.MAV_AUTOPILOT_PX4, 0, 0, 0, 3)
    assert not d.accept(_from(other, 8, 1), 0.5)
    assert not d.accept(_from(ap, 7, 154), 0.5)  # a gimbal of the same system
    assert dict(d.counters) == {"before_discovery": 1, "other_system": 1, "other_component": 1}
    assert not d.heartbeat_lost(2.9) and d.heartbeat_lost(3.1)
    assert not d.boot_time(60_000_000) and not d.boot_time(59_500_000)  # jitter, not a reboot
    assert d.boot_time(1_000_000) and d.reboots == 1


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
    assert answer is not None and (answer.tc1, answer.ts1) == (5_000, 123)
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


def test_odometry_in_the_frames_ardupilot_fuses_velocity_in_body_frd():
    q = euler_to_quaternion(0.0, 0.0, math.pi / 2)  # nose east
    msg = feeds.odometry(_estimate((1.0, 2.0, -3.0), v=(0.0, 4.0, 0.0)), q, np.array((0.0, 0.0, 0.1)))
    assert (msg.frame_id, msg.child_frame_id) == (mavlink.MAV_FRAME_LOCAL_FRD, mavlink.MAV_FRAME_BODY_FRD)
    assert msg.estimator_type == mavlink.MAV_ESTIMATOR_TYPE_VIO and msg.quality == 90
    np.testing.assert_allclose((msg.vx, msg.vy, msg.vz), (4.0, 0.0, 0.0), atol=1e-6)  # flying forward
    assert (msg.x, msg.y, msg.z) == (1.0, 2.0, -3.0) and msg.pose_covariance[0] == pytest.approx(0.04)
    vis = feeds.vision_position(_estimate((1.0, 2.0, -3.0)), q)
    assert vis.yaw == pytest.approx(math.pi / 2) and vis.covariance[6] == pytest.approx(0.05)


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
