"""Range and plausibility checks of the MAVLink codec: just inside a limit decodes, just outside is
rejected with a counted reason; encoders refuse what they must never send (known answers)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from companion.domain.geodesy import LocalNedFrame
from companion.domain.samples import GnssFix, ImuSample, NavEstimate, Setpoint
from companion.mavlink import codec as mc

FRAME = LocalNedFrame(-37.8594910, 144.7647800, 10.0)
LIM = mc.LIMITS


def wire(msg):
    return mc.new_link(255, 0).parse_buffer(mc.pack(mc.new_link(1, 1), msg))[0]


def _imu_msg(t_us, acc, gyro):
    return mc.mavlink.MAVLink_highres_imu_message(t_us, *acc, *gyro, 0, 0, 0, 0, 0, 0, 0,
                                                   mc.IMU_FIELDS_ACC_GYRO, 0)


def _reason(fn, *args):
    with pytest.raises(mc.CodecError) as info:
        fn(*args)
    return info.value.reason


def test_imu_specific_force_and_rate_limits():
    f, w = LIM.max_specific_force_m_s2, LIM.max_rate_rad_s
    inside = wire(_imu_msg(1_000, (f * 0.999, 0, 0), (0, -w * 0.999, 0)))
    assert mc.decode_imu(inside).t_us == 1_000
    assert _reason(mc.decode_imu, wire(_imu_msg(1_000, (0, 0, -f * 1.01), (0, 0, 0)))) == "out_of_range"
    assert _reason(mc.decode_imu, wire(_imu_msg(1_000, (0, 0, 0), (w * 1.01, 0, 0)))) == "out_of_range"
    assert _reason(mc.decode_imu, wire(_imu_msg(1_000, (0, math.inf, 0), (0, 0, 0)))) == "non_finite"
    assert _reason(mc.decode_imu, wire(_imu_msg(1_000, (0, 0, 0), (math.nan, 0, 0)))) == "non_finite"
    assert _reason(mc.decode_imu, wire(_imu_msg(2**63, (0, 0, 0), (0, 0, 0)))) == "bad_stamp"


def test_raw_imu_in_mg_is_range_checked_too():
    raw = mc.mavlink.MAVLink_raw_imu_message(5_000, 20_000, 0, 0, 0, 0, 0, 0, 0, 0)  # 20 g
    assert _reason(mc.decode_raw_imu, wire(raw)) == "out_of_range"


def test_fix_farther_than_the_limit_from_home_is_rejected_only_with_a_home():
    def fix(north_m):
        lat, lon, alt = FRAME.to_geodetic(np.array([north_m, 0.0, -10.0]))
        return wire(mc.encode_gnss(GnssFix(1_000, lat, lon, alt, 3, 10, 0.1, 0.2, 0.8)))

    near, far = fix(0.99 * LIM.max_home_distance_m), fix(1.01 * LIM.max_home_distance_m)
    assert isinstance(mc.decode_sample(near, FRAME), GnssFix)
    assert isinstance(mc.decode_sample(far), GnssFix)  # no home: only lat/lon validity
    assert _reason(mc.decode_sample, far, FRAME) == "out_of_range"


def _estimate(p=(1.0, 2.0, -10.0), v=(0.0, 0.0, 0.0), t_us=10_000, var=0.01, nis=1.0, beta=0.5):
    return NavEstimate(t_us, np.array(p, float), np.array(v, float), np.zeros(3), np.full(9, var),
                       beta, nis, "test")


def test_odometry_positions_velocities_variances_are_bounded_both_ways():
    d = LIM.max_home_distance_m
    assert mc.decode_odometry(wire(mc.encode_odometry(_estimate(p=(0.99 * d, 0, 0))))).t_us == 10_000
    for bad, reason in ((_estimate(p=(1.01 * d, 0, 0)), "out_of_range"),
                        (_estimate(p=(math.nan, 0, 0)), "non_finite"),
                        (_estimate(v=(0, 1.01 * LIM.max_speed_m_s, 0)), "out_of_range"),
                        (_estimate(var=-1.0), "out_of_range"),
                        (_estimate(t_us=-5), "bad_stamp")):
        assert _reason(mc.encode_odometry, bad) == reason  # never sent
    far = mc.mavlink.MAVLink_odometry_message(
        10_000, mc.mavlink.MAV_FRAME_LOCAL_NED, mc.mavlink.MAV_FRAME_LOCAL_NED, 1.7e37, 0, 0,
        [1, 0, 0, 0], 0, 0, 0, 0, 0, 0, [0.0] * 21, [0.0] * 21, 0, 0, 50)
    assert _reason(mc.decode_odometry, wire(far)) == "out_of_range"


def test_belief_values_a_float32_cannot_hold_are_not_encoded():
    assert _reason(mc.encode_named_value, 1_000, mc.NIS_NAME, 1e300) == "out_of_range"
    assert _reason(mc.encode_named_value, 2**32 * 1000, mc.NIS_NAME, 1.0) == "bad_stamp"
    msgs = mc.encode_belief(_estimate(nis=2.0))
    assert [mc.decode_named_value(wire(m)).value for m in msgs] == [0.5, 2.0]
    huge = dataclasses.replace(_estimate(nis=1e300), pos_horiz_test_ratio=1e300)
    status = mc.decode_estimator_status(wire(mc.encode_estimator_status(huge)))
    assert status.pos_horiz_ratio == pytest.approx(mc.FLOAT32_MAX, rel=1e-6)  # clamped, finite


def test_setpoints_are_bounded_both_ways():
    ok = Setpoint(50_000, np.array([1.0, 2.0, -10.0]), np.zeros(3), np.zeros(3))
    assert mc.decode_setpoint(wire(mc.encode_setpoint(ok))).t_us == 50_000
    far = Setpoint(50_000, np.array([1e9, 0.0, 0.0]), np.zeros(3), np.zeros(3))
    assert _reason(mc.encode_setpoint, far) == "out_of_range"
    late = Setpoint(2**32 * 1000, np.zeros(3), np.zeros(3), np.zeros(3))
    assert _reason(mc.encode_setpoint, late) == "bad_stamp"
    msg = mc.mavlink.MAVLink_set_position_target_local_ned_message(
        50, 1, 1, mc.mavlink.MAV_FRAME_LOCAL_NED, 0, 0, 0, 0, 0, 0, 0, 1e6, 0, 0, 0, 0)
    assert _reason(mc.decode_setpoint, wire(msg)) == "out_of_range"  # acceleration 1e6 m/s²


def test_a_valid_imu_sample_round_trips_exactly():
    s = ImuSample(123_456_789, np.array([0.5, -0.25, -9.75]), np.array([0.125, 0.0, -0.5]))
    back = mc.decode_imu(wire(mc.encode_imu(s)))
    np.testing.assert_array_equal(back.acc_frd_m_s2, s.acc_frd_m_s2)
