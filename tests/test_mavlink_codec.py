"""MAVLink codec: every domain type <-> message, both ways, through real packed MAVLink 2 bytes."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from companion.domain.geodesy import LocalNedFrame
from companion.domain.rotation import quaternion_to_euler
from companion.domain.samples import AttitudeSample, GnssFix, ImuSample, NavEstimate, Setpoint, TruthState
from companion.mavlink import codec as mc
from companion.mavlink.codec import mavlink

FRAME = LocalNedFrame(-37.8594910, 144.7647800, 10.0)


def f32(*values: float) -> np.ndarray:
    """Values exactly representable on the wire (MAVLink floats are float32)."""
    return np.array(values, dtype=np.float32).astype(float)


def wire(msg):
    """Pack on one link, parse the bytes on another: what a receiver really gets."""
    frame = mc.pack(mc.new_link(1, 1), msg)
    assert frame[0] == 0xFD  # MAVLink 2
    received = mc.new_link(255, 0).parse_buffer(frame)
    assert received is not None and len(received) == 1
    assert received[0].get_type() == msg.get_type()
    return received[0]


def unit_q(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    return f32(*(q / np.linalg.norm(q)))


def test_imu_round_trip_is_exact() -> None:
    s = ImuSample(123_456_789, f32(0.1, -0.2, -9.81), f32(0.01, -0.02, 0.3))
    back = mc.decode_imu(wire(mc.encode_imu(s)))
    assert back.t_us == s.t_us
    np.testing.assert_array_equal(back.acc_frd_m_s2, s.acc_frd_m_s2)
    np.testing.assert_array_equal(back.gyro_frd_rad_s, s.gyro_frd_rad_s)
    assert mc.decode_sample(wire(mc.encode_imu(s))).t_us == s.t_us


def test_imu_barometer_fields_follow_fields_updated() -> None:
    """pressure_alt passed on with bit 11 (abs_pressure bit 9, temperature bit 12 set when sent); without
    bit 11 none (a log of fields_updated 63 with a constant 1013.25 hPa); NaN or absurd: NaN, IMU kept."""
    acc, gyro = f32(0.1, -0.2, -9.81), f32(0.01, -0.02, 0.3)
    s = ImuSample(1_000, acc, gyro, float(f32(87.25)[0]))
    m = wire(mc.encode_imu(s, 1002.5, 31.0))
    assert m.fields_updated == 63 | (1 << 9) | (1 << 11) | (1 << 12)
    assert (m.abs_pressure, m.temperature) == (1002.5, 31.0)
    assert mc.decode_imu(m).pressure_alt_m == s.pressure_alt_m
    plain = wire(mc.encode_imu(ImuSample(1_000, acc, gyro)))
    assert plain.fields_updated == 63 and mc.decode_imu(plain).pressure_alt_m is None
    logged = mc.mavlink.MAVLink_highres_imu_message(1_000, *acc, *gyro, 0, 0, 0, 1013.25, 0, 0, 0, 63, 0)
    assert mc.decode_imu(wire(logged)).pressure_alt_m is None
    for bad in (math.nan, math.inf, 1e6):
        back = mc.decode_imu(wire(mc.encode_imu(ImuSample(1_000, acc, gyro, bad))))
        assert math.isnan(back.pressure_alt_m) and back.t_us == 1_000


def test_attitude_round_trip() -> None:
    q = unit_q(np.random.default_rng(1))
    back = mc.decode_attitude(wire(mc.encode_attitude(AttitudeSample(5_000_000, q))))
    assert back.t_us == 5_000_000  # time_boot_ms: whole milliseconds survive
    np.testing.assert_allclose(back.q_ned_frd, q, atol=1e-7)


def test_gnss_round_trip_and_unknown_fields() -> None:
    v = np.array([3.0, -4.0, 0.7])
    fix = GnssFix(987_654, -37.8594911, 144.7647801, 12.345, 3, 11, h_acc_m=0.812, v_acc_m=1.5, hdop=0.9,
                  v_ned_m_s=v, vel_acc_m_s=0.25)
    back = mc.decode_gnss(wire(mc.encode_gnss(fix)))
    # ground speed (cm/s) and course (cdeg): the horizontal velocity to < 1 cm/s; no vertical field
    np.testing.assert_allclose(back.v_ned_m_s[0:2], v[0:2], atol=0.005)
    assert math.isnan(back.v_ned_m_s[2])
    assert back == dataclasses.replace(fix, v_ned_m_s=back.v_ned_m_s)
    raw = wire(mc.encode_gnss(fix))
    cog = round(math.degrees(math.atan2(-4.0, 3.0)) * 100) % 36000
    assert (raw.vel, raw.cog, raw.vel_acc) == (500, cog, 250)
    unknown = GnssFix(1000, 1.0, 2.0, 3.0, 3, 255)
    back = mc.decode_gnss(wire(mc.encode_gnss(unknown)))
    assert math.isnan(back.hdop) and math.isnan(back.h_acc_m) and math.isnan(back.v_acc_m)
    assert back.satellites_visible == 255 and back.v_ned_m_s is None and math.isnan(back.vel_acc_m_s)
    raw = wire(mc.encode_gnss(unknown))
    assert raw.eph == 65535 and raw.h_acc == 0 and (raw.vel, raw.cog, raw.vel_acc) == (65535, 65535, 0)
    still = mc.decode_gnss(wire(mc.encode_gnss(dataclasses.replace(unknown, v_ned_m_s=np.zeros(3)))))
    assert still.v_ned_m_s[0:2].tolist() == [0.0, 0.0]  # speed 0: no course needed


def test_gps2_raw_gps_input_and_hil_gps_carry_the_velocity() -> None:
    """GPS2_RAW decodes as GPS_RAW_INT; GPS_INPUT and HIL_GPS carry a NED velocity (GPS_INPUT's
    ignore_flags say which parts are unset); an absurd velocity is out of range."""
    g2 = mavlink.MAVLink_gps2_raw_message(5_000, 3, 10_000_000, 20_000_000, 3000, 120, 65535, 250, 9000, 9,
                                          0, 0, 0, 0, 900, 1500, 300, 0)
    f = mc.GNSS_DECODERS["GPS2_RAW"](wire(g2))
    np.testing.assert_allclose(f.v_ned_m_s[0:2], [0.0, 2.5], atol=1e-12)
    assert (f.h_acc_m, f.vel_acc_m_s, f.hdop) == (0.9, 0.3, 1.2)
    flags = mavlink.GPS_INPUT_IGNORE_FLAG_VEL_VERT | mavlink.GPS_INPUT_IGNORE_FLAG_HDOP
    gi = mavlink.MAVLink_gps_input_message(7_000, 0, flags, 0, 0, 3, 10_000_000, 20_000_000, 31.5, 0.8, 1.1,
                                           1.5, -2.0, 0.4, 0.35, 2.5, 4.0, 12, 0)
    f = mc.GNSS_DECODERS["GPS_INPUT"](wire(gi))
    assert f.v_ned_m_s[0:2].tolist() == [1.5, -2.0] and math.isnan(f.v_ned_m_s[2])
    assert (f.t_validity_us, f.alt_m, f.h_acc_m, f.v_acc_m) == (7_000, 31.5, 2.5, 4.0)
    assert f.vel_acc_m_s == pytest.approx(0.35, rel=1e-7)  # float32 on the wire
    assert math.isnan(f.hdop)
    none = mc.decode_gps_input(wire(mavlink.MAVLink_gps_input_message(
        7_000, 0, 8 | 16 | 32, 0, 0, 3, 10_000_000, 20_000_000, 31.5, 0.8, 1.1, 0, 0, 0, 0, 2.5, 4.0, 12, 0)))
    assert none.v_ned_m_s is None and math.isnan(none.vel_acc_m_s)
    hil = mavlink.MAVLink_hil_gps_message(9_000, 3, 10_000_000, 20_000_000, 31_500, 95, 65535, 250, 150, -200,
                                          30, 30_000, 10, 0, 0)
    f = mc.GNSS_DECODERS["HIL_GPS"](wire(hil))
    assert f.v_ned_m_s.tolist() == [1.5, -2.0, 0.3] and f.hdop == 0.95 and f.alt_m == 31.5
    with pytest.raises(mc.CodecError, match="out_of_range"):
        mc.decode_gnss(wire(mavlink.MAVLink_gps_raw_int_message(1, 3, 1, 1, 0, 65535, 65535, 60_000, 0, 9)))


def test_truth_round_trip_through_geodetic() -> None:
    rng = np.random.default_rng(2)
    s = TruthState(42_000, np.array([120.3, -45.7, -30.2]), f32(1.5, -2.0, 0.25), unit_q(rng))
    back = mc.decode_truth(wire(mc.encode_truth(s, FRAME)), FRAME, t_us=42_000)
    assert back.t_us == 42_000
    np.testing.assert_allclose(back.p_ned_m, s.p_ned_m, atol=0.02)  # degE7 ≈ 1 cm, alt float32
    np.testing.assert_array_equal(back.v_ned_m_s, s.v_ned_m_s)
    np.testing.assert_allclose(back.q_ned_frd, s.q_ned_frd, atol=1e-7)
    assert np.isnan(back.gnss_bias_ned_m).all() and math.isnan(back.gnss_latency_s)


def _estimate(beta: float, nis: float, **extra) -> NavEstimate:
    return NavEstimate(
        t_us=7_000_000, p_ned_m=f32(10.5, -3.25, -20.0), v_ned_m_s=f32(1.0, 0.5, -0.125),
        b_ned_m=np.array([0.3, -0.2, 0.1]), cov_diag=f32(*(0.01 * np.arange(1, 10))),
        beta=beta, nis=nis, method="second-order", **extra,
    )


def test_odometry_round_trip() -> None:
    e = _estimate(beta=0.874, nis=2.5)
    back = mc.decode_odometry(wire(mc.encode_odometry(e)))
    assert back.t_us == e.t_us
    np.testing.assert_array_equal(back.p_ned_m, e.p_ned_m)
    np.testing.assert_array_equal(back.v_ned_m_s, e.v_ned_m_s)
    np.testing.assert_array_equal(back.cov_diag[:6], e.cov_diag[:6])
    assert np.isnan(back.cov_diag[6:]).all() and np.isnan(back.b_ned_m).all()
    assert math.isnan(back.beta)  # β is not ODOMETRY's quality: it travels in GNSS_BETA


def test_odometry_follows_the_spec_unknown_conventions() -> None:
    raw = wire(mc.encode_odometry(_estimate(beta=0.874, nis=2.5)))
    assert math.isnan(raw.q[0]) and list(raw.q[1:]) == [0.0, 0.0, 0.0]  # attitude unknown: NaN first
    for cov in (raw.pose_covariance, raw.velocity_covariance):
        assert math.isfinite(cov[0]) and not any(math.isnan(c) for c in cov)  # known: no NaN inside
        assert [cov[i] for i in (15, 18, 20)] == [math.inf] * 3  # not estimated: no information
        assert [c for i, c in enumerate(cov) if i not in (0, 6, 11, 15, 18, 20)] == [0.0] * 15
    assert raw.quality == mc.ODOMETRY_QUALITY_UNKNOWN == 0  # valid estimate, quality not rated
    invalid = wire(mc.encode_odometry(_estimate(beta=0.9, nis=1.0, pos_valid=False, gnss_resets=258)))
    assert invalid.quality == -1  # the spec's "odometry has failed"
    assert invalid.reset_counter == 2  # the estimator's GNSS resets, modulo 256
    back = mc.decode_odometry(invalid)
    assert not back.pos_valid and back.gnss_resets == 2
    assert mc.decode_odometry(raw).pos_valid


def test_estimator_status_and_belief_values() -> None:
    e = _estimate(beta=0.5, nis=3.0, pos_horiz_test_ratio=0.5)
    st = mc.decode_estimator_status(wire(mc.encode_estimator_status(e)))
    assert st.t_us == e.t_us and st.flags == mc.ESTIMATOR_HEALTHY_FLAGS
    assert st.pos_horiz_ratio == pytest.approx(0.5)
    raw = wire(mc.encode_estimator_status(e))
    assert all(math.isnan(getattr(raw, f)) for f in
               ("vel_ratio", "pos_vert_ratio", "mag_ratio", "hagl_ratio", "tas_ratio"))  # never tested
    # the receiver's velocity tested, the IMU disagreeing with it: its ratio and ACCEL_ERROR
    bad_imu = _estimate(0.5, 3.0, pos_horiz_test_ratio=0.5, vel_test_ratio=1.7, imu_gnss_disagreement=True)
    st_imu = mc.decode_estimator_status(wire(mc.encode_estimator_status(bad_imu)))
    assert st_imu.vel_ratio == pytest.approx(1.7) and math.isnan(st.vel_ratio)
    assert st_imu.flags == mc.ESTIMATOR_HEALTHY_FLAGS | mc.mavlink.ESTIMATOR_ACCEL_ERROR
    failed = wire(mc.encode_estimator_status(_estimate(0.5, 3.0, pos_horiz_test_ratio=2.6, gnss_glitch=True)))
    assert failed.pos_horiz_ratio == pytest.approx(2.6)  # the rejected fix's ratio, not the last fused NIS
    assert failed.flags == mc.ESTIMATOR_HEALTHY_FLAGS | mc.mavlink.ESTIMATOR_GPS_GLITCH
    untested = mc.decode_estimator_status(wire(mc.encode_estimator_status(_estimate(1.0, math.nan))))
    assert math.isnan(untested.pos_horiz_ratio) and untested.flags == mc.ESTIMATOR_HEALTHY_FLAGS
    lost = wire(mc.encode_estimator_status(_estimate(0.5, 3.0, pos_valid=False, gnss_glitch=True)))
    assert lost.flags == mc.mavlink.ESTIMATOR_GPS_GLITCH  # no output valid: none claimed
    assert st.pos_horiz_accuracy_m == pytest.approx(math.sqrt(0.03), rel=1e-6)
    assert st.pos_vert_accuracy_m == pytest.approx(math.sqrt(0.03), rel=1e-6)
    values = [mc.decode_named_value(wire(m)) for m in mc.encode_belief(e)]
    expected = [("GNSS_BETA", 0.5, 7_000_000), ("GNSS_NIS", 3.0, 7_000_000)]
    assert [(v.name, v.value, v.t_us) for v in values] == expected
    assert [m.name for m in mc.encode_belief(_estimate(beta=1.0, nis=math.nan))] == ["GNSS_BETA"]
    with pytest.raises(ValueError):
        mc.encode_named_value(0, "ELEVEN_CHARS", 1.0)


def test_setpoint_round_trip_and_type_mask() -> None:
    s = Setpoint(3_000_000, f32(5.0, 6.0, -30.0), f32(0.5, 0.25, 0.0), f32(0.1, 0.0, -0.2))
    back = mc.decode_setpoint(wire(mc.encode_setpoint(s)))
    assert back.t_us == s.t_us
    for a, b in ((back.p_ned_m, s.p_ned_m), (back.v_ned_m_s, s.v_ned_m_s), (back.a_ned_m_s2, s.a_ned_m_s2)):
        np.testing.assert_array_equal(a, b)
    msg = mc.encode_setpoint(s)
    msg.type_mask |= 0b111111000  # position only: no feed-forward
    back = mc.decode_setpoint(wire(msg))
    assert not back.v_ned_m_s.any() and not back.a_ned_m_s2.any()
    msg.type_mask |= 0b111
    with pytest.raises(mc.CodecError) as err:
        mc.decode_setpoint(wire(msg))
    assert err.value.reason == "unsupported_frame"


def test_heartbeat_and_system_time() -> None:
    hb = mc.decode_heartbeat(wire(mc.encode_heartbeat("companion")))
    assert (hb.mav_type, hb.autopilot) == mc.ROLE_TYPES["companion"]
    assert (hb.base_mode, hb.custom_mode, hb.armed) == (0, 0, False)  # not an autopilot
    v = mc.decode_heartbeat(wire(mc.encode_heartbeat("vehicle", armed=True, mode="OFFBOARD")))
    assert v.armed and v.base_mode & mc.mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    assert v.custom_mode == 0x0006_0000  # PX4 layout: main mode 6 (OFFBOARD) in bits 16-23
    from pymavlink import mavutil

    assert mavutil.mode_string_v10(wire(mc.encode_heartbeat("vehicle", armed=True))) == "OFFBOARD"
    assert mavutil.mode_string_v10(wire(mc.encode_heartbeat("vehicle", mode="HOLD"))) == "LOITER"
    assert not mc.decode_heartbeat(wire(mc.encode_heartbeat("vehicle", armed=False))).armed
    clock = mc.decode_system_time(wire(mc.encode_system_time(1_700_000_000_123_456, 65_432_000)))
    assert clock == mc.ClockPair(1_700_000_000_123_456, 65_432_000)
    assert mc.decode_sample(wire(mc.encode_heartbeat("vehicle"))) is None


def test_raw_and_scaled_imu_known_answers() -> None:
    m = mc.mavlink
    raw = wire(m.MAVLink_raw_imu_message(2_000_000, 10, -20, -1000, 100, -200, 300, 0, 0, 0, 0, 0))
    s = mc.decode_sample(raw)
    np.testing.assert_allclose(s.acc_frd_m_s2, [0.0980665, -0.196133, -9.80665])
    np.testing.assert_allclose(s.gyro_frd_rad_s, [0.1, -0.2, 0.3])
    assert s.t_us == 2_000_000
    scaled = wire(m.MAVLink_scaled_imu_message(2500, 0, 0, -1000, 0, 0, 1000, 0, 0, 0, 0))
    s = mc.decode_sample(scaled)
    assert s.t_us == 2_500_000 and s.acc_frd_m_s2[2] == pytest.approx(-9.80665) and s.gyro_frd_rad_s[2] == 1.0


def test_attitude_euler_matches_scipy() -> None:
    roll, pitch, yaw = f32(0.3, -0.2, 2.5)
    s = mc.decode_sample(wire(mc.mavlink.MAVLink_attitude_message(1500, roll, pitch, yaw, 0, 0, 0)))
    x, y, z, w = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_quat()
    np.testing.assert_allclose(s.q_ned_frd, [w, x, y, z], atol=1e-12)
    np.testing.assert_allclose(quaternion_to_euler(s.q_ned_frd), (roll, pitch, yaw), atol=1e-12)


@pytest.mark.parametrize(
    ("msg", "reason"),
    [
        (mc.encode_imu(ImuSample(1, np.array([np.nan, 0, 0]), np.zeros(3))), "non_finite"),
        (mc.mavlink.MAVLink_highres_imu_message(1, 0, 0, -9.8, *[0] * 12), "fields_not_updated"),
        (mc.encode_attitude(AttitudeSample(1000, np.array([2.0, 0, 0, 0]))), "out_of_range"),
        (mc.encode_attitude(AttitudeSample(1000, np.array([np.inf, 0, 0, 0]))), "non_finite"),
        (mc.mavlink.MAVLink_gps_raw_int_message(1, 3, 950_000_000, 0, 0, 0, 0, 0, 0, 9), "out_of_range"),
        (mc.mavlink.MAVLink_attitude_message(1, np.nan, 0, 0, 0, 0, 0), "non_finite"),
    ],
)
def test_bad_fields_raise_a_counted_codec_error(msg, reason: str) -> None:
    with pytest.raises(mc.CodecError) as err:
        mc.decode_sample(wire(msg))
    assert err.value.reason == reason


def test_bad_outputs_raise_a_counted_codec_error() -> None:
    odo = mc.encode_odometry(_estimate(0.9, 1.0))
    odo.frame_id = mc.mavlink.MAV_FRAME_BODY_FRD
    with pytest.raises(mc.CodecError, match="unsupported_frame"):
        mc.decode_odometry(wire(odo))
    nis_nan = mc.mavlink.MAVLink_named_value_float_message(0, b"GNSS_NIS", math.nan)
    with pytest.raises(mc.CodecError, match="non_finite"):
        mc.decode_named_value(wire(nis_nan))
    truth = mc.encode_truth(TruthState(0, np.zeros(3), np.zeros(3), np.array([1.0, 0, 0, 0])), FRAME)
    truth.lat_int, truth.lat = 0, math.nan
    truth.lon_int = 0
    with pytest.raises(mc.CodecError, match="non_finite"):
        mc.decode_truth(wire(truth), FRAME, 0)


def test_bias_debug_vect_round_trip_and_wrong_name():
    e = NavEstimate(1_234_567, np.zeros(3), np.zeros(3), np.array([0.25, -1.5, 0.125]), np.full(9, 0.1), 0.5,
                    1.0, "second-order")
    t_us, b = mc.decode_bias(wire(mc.encode_bias(e)))
    assert t_us == 1_234_567
    np.testing.assert_array_equal(b, [0.25, -1.5, 0.125])  # exact in float32
    other = mc.mavlink.MAVLink_debug_vect_message(b"OTHER", 0, 1.0, 2.0, 3.0)
    with pytest.raises(mc.CodecError) as exc:
        mc.decode_bias(wire(other))
    assert exc.value.reason == "name"
    nan = mc.mavlink.MAVLink_debug_vect_message(b"GNSS_BIAS", 0, math.nan, 2.0, 3.0)
    with pytest.raises(mc.CodecError):
        mc.decode_bias(wire(nan))
