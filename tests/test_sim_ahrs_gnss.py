"""The simulated autopilot's GNSS-velocity gravity reference (simvehicle.ahrs) and its measure
(gcs_tools.evaluate.attitude_check): known answers."""

import dataclasses
import math

import numpy as np
import pytest

from companion.mission import load_mission, with_scenario
from gcs_tools.evaluate.attitude_check import central_velocity, tilt_error_rad, velocity_error_density
from simvehicle import SimVehicle
from simvehicle.ahrs import Ahrs, gnss_tilt_error
from simvehicle.config import AhrsConfig, sim_config_for

G = 9.80665
RATE = 200.0
PERIOD = 40  # samples per update: 0.2 s, one fix at its end


def _fly(cfg: AhrsConfig, acc_n: float, seconds: float, fixes: bool = True, sats: int = 10,
         lag_s: float = 0.08, b_acc: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> float:
    """Level vehicle, yaw 0, accelerating north at ``acc_n`` (specific force (a, 0, −g) + b_acc in body);
    its receiver's velocity valid ``lag_s`` before each fix's arrival. The final tilt error (rad)."""
    q_true = np.array([1.0, 0.0, 0.0, 0.0])
    ahrs = Ahrs(cfg, RATE, q_true, np.random.default_rng(3))
    f = np.tile(np.array([acc_n, 0.0, -G]) + np.array(b_acc), (PERIOD, 1))
    w = np.zeros((PERIOD, 3))
    q_blk = np.tile(q_true, (PERIOD, 1))
    q = ahrs.update(f, w, q_blk)
    for k in range(1, round(seconds * RATE / PERIOD)):
        t_arrival = (k + 1) * PERIOD / RATE
        gnss = [(PERIOD - 1, np.array([acc_n * (t_arrival - lag_s), 0.0, 0.0]), sats)] if fixes else []
        q = ahrs.update(f, w, q_blk, gnss)
    return float(tilt_error_rad(q[-1:], q_true[None])[0])


def test_constant_acceleration_the_compensated_filter_keeps_the_tilt_mahony_converges_to_atan_a_g():
    a = 2.0  # m/s²: the plain filter's gravity is tilted by atan(a / g) = 11.5°
    # 300 s: 6 time constants of the bias loop (kp / ki = 50 s), which overshoots on the way
    # no heading bias: a heading error ψ turns the IMU's acceleration off the GNSS one by ψ, a tilt
    # error ≈ a ψ / g remains (which a real autopilot's EKF turns into a heading estimate)
    base = AhrsConfig(enabled=True, heading_noise_rad=0.0, heading_bias_rad=0.0, initial_tilt_error_rad=0.05)
    plain = _fly(base, a, 300.0)
    assert plain == pytest.approx(math.atan(a / G), rel=0.002)
    aided_cfg = dataclasses.replace(base, gnss_velocity_reference=True)
    aided = _fly(aided_cfg, a, 300.0)
    assert aided < math.radians(0.1)  # the initial 0.05 rad error removed, the acceleration not leaking in
    # GNSS lost (no fixes, or too few satellites): back to the accelerometer alone, as DCM falls back
    assert _fly(aided_cfg, a, 300.0, fixes=False) == pytest.approx(plain, abs=1e-9)
    assert _fly(aided_cfg, a, 300.0, sats=5) == pytest.approx(plain, abs=1e-9)


def test_stationary_the_aided_filter_converges_where_the_plain_one_does():
    """At rest the reference is gravity either way: both converge to the accelerometer-bias tilt."""
    b_acc = (0.05, -0.03, 0.0)
    expected = math.atan(math.hypot(*b_acc[:2]) / G)
    base = AhrsConfig(enabled=True, heading_noise_rad=0.0, initial_tilt_error_rad=0.05)
    plain = _fly(base, 0.0, 300.0, b_acc=b_acc)
    aided = _fly(dataclasses.replace(base, gnss_velocity_reference=True), 0.0, 300.0, b_acc=b_acc)
    assert plain == pytest.approx(expected, rel=0.05)
    assert aided == pytest.approx(expected, rel=0.05)


def test_off_the_fixes_change_nothing():
    cfg = AhrsConfig(enabled=True)
    q_true = np.array([1.0, 0.0, 0.0, 0.0])
    rng = np.random.default_rng(0)
    f = np.array([0.0, 0.0, -G]) + 0.1 * rng.standard_normal((PERIOD, 3))
    w = 0.01 * rng.standard_normal((PERIOD, 3))
    a = Ahrs(cfg, RATE, q_true, np.random.default_rng(1))
    b = Ahrs(cfg, RATE, q_true, np.random.default_rng(1))
    qa = a.update(f, w, np.tile(q_true, (PERIOD, 1)))
    qb = b.update(f, w, np.tile(q_true, (PERIOD, 1)), [(PERIOD - 1, np.array([3.0, 0.0, 0.0]), 10)])
    np.testing.assert_array_equal(qa, qb)


def test_gnss_tilt_error_known_answers():
    identity = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    dt = 0.2
    # accelerating north at 2 m/s², the IMU (true attitude) agreeing: no error
    e = gnss_tilt_error((2.0 * dt, 0.0, -G * dt), (2.0 * dt, 0.0, 0.0), dt, identity)
    assert e is not None and max(abs(c) for c in e) < 1e-12
    # the estimate pitched by θ sees the gravity reference tilted: the error about body y is ≈ −θ·sign
    th = 0.01
    f_int = (G * math.sin(th) * dt, 0.0, -G * math.cos(th) * dt)  # level truth, specific force seen as tilted
    e = gnss_tilt_error(f_int, (0.0, 0.0, 0.0), dt, identity)
    assert e is not None and abs(e[1]) == pytest.approx(math.sin(th), rel=1e-9) and abs(e[0]) < 1e-12


def test_a_realistic_flight_is_aided_and_seeded():
    m = with_scenario(load_mission("default-tuning"), "realistic")
    cfg = sim_config_for(m)
    cfg = dataclasses.replace(cfg, ahrs=dataclasses.replace(cfg.ahrs, gnss_velocity_reference=True))
    qs = []
    for _ in range(2):
        sim = SimVehicle(m, 0, 1000, cfg)
        for _ in range(40):  # 2 s at 20 Hz control
            out = sim.advance(None, None)
        assert sim.ahrs is not None and sim.ahrs.gnss_corrections > 5
        qs.append(out.q_sent_ned_frd)
    np.testing.assert_array_equal(qs[0], qs[1])


def test_velocity_error_density_known_answers():
    t = np.arange(0.0, 60.0, 0.005)
    v = np.column_stack([np.sin(t), np.cos(0.5 * t), 0 * t])
    a = np.column_stack([np.cos(t), -0.5 * np.sin(0.5 * t), 0 * t])
    # the acceleration integrates to the velocity change (to the rectangle rule's O(dt)), plus a constant
    assert velocity_error_density(t, a + [0.3, -0.2, 0.0], t, v, 2.0) < 0.01
    # white noise of std σ per 200 Hz sample: a density of σ / √200 at every window
    rng = np.random.default_rng(0)
    noise = 0.5 * rng.standard_normal(a.shape)
    for w in (0.2, 2.0):
        assert velocity_error_density(t, a + noise, t, v, w) == pytest.approx(0.5 / math.sqrt(200), rel=0.15)
    # a velocity from positions by central difference (sin's derivative)
    tt = np.arange(0.0, 10.0, 0.1)
    dv = central_velocity(tt, np.column_stack([np.sin(tt)]), np.array([2.0, 3.0]), half_s=0.05)
    np.testing.assert_allclose(dv[:, 0], np.cos([2.0, 3.0]), atol=3e-3)  # linear interpolation: O(h²)


def test_attitude_check_flies_a_scenario_with_an_ahrs():
    from companion.errors import UserError
    from gcs_tools.evaluate.attitude_check import sim_flight

    r = sim_flight("default-tuning", 0, 1000, True, max_duration_s=8.0, scenario="realistic")
    assert set(r["density"]) == {"0.2", "1", "2", "5"}
    assert all(math.isfinite(v) for v in r["density"].values())
    assert 0.0 < r["tilt_rms_deg"] < 10.0
    with pytest.raises(UserError, match="true attitude"):
        sim_flight("default-tuning", 0, 1000, True, max_duration_s=8.0, scenario="paper")
