"""Cascaded autopilot (eq. 9-11) in closed loop with the rigid body."""

import numpy as np
import pytest
from vehicle_world import FixtureMission

from companion.domain.rotation import euler_to_quaternion, rotation_matrix
from companion.domain.samples import NavEstimate, Setpoint
from simvehicle import SimVehicle
from simvehicle.autopilot import Autopilot
from simvehicle.config import AutopilotConfig, VehicleConfig

MISSION = FixtureMission()


def min_jerk(p0: np.ndarray, p1: np.ndarray, T: float, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Test-only minimum-jerk segment (eq. 5) with its derivatives; holds p1 after T."""
    s = min(max(t / T, 0.0), 1.0)
    a = 10 * s**3 - 15 * s**4 + 6 * s**5
    da = (30 * s**2 - 60 * s**3 + 30 * s**4) / T if t < T else 0.0
    dda = (60 * s - 180 * s**2 + 120 * s**3) / T**2 if t < T else 0.0
    d = p1 - p0
    return p0 + a * d, da * d, dda * d


def truth_estimate(sim: SimVehicle, out) -> NavEstimate:
    tr = out.truth[-1]
    return NavEstimate(out.t_us, tr.p_ned_m, tr.v_ned_m_s, np.zeros(3), np.zeros(9), 1.0, np.nan, "truth")


def fly_segment(p1: np.ndarray, T: float, seconds: float, seed: int = 0):
    sim = SimVehicle(MISSION, 0, seed)
    p0 = sim.start_ned_m.copy()
    est, errors = None, []
    while sim.t_us < seconds * 1e6:
        t_s = sim.t_us * 1e-6
        p, v, a = min_jerk(p0, p1, T, t_s)
        out = sim.advance(est, Setpoint(sim.t_us, p, v, a))
        est = truth_estimate(sim, out)
        p_ref, _, _ = min_jerk(p0, p1, T, out.t_us * 1e-6)
        errors.append(np.linalg.norm(out.truth[-1].p_ned_m - p_ref))
    return sim, np.array(errors)


def test_tracks_min_jerk_segment_with_truth_feedback():
    """Stated bound: 60 m north, 20 m east, 5 m up in 15 s (peak 8.3 m/s, 1.9 m/s²) -> error < 0.15 m."""
    p1 = np.array([60.0, 20.0, -35.0])
    sim, err = fly_segment(p1, T=15.0, seconds=20.0)
    assert err.max() < 0.15
    assert np.linalg.norm(sim.p_ned_m - p1) < 0.1  # settled on the goal 5 s after the end
    assert not sim.body.x[12] ** 2 > 1e-6  # yaw rate stays ~0 (yaw held)


def test_holds_on_its_own_without_estimate_and_ignores_stale_estimates():
    sim = SimVehicle(MISSION, 0, 1)
    start = sim.start_ned_m.copy()
    far = Setpoint(0, start + [30.0, 0.0, 0.0], np.zeros(3), np.zeros(3))
    wrong = NavEstimate(0, start + [-20.0, 5.0, 3.0], np.zeros(3), np.zeros(3), np.zeros(9), 1.0, 0.0, "x")
    for _ in range(100):  # 5 s: no estimate at all, then one that stays frozen at t = 0 (stale)
        sim.advance(None if sim.t_us < 1_000_000 else wrong, far)
    assert np.linalg.norm(sim.p_ned_m - start) < 0.2
    # a fresh estimate that is 2 m off makes it move 2 m the other way (it flies on the estimate)
    for _ in range(200):
        est = NavEstimate(sim.t_us, sim.p_ned_m + [2.0, 0.0, 0.0], np.array(sim.body.x[3:6]), np.zeros(3),
                          np.zeros(9), 1.0, 0.0, "x")
        sim.advance(est, Setpoint(sim.t_us, start, np.zeros(3), np.zeros(3)))
    assert sim.p_ned_m[0] == pytest.approx(start[0] - 2.0, abs=0.05)


def test_integral_only_accumulates_near_the_reference():
    ap = Autopilot(AutopilotConfig(eps_int_m=1.0), VehicleConfig(), np.zeros(3))
    ap.holding = False
    ap.track(np.array([5.0, 0.0, 0.0]), np.zeros(3), np.zeros(3))  # 5 m away: frozen
    assert ap.integral_m_s == [0.0, 0.0, 0.0]
    ap.track(np.array([0.5, 0.0, -0.2]), np.zeros(3), np.zeros(3))  # within 1 m: integrates e * dt
    assert ap.integral_m_s == pytest.approx([0.5 * 0.05, 0.0, -0.2 * 0.05])


@pytest.mark.parametrize("yaw", [0.0, 0.9])
def test_small_angle_mapping_signs_in_ned(yaw):
    """A northward/eastward acceleration command tilts the thrust vector that way, whatever the yaw."""
    ap = Autopilot(AutopilotConfig(), VehicleConfig(), np.zeros(3), yaw_hold_rad=yaw)
    for a_ref in ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-0.7, 0.4, 0.0]):
        ap.track(np.zeros(3), np.zeros(3), np.array(a_ref))
        R = rotation_matrix(euler_to_quaternion(ap.roll_cmd_rad, ap.pitch_cmd_rad, yaw))
        a_horizontal = (-9.81 * R[:, 2])[:2]  # thrust acceleration (body -z) at hover thrust
        np.testing.assert_allclose(a_horizontal, a_ref[:2], rtol=0.02, atol=0.01)


def test_non_finite_estimate_or_setpoint_is_not_flown():
    sim = SimVehicle(MISSION, 0, 2)
    start, zero = sim.start_ned_m.copy(), np.zeros(3)
    nan3 = np.full(3, np.nan)
    for k in range(60):  # 3 s: fresh but NaN estimates, then good estimates with a NaN setpoint
        x = sim.body.x
        good = NavEstimate(sim.t_us, np.array(x[0:3]), np.array(x[3:6]), zero, np.zeros(9), 1.0, 0.0, "x")
        bad = NavEstimate(sim.t_us, nan3, zero, zero, np.zeros(9), 1.0, 0.0, "x")
        target = start + [25.0, 0.0, 0.0] if k < 30 else nan3
        sp = Setpoint(sim.t_us, target, zero, zero)
        sim.advance(bad if k < 30 else good, sp)
        assert sim.autopilot.holding == (k < 30)
    assert np.linalg.norm(sim.p_ned_m - start) < 0.2


def test_estimate_lost_mid_flight_dead_reckons_brakes_and_holds():
    """Truth estimates until t = 6 s (7.3 m/s), then the estimate freezes while the setpoint moves on.
    Stated bounds: within the 0.5 s stale window it tracks the setpoint on its dead-reckoned state
    (< 0.5 m); then it brakes (< 8 m: 7.6 m/s at ≤ g tan 25° needs ≥ 6.3 m) and is slower than
    1 m/s 2 s after the hold began, moving < 0.3 m in the 3.5 s after that."""
    sim = SimVehicle(MISSION, 0, 3)
    p0, p1 = sim.start_ned_m.copy(), np.array([60.0, 20.0, -35.0])
    est, t_lost, hold_t, rows, p_start_of_period = None, 6.0, None, [], p0
    while sim.t_us < 12e6:
        t_s = sim.t_us * 1e-6
        out = sim.advance(est, Setpoint(sim.t_us, *min_jerk(p0, p1, 15.0, t_s)))
        if out.t_us * 1e-6 <= t_lost:
            est = truth_estimate(sim, out)
        tr = out.truth[-1]
        if sim.autopilot.holding and hold_t is None and t_s > t_lost:
            hold_t = t_s
            assert hold_t == pytest.approx(t_lost + 0.5, abs=0.06)
        if t_s > t_lost:  # the navigation state of this period's start, dead-reckoned
            assert np.linalg.norm(sim.autopilot.nav_p_ned_m - p_start_of_period) < 0.1
        p_start_of_period = tr.p_ned_m
        rows.append((out.t_us * 1e-6, *tr.p_ned_m, np.linalg.norm(tr.v_ned_m_s), sim.autopilot.holding))
        if hold_t is None and t_s > t_lost:
            assert np.linalg.norm(tr.p_ned_m - min_jerk(p0, p1, 15.0, out.t_us * 1e-6)[0]) < 0.5
    r = np.array(rows)
    holding = (r[:, 5] > 0) & (r[:, 0] > t_lost)
    p_hold0 = r[holding][0, 1:4]
    assert r[holding][0, 4] > 6.0  # it was fast when the hold began
    assert np.max(np.linalg.norm(r[holding, 1:4] - p_hold0, axis=1)) < 8.0
    settled = r[:, 0] >= hold_t + 2.0
    assert np.all(r[settled, 4] < 1.0)
    assert np.max(np.linalg.norm(r[settled, 1:4] - r[settled][0, 1:4], axis=1)) < 0.3
