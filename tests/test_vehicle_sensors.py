"""IMU and GNSS degradation models (eq. 22-27): statistics with stated tolerances, seeded."""

import math

import numpy as np
import pytest
from vehicle_world import FixtureMission, RectWorld

from companion.domain.rotation import rotation_matrix
from simvehicle import SimVehicle
from simvehicle.config import GnssConfig, ImuConfig, VehicleConfig
from simvehicle.gnss import GnssModel, NedToGeodetic, conditions
from simvehicle.imu import Imu, specific_force_frd

PERIOD_S = 0.05
FRAME = FixtureMission().frame


def test_imu_at_hover_reads_minus_g():
    sim = SimVehicle(FixtureMission(), 0, seed=4)
    acc = []
    for _ in range(200):  # 10 s of hover, 2000 samples
        out = sim.advance(None, None)
        acc += [s.acc_frd_m_s2 for s in out.imu]
    # the mean is within 5 standard errors (0.08 / sqrt(2000) = 1.8 mm/s²) plus 2 mm/s² of real motion
    tol = 5 * 0.08 / math.sqrt(2000) + 2e-3
    np.testing.assert_allclose(np.mean(acc, axis=0), [0.0, 0.0, -9.81], atol=tol)


def test_imu_noise_has_configured_std_and_is_seeded():
    cfg = ImuConfig()
    f, w = np.tile([0.1, -0.2, -9.81], (20_000, 1)), np.tile([0.01, 0.0, -0.02], (20_000, 1))
    acc, gyro = Imu(cfg, np.random.default_rng(1)).measure(f, w)
    # 20k samples per axis: std of the std estimate 0.5 % -> 3 %; mean within 5 standard errors
    np.testing.assert_allclose((acc - f).std(axis=0), cfg.sigma_acc_m_s2, rtol=0.03)
    np.testing.assert_allclose((gyro - w).std(axis=0), cfg.sigma_gyro_rad_s, rtol=0.03)
    np.testing.assert_allclose((acc - f).mean(axis=0), 0.0, atol=5 * cfg.sigma_acc_m_s2 / math.sqrt(20_000))
    again, _ = Imu(cfg, np.random.default_rng(1)).measure(f, w)
    np.testing.assert_array_equal(acc, again)


def test_specific_force_is_rotated_drag_plus_thrust():
    cfg = VehicleConfig(drag_n_s_m=2.0)
    q = np.array([math.cos(0.2), 0.1, math.sin(0.2), -0.3])
    q /= np.linalg.norm(q)
    v = np.array([3.0, -1.0, 0.5])
    f = np.array([specific_force_frd(cfg, 50.0, [0.0, 0.0, 0.0, *v, *q, 0.0, 0.0, 0.0])])
    R = rotation_matrix(q[None, :])[0]
    np.testing.assert_allclose(f[0], R.T @ (-2.0 * v) / 5.0 + [0, 0, -10.0], atol=1e-14)
    noisy, _ = Imu(ImuConfig(sigma_acc_m_s2=0.0), np.random.default_rng(0)).measure(f, np.zeros((1, 3)))
    np.testing.assert_array_equal(noisy, f)


def gm_series(cfg: GnssConfig, clearance_m: float, n: int, seed: int = 0):
    model = GnssModel(cfg, PERIOD_S, FRAME, np.random.default_rng(seed), clearance_m)
    bias, lat = np.empty((n, 3)), np.empty(n)
    for k in range(n):
        model.step(clearance_m)
        bias[k], lat[k] = model.bias_ned_m, model.latency_s
    return bias, lat


@pytest.mark.parametrize("clearance_m", [2.0, 10.0, 40.0])  # canyon, half-way, open sky
def test_gauss_markov_bias_has_configured_std_and_correlation_time(clearance_m):
    cfg = GnssConfig()
    c = conditions(cfg, clearance_m)
    bias, _ = gm_series(cfg, clearance_m, 60_000, seed=7)
    # 60k steps x 3 axes; effective sample size >= 3 * 60k * 0.0167 / 2 = 1500 -> std within 6 %
    assert bias.std() == pytest.approx(c.sigma_bias_m, rel=0.06)
    # lag-1 autocorrelation estimates κ = exp(-Δt/Γ); Γ within 8 %
    x = bias - bias.mean(axis=0)
    kappa = (x[1:] * x[:-1]).sum() / (x[:-1] ** 2).sum()
    assert -PERIOD_S / math.log(kappa) == pytest.approx(c.gamma_s, rel=0.08)


def test_gauss_markov_scales_with_proximity():
    cfg = GnssConfig()
    near, mid, far = (conditions(cfg, d) for d in (1.0, 10.0, 50.0))
    assert near.sigma_bias_m == cfg.sigma_bias_max_m and far.sigma_bias_m == cfg.sigma_bias_open_m
    assert near.gamma_s == cfg.gamma_canyon_s and far.gamma_s == cfg.gamma_open_s
    assert near.sigma_noise_m == pytest.approx(0.10) and far.sigma_noise_m == pytest.approx(0.08)
    assert far.latency_mean_s < mid.latency_mean_s < near.latency_mean_s
    assert near.satellites < far.satellites


def test_latency_has_configured_mean_and_respects_the_cap():
    cfg = GnssConfig()
    _, lat = gm_series(cfg, 2.0, 40_000, seed=3)
    # stationary std 0.03 / sqrt(1 - ζ²) ≈ 0.15 s; correlation 50 steps -> ~400 effective samples,
    # standard error 7.5 ms: mean within 30 ms
    assert lat.mean() == pytest.approx(cfg.latency_canyon_s, abs=0.03)
    assert lat.std() == pytest.approx(0.03 / math.sqrt(1 - math.exp(-2 * PERIOD_S / 2.5)), rel=0.15)
    # a mean at the cap: clipped, never above it, never negative (open-sky mean at 0 likewise)
    _, lat = gm_series(GnssConfig(latency_canyon_s=1.2, latency_open_s=0.0), 2.0, 20_000, seed=5)
    assert lat.max() == 1.2 and (lat == 1.2).mean() > 0.05
    _, lat = gm_series(GnssConfig(latency_canyon_s=1.2, latency_open_s=0.0), 50.0, 20_000, seed=5)
    assert lat.min() == 0.0 and (lat == 0.0).mean() > 0.05


def test_fixes_arrive_after_their_latency_some_out_of_order():
    world = RectWorld(((-20.0, 6.0, 20.0, 30.0),))  # building 6 m east of the hover point: canyon
    sim = SimVehicle(FixtureMission(world=world), 0, seed=11)
    validity, arrival = [], []
    for _ in range(1200):  # 60 s
        out = sim.advance(None, None)
        for fix, t_arr in zip(out.gnss, out.gnss_arrival_us, strict=True):
            validity.append(fix.t_validity_us)
            arrival.append(t_arr)
            assert sim.t_us - 50_000 < t_arr <= out.t_us
    validity, arrival = np.array(validity), np.array(arrival)
    delay_s = (arrival - validity) * 1e-6
    assert delay_s.min() >= 0 and delay_s.max() <= 1.2 + 0.005
    assert delay_s.mean() == pytest.approx(0.6, abs=0.15)  # canyon mean latency, rounded up to a tick
    assert np.all(np.diff(arrival) >= 0)
    assert (np.diff(validity) < 0).sum() > 5  # out of order
    assert sim.gnss.sent == len(validity) + sim.gnss.pending
    assert set(validity % 50_000) == {0}  # validity on the 20 Hz grid


def test_fix_is_truth_plus_truth_bias_plus_white_noise():
    world = RectWorld(((-20.0, 4.0, 20.0, 30.0),))  # canyon (w = 1): bias std 1.2 m, noise 0.10 m
    sim = SimVehicle(FixtureMission(world=world), 0, seed=2)
    truth, fixes = {}, []
    for _ in range(600):
        out = sim.advance(None, None)
        truth.update((t.t_us, t) for t in out.truth)
        fixes += out.gnss
    resid = np.array([
        FRAME.to_ned_m(f.lat_deg, f.lon_deg, f.alt_m) - truth[f.t_validity_us].p_ned_m
        - truth[f.t_validity_us].gnss_bias_ned_m
        for f in fixes
    ])
    assert len(resid) > 500
    sigma = conditions(GnssConfig(), 4.0).sigma_noise_m
    assert sigma == pytest.approx(0.10)
    # ~1700 residuals: std within 6 %, mean within 5 standard errors
    np.testing.assert_allclose(resid.std(axis=0), sigma, rtol=0.06)
    np.testing.assert_allclose(resid.mean(axis=0), 0.0, atol=5 * sigma / math.sqrt(len(resid)))
    assert all(f.h_acc_m == pytest.approx(sigma) and f.fix_type == 3 for f in fixes)


def test_ned_to_geodetic_inverts_the_library_map():
    inv = NedToGeodetic(FRAME)
    rng = np.random.default_rng(0)
    for scale, tol_m in ((1000.0, 1e-4), (5000.0, 1e-6)):  # one correction within 1 km, iterated beyond
        for p in rng.uniform(-scale, scale, (40, 3)):
            lat, lon, alt = inv(p)
            np.testing.assert_allclose(FRAME.to_ned_m(lat, lon, alt), p, atol=tol_m)
            np.testing.assert_allclose((lat, lon), FRAME.to_geodetic(p)[:2], atol=tol_m * 1e-5)


def test_normal_blocks_serve_the_generators_own_stream():
    from simvehicle.noise import NormalBlocks

    blocks, direct = NormalBlocks(np.random.default_rng(9), block_size=50), np.random.default_rng(9)
    for n in (3, 4, 60, 7, 0, 45, 120, 1):  # across block edges and larger than a block
        np.testing.assert_array_equal(blocks.take(n), direct.standard_normal(n))


@pytest.mark.parametrize(("clearance_m", "speed_m_s"), [(40.0, 0.0), (40.0, 8.0), (2.0, 0.0), (2.0, 8.0)])
def test_doppler_velocity_error_is_white_and_grows_with_speed_only_in_a_canyon(clearance_m, speed_m_s):
    """The receiver's velocity (gnss.velocity): per-axis std sqrt(σ_v² + (w κ |v|)²) (w the proximity
    weight), zero mean, uncorrelated fix to fix, reported as the speed accuracy; its draws do not
    change the positions."""
    cfg = GnssConfig(velocity=True)
    v = np.array([speed_m_s * 0.6, speed_m_s * 0.8, 0.0])
    model = GnssModel(cfg, PERIOD_S, FRAME, np.random.default_rng(3), clearance_m,
                      velocity_rng=np.random.default_rng(4))
    plain = GnssModel(GnssConfig(), PERIOD_S, FRAME, np.random.default_rng(3), clearance_m)
    n = 6_000
    err = np.empty((n, 3))
    for k in range(n):
        fix = model.sample(k * 50_000, np.zeros(3), clearance_m, v)
        assert np.array_equal(fix.p_ned_m, plain.sample(k * 50_000, np.zeros(3), clearance_m).p_ned_m)
        err[k] = fix.v_ned_m_s - v
    w = conditions(cfg, clearance_m).weight
    expected = math.hypot(cfg.sigma_velocity_m_s, w * cfg.velocity_reflection_factor * speed_m_s)
    assert fix.sigma_velocity_m_s == pytest.approx(expected, rel=1e-12)
    assert model.to_fix(fix).vel_acc_m_s == fix.sigma_velocity_m_s
    np.testing.assert_allclose(err.std(axis=0), expected, rtol=0.05)  # 6k samples: std known to 0.9 %
    np.testing.assert_allclose(err.mean(axis=0), 0.0, atol=5 * expected / math.sqrt(n))
    assert abs(np.corrcoef(err[1:, 0], err[:-1, 0])[0, 1]) < 0.06  # 5 standard errors
    assert GnssModel(GnssConfig(), PERIOD_S, FRAME, np.random.default_rng(3), 2.0).sample(
        0, np.zeros(3), 2.0, v).v_ned_m_s is None  # the paper's receiver: positions only
