"""Sensor-realism scenarios: MEMS IMU errors, onboard AHRS, unmodelled GNSS (known answers, statistics)."""

import dataclasses
import math

import numpy as np
import pytest

from companion.domain.rotation import rotation_matrix, yaw_of
from companion.mission import ConfigError, load_mission, with_scenario
from companion.mission.scenarios import ICM_42688_P
from simvehicle import SimVehicle
from simvehicle.ahrs import Ahrs, attitude_error_rad
from simvehicle.config import AhrsConfig, GnssConfig, ImuConfig, sim_config_for
from simvehicle.imu import Imu
from simvehicle.nlos import Constellation, UnmodelledGnss, position_error

G = 9.80665


def test_paper_imu_is_the_white_noise_stream():
    """The paper's IMU draws exactly rng.standard_normal((n, 6)) per block: the pre-scenario stream."""
    f = np.tile([0.1, -0.2, -G], (10, 1))
    w = np.tile([0.01, 0.02, -0.03], (10, 1))
    acc, gyro = Imu(ImuConfig(), np.random.default_rng(5)).measure(f, w)
    n = np.random.default_rng(5).standard_normal((10, 6))
    np.testing.assert_array_equal(acc, f + 0.08 * n[:, :3])
    np.testing.assert_array_equal(gyro, w + 0.003 * n[:, 3:])


def test_mems_imu_noise_bias_walk_and_scale_statistics():
    cfg = ImuConfig(**ICM_42688_P)
    imu = Imu(cfg, np.random.default_rng(1), rate_hz=200.0)
    # white noise: std = sqrt(vibration² + density² × 100 Hz)
    assert imu.sigma_acc_m_s2 == pytest.approx(math.hypot(0.08, 70e-6 * G * 10.0))
    assert imu.sigma_gyro_rad_s == pytest.approx(math.hypot(0.003, math.radians(0.0028) * 10.0))
    # bias walk: over many IMUs the bias change after T has variance walk² T (zero true input)
    n_imu, steps = 400, 200  # 1 s at 200 Hz
    drift = []
    for seed in range(n_imu):
        imu = Imu(cfg, np.random.default_rng(100 + seed))
        b0 = imu.bias.copy()
        imu.measure(np.zeros((steps, 3)), np.zeros((steps, 3)))
        drift.append(imu.bias - b0)
    drift = np.array(drift)
    expected = np.array([cfg.acc_bias_walk_m_s2_rt_s] * 3 + [cfg.gyro_bias_walk_rad_s_rt_s] * 3) ** 2 * 1.0
    ratio = drift.var(axis=0) / expected
    assert np.all((ratio > 0.75) & (ratio < 1.3))  # 400 samples: var estimate within ±25 % (≈ 3.5σ)
    # turn-on bias and scale: the measured mean of a long static record is (1 + s) f + b
    imu = Imu(ImuConfig(acc_bias_turn_on_m_s2=0.05, acc_scale_factor=0.01), np.random.default_rng(3))
    f = np.tile([0.0, 0.0, -G], (20000, 1))
    acc, _ = imu.measure(f, np.zeros_like(f))
    expect = (1.0 + imu.scale[:3]) * f[0] + imu.bias[:3]
    np.testing.assert_allclose(acc.mean(axis=0), expect, atol=4 * 0.08 / math.sqrt(20000))
    assert abs(imu.scale[2]) > 0  # a scale error was drawn


def test_ahrs_converges_to_the_accelerometer_tilt_and_heading_reference():
    """Static vehicle, yaw 30°, gyro bias: the tilt error decays (τ = 1/kp) to the accelerometer-bias
    tilt, the heading to truth + the reference's bias, and the integral learns the gyro bias."""
    cfg = AhrsConfig(enabled=True, heading_noise_rad=0.0, initial_tilt_error_rad=0.05)
    yaw = math.radians(30.0)
    q_true = np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])
    ahrs = Ahrs(cfg, 200.0, q_true, np.random.default_rng(2))
    e0 = float(attitude_error_rad(np.array([ahrs.q]), q_true[None])[0])
    assert e0 > 0.02
    b_acc = np.array([0.05, -0.03, 0.0])  # tilt error it causes: atan(|b_h| / g)
    b_gyro = np.array([0.004, -0.003, 0.002])
    f = np.tile(np.array([0.0, 0.0, -G]) + b_acc, (200, 1))
    w = np.tile(b_gyro, (200, 1))
    q_blk = np.tile(q_true, (200, 1))
    for _ in range(300):  # 300 s: 30 roll/pitch time constants (1/kp), 6 of the bias loop (kp/ki = 50 s)
        q = ahrs.update(f, w, q_blk)
    tilt_expected = math.atan(np.hypot(*b_acc[:2]) / G)

    down_est, down_true = rotation_matrix(q[-1:])[0][2], rotation_matrix(q_true[None])[0][2]
    tilt = math.acos(min(1.0, float(down_est @ down_true)))
    assert tilt == pytest.approx(tilt_expected, abs=0.1 * tilt_expected)
    assert yaw_of(q[-1]) - yaw == pytest.approx(ahrs.heading_bias_rad, abs=2e-3)
    np.testing.assert_allclose(ahrs.gyro_bias_rad_s, b_gyro, atol=2e-4)


def test_line_of_sight_known_answers():
    """One 10 m × 10 m building 30 m high, 10 m north of the vehicle flying at 20 m."""
    cfg = GnssConfig(constellation_size=4)
    rects = np.array([[10.0, -5.0, 20.0, 5.0]])
    sky = Constellation(cfg, rects, np.array([30.0]), np.random.default_rng(0))
    sky.azimuth_rad = np.radians([0.0, 0.0, 180.0, 90.0])  # N, N, S, E
    sky.elevation_rad = np.radians([30.0, 60.0, 30.0, 30.0])
    # north at 30°: at 10 m the ray is at 20 + 5.8 < 30 → blocked; at 60° it is at 37 m → clear
    blocked = sky.blocked(np.array([0.0, 0.0, -20.0]))
    assert blocked.tolist() == [True, False, False, False]
    assert not sky.blocked(np.array([0.0, 0.0, -40.0])).any()  # above the roof


def test_position_error_least_squares_known_answers():
    sky = Constellation(GnssConfig(), np.zeros((0, 4)), np.zeros(0), np.random.default_rng(4))
    used = np.ones(len(sky.azimuth_rad), dtype=bool)
    dx, pdop = position_error(sky.u_ned, used, np.zeros(used.size))
    np.testing.assert_allclose(dx, 0.0, atol=1e-12)
    # the same delay on every satellite is a receiver-clock offset: no position error
    dx, _ = position_error(sky.u_ned, used, np.full(used.size, 7.0))
    np.testing.assert_allclose(dx, 0.0, atol=1e-9)
    # one delayed satellite: the residual of the LS solution is orthogonal to the geometry
    delay = np.zeros(used.size)
    delay[0] = 10.0
    dx, _ = position_error(sky.u_ned, used, delay)
    Gm = np.column_stack([-sky.u_ned, np.ones(used.size)])
    sol = np.linalg.lstsq(Gm, delay, rcond=None)[0]
    np.testing.assert_allclose(dx, sol[:3], atol=1e-9)
    assert pdop > 0 and np.linalg.norm(dx) > 0.1


def test_heavy_tail_keeps_the_variance_and_fattens_the_tails():
    cfg = GnssConfig(heavy_tail_dof=5.0)
    u = UnmodelledGnss(cfg, np.zeros((0, 4)), np.zeros(0), np.random.default_rng(9))
    scale = np.array([u.step(np.zeros(3)).noise_scale for _ in range(5000)])
    z = scale * np.random.default_rng(10).standard_normal(scale.size)
    assert np.var(z) == pytest.approx(1.0, rel=0.2)  # t₅ (kurtosis 9): sd of the estimate 0.04
    assert np.mean(np.abs(z) > 4.0) > 20 * 6.3e-5  # P(|N| > 4) = 6.3e-5; unit-variance t₅: 3.6e-3


def test_nlos_draws_do_not_depend_on_the_path_flown():
    """Common random numbers: satellite i's k-th blocked episode gets the same (tracked, delay)
    whatever other satellites did before, so two paths through the same seed meet the same
    reflections (one shared stream would shift every later draw)."""
    cfg = GnssConfig(constellation_size=4, nlos=True, nlos_reflect_prob=1.0, heavy_tail_dof=4.0)

    def episodes(order: list[list[int]]) -> tuple[dict[int, list[float]], list[float]]:
        u = UnmodelledGnss(cfg, np.zeros((0, 4)), np.zeros(0), np.random.default_rng(11))
        seen: dict[int, list[float]] = {}
        tails = []
        for blocked in order:  # drive the blocked pattern directly, one fix per entry
            mask = np.zeros(4, dtype=bool)
            mask[blocked] = True
            u.sky.blocked = lambda p, m=mask: m  # type: ignore[method-assign]
            tails.append(u.step(np.zeros(3)).noise_scale)
            for i in np.flatnonzero(mask & (u._delay_m > 0)).tolist():
                if not seen.get(i) or seen[i][-1] != u._delay_m[i]:
                    seen.setdefault(i, []).append(float(u._delay_m[i]))
        return seen, tails

    # path A: satellite 0 blocked twice, then 1; path B: 1 first, 0 blocked in between, different timing
    a, tails_a = episodes([[0], [], [0], [0, 1], [], []])
    b, tails_b = episodes([[1], [1], [], [0], [], [0]])
    assert a[0] == b[0] and len(a[0]) == 2  # satellite 0's two episodes: the same delays
    assert a[1] == b[1] and len(a[1]) == 1
    assert a[0][0] != a[0][1] and a[0][0] != a[1][0]  # fresh draws per episode and per satellite
    assert tails_a == tails_b  # the heavy tail: one draw per fix from its own stream


def test_scenarios_configure_the_simulator_and_reject_unknown_names():
    m = load_mission("test")
    paper = sim_config_for(m)
    assert paper.imu.ideal and not paper.ahrs.enabled and not paper.gnss.unmodelled
    real = sim_config_for(with_scenario(m, "realistic"))
    assert real.imu.acc_noise_density_m_s2_rt_hz == pytest.approx(70e-6 * G) and real.ahrs.enabled
    assert not real.gnss.unmodelled
    mis = sim_config_for(with_scenario(m, "mismatch"))
    assert mis.gnss.nlos and mis.gnss.heavy_tail_dof == 3.0 and mis.gnss.gamma_canyon_s == 10.0
    # the mission's own section wins over the scenario's
    own = with_scenario(dataclasses.replace(m, sections={"gnss": {"gamma_canyon_s": 5.0}}), "mismatch")
    assert sim_config_for(own).gnss.gamma_canyon_s == 5.0 and sim_config_for(own).gnss.nlos
    with pytest.raises(ConfigError, match="'urban': not one of paper, realistic, mismatch"):
        with_scenario(m, "urban")


def test_realistic_flight_sends_an_estimated_attitude_and_mismatch_fixes_step():
    m = load_mission("test")
    sim = SimVehicle(with_scenario(m, "mismatch"), 0, 3)
    err = []
    for _ in range(40):
        out = sim.advance(None, None)
        err.append(attitude_error_rad(out.q_att_ned_frd, out.q_ned_frd))
    err = np.concatenate(err)
    assert 1e-4 < np.median(err) < math.radians(10)  # an estimate: neither the truth nor lost
    assert out.attitude[-1].q_ned_frd.tolist() == out.q_sent_ned_frd[-1].tolist()
    assert sim.gnss.unmodelled is not None and sim.gnss.sent == 40
    paper = SimVehicle(m, 0, 3).advance(None, None)
    assert paper.q_sent_ned_frd is None
    assert paper.attitude[0].q_ned_frd.tolist() == paper.q_ned_frd[0].tolist()


def test_sitl_passes_the_scenario_to_the_vehicle_process(tmp_path):
    from simvehicle.harness.sitl.launcher import SitlOptions, child_specs

    specs = child_specs(SitlOptions("test", 0, "naive", 0, tmp_path, scenario="mismatch"), (1, 2, 3))
    vehicle = next(s for s in specs if s.name == "vehicle").module_argv
    assert vehicle[vehicle.index("--scenario") + 1] == "mismatch"
    plain = child_specs(SitlOptions("test", 0, "naive", 0, tmp_path), (1, 2, 3))
    assert "--scenario" not in next(s for s in plain if s.name == "vehicle").module_argv
