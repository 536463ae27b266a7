"""Minimum-jerk segments (eq. 5): rest at the ends, derivatives by finite differences, limits."""

import math

import numpy as np
import pytest

from companion.planning.minjerk import MinJerkTrajectory, alpha, segment_duration_s

WAYPOINTS = np.array([[0.0, 0.0, -20.0], [30.0, 0.0, -20.0], [30.0, 4.0, -20.0], [-10.0, 40.0, -20.0]])
SPEED_M_S, ACC_M_S2 = 4.0, 1.5


def test_alpha_known_values_and_derivatives():
    a, da, dda = alpha(np.array([0.0, 0.5, 1.0]))
    np.testing.assert_allclose(a, [0.0, 0.5, 1.0])
    np.testing.assert_allclose(da, [0.0, 15 / 8, 0.0])
    np.testing.assert_allclose(dda, [0.0, 0.0, 0.0], atol=1e-12)
    s, h = np.linspace(0.01, 0.99, 50), 1e-6
    np.testing.assert_allclose(da, da)  # shape sanity
    np.testing.assert_allclose(alpha(s)[1], (alpha(s + h)[0] - alpha(s - h)[0]) / (2 * h), atol=1e-8)
    np.testing.assert_allclose(alpha(s)[2], (alpha(s + h)[1] - alpha(s - h)[1]) / (2 * h), atol=1e-7)
    s_peak = 0.5 - math.sqrt(3) / 6
    assert abs(alpha(np.array(s_peak))[2]) == pytest.approx(10 / math.sqrt(3))


def test_durations_are_the_shortest_within_both_limits():
    assert segment_duration_s(10.0, 2.0, 1.0) == pytest.approx(1.875 * 10 / 2)  # speed-limited
    assert segment_duration_s(10.0, 20.0, 1.0) == pytest.approx(math.sqrt(10 / math.sqrt(3) * 10))


def test_segments_start_and_end_at_rest_at_each_waypoint():
    traj = MinJerkTrajectory.through(WAYPOINTS, SPEED_M_S, ACC_M_S2, t_start_s=2.0)
    t_wp = 2.0 + np.r_[0.0, np.cumsum(traj.durations_s)]
    p, v, a = traj.reference(t_wp)
    np.testing.assert_allclose(p, WAYPOINTS, atol=1e-12)
    np.testing.assert_allclose(v, 0.0, atol=1e-12)
    np.testing.assert_allclose(a, 0.0, atol=1e-12)
    # held before the start and after the end
    for t, where in ((-5.0, WAYPOINTS[0]), (0.0, WAYPOINTS[0]), (t_wp[-1] + 100.0, WAYPOINTS[-1])):
        p, v, a = traj.reference(t)
        np.testing.assert_array_equal(p, where)
        assert not v.any() and not a.any()


def test_velocity_and_acceleration_match_finite_differences():
    traj = MinJerkTrajectory.through(WAYPOINTS, SPEED_M_S, ACC_M_S2)
    t = np.linspace(-1.0, traj.duration_s + 1.0, 3001)
    h = 1e-5
    p, v, a = traj.reference(t)
    p_plus, v_plus, _ = traj.reference(t + h)
    p_minus, v_minus, _ = traj.reference(t - h)
    np.testing.assert_allclose(v, (p_plus - p_minus) / (2 * h), atol=1e-6)
    np.testing.assert_allclose(a, (v_plus - v_minus) / (2 * h), atol=1e-5)
    # scalar and vector calls agree
    for k in (0, 1234, 3000):
        for x, y in zip(traj.reference(float(t[k])), (p[k], v[k], a[k]), strict=True):
            np.testing.assert_array_equal(x, y)


def test_peak_speed_and_acceleration_stay_within_limits_and_one_is_reached():
    traj = MinJerkTrajectory.through(WAYPOINTS, SPEED_M_S, ACC_M_S2)
    ends = np.cumsum(traj.durations_s)
    for k, (t0, t1) in enumerate(zip(ends - traj.durations_s, ends, strict=True)):
        _, v, a = traj.reference(np.linspace(t0, t1, 20001))
        speed, acc = np.linalg.norm(v, axis=1).max(), np.linalg.norm(a, axis=1).max()
        assert speed <= SPEED_M_S * (1 + 1e-9) and acc <= ACC_M_S2 * (1 + 1e-9)
        tight = max(speed / SPEED_M_S, acc / ACC_M_S2)
        assert tight == pytest.approx(1.0, abs=1e-6), f"segment {k} slower than it needs to be"


def test_rejects_repeated_waypoints():
    with pytest.raises(ValueError, match="distinct"):
        MinJerkTrajectory.through(WAYPOINTS[[0, 0, 1]], SPEED_M_S, ACC_M_S2)


def test_scalar_float_path_equals_the_vector_path_bit_for_bit():
    traj = MinJerkTrajectory.through(WAYPOINTS, SPEED_M_S, ACC_M_S2, t_start_s=2.0)
    ends = 2.0 + np.cumsum(traj.durations_s)
    t = np.r_[np.linspace(-1.0, traj.duration_s + 3.0, 2001), 2.0, ends, np.nextafter(ends, 0.0)]
    p, v, a = traj.reference(t)
    for k, tk in enumerate(t.tolist()):
        for x, y in zip(traj.reference(tk), (p[k], v[k], a[k]), strict=True):
            np.testing.assert_array_equal(x, y)
