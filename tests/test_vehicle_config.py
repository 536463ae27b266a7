"""SimVehicle: determinism, start state, collisions and one-line config errors."""

import numpy as np
import pytest
from vehicle_world import FixtureMission, Profile, RectWorld

from companion.domain.samples import NavEstimate, Setpoint
from companion.errors import UserError
from companion.mission.schema import ConfigError
from simvehicle import SimVehicle
from simvehicle.config import SimConfig, sim_config_for


def run(seed: int, periods: int = 60):
    sim = SimVehicle(FixtureMission(world=RectWorld(((-20.0, 8.0, 20.0, 30.0),))), 0, seed)
    outs = [sim.advance(None, None) for _ in range(periods)]
    imu = np.array([s.acc_frd_m_s2 for o in outs for s in o.imu])
    truth = np.array([s.p_ned_m for o in outs for s in o.truth])
    gnss = np.array([(f.t_validity_us, f.lat_deg, f.lon_deg, f.alt_m) for o in outs for f in o.gnss])
    return imu, truth, gnss


def test_same_seed_same_run_bit_for_bit_and_different_seeds_differ():
    a, b, c = run(5), run(5), run(6)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)
    for x, z in zip(a, c, strict=True):
        assert x.shape != z.shape or not np.array_equal(x, z)


def test_starts_hovering_at_flight_altitude_over_the_profile_start():
    profiles = (Profile((0.0, 0.0), (1.0, 1.0)), Profile((12.0, -7.0), (0.0, 0.0)))
    m = FixtureMission(profiles=profiles, altitude_m=42.0)
    sim = SimVehicle(m, 1, 0)
    np.testing.assert_array_equal(sim.start_ned_m, [12.0, -7.0, -42.0])
    out = sim.advance(None, None)
    assert out.t_us == 50_000 and len(out.imu) == len(out.attitude) == len(out.truth) == 10
    assert [s.t_us for s in out.imu] == list(range(5_000, 50_001, 5_000))
    assert np.linalg.norm(out.truth[-1].p_ned_m - sim.start_ned_m) < 0.01
    with pytest.raises(UserError, match="profile 2"):
        SimVehicle(m, 2, 0)


def test_collision_with_a_building_is_reported():
    m = FixtureMission(world=RectWorld(((10.0, -5.0, 20.0, 5.0),)))  # wall 10 m north of the start
    sim = SimVehicle(m, 0, 0)
    hit_at = None
    for k in range(200):
        x, zero = sim.body.x, np.zeros(3)
        est = NavEstimate(sim.t_us, np.array(x[0:3]), np.array(x[3:6]), zero, np.zeros(9), 1.0, 0.0, "x")
        out = sim.advance(est, Setpoint(sim.t_us, sim.start_ned_m + [20.0, 0.0, 0.0], zero, zero))
        if out.collided:
            hit_at = k
            break
    assert hit_at is not None
    assert out.truth[-1].p_ned_m[0] > 10.0 - sim.config.vehicle.radius_m
    assert out.truth[-1].clearance_m < sim.config.vehicle.radius_m


@pytest.mark.parametrize(
    ("sections", "message"),
    [
        ({"vehicle": {"mass_kgs": 5}}, "fixture: vehicle: unknown key 'mass_kgs'"),
        ({"vehicle": {"mass_kg": "heavy"}}, "fixture: vehicle.mass_kg: expected a number, got 'heavy'"),
        ({"vehicle": {"mass_kg": -1}}, "fixture: vehicle: mass_kg: must be > 0"),
        ({"vehicle": {"inertia_kg_m2": [0.1, 0.1]}}, "fixture: vehicle.inertia_kg_m2: expected 3 items"),
        ({"vehicle": {"max_thrust_n": 20}}, "fixture: vehicle: max_thrust_n: must exceed the weight"),
        ({"autopilot": {"max_tilt_deg": 95}}, "fixture: autopilot: max_tilt_deg: must be in (0, 80)"),
        ({"imu": {"sigma_acc_m_s2": -0.1}}, "fixture: imu: sigma_acc_m_s2: must be >= 0"),
        ({"ahrs": {"gnss_timeout_s": 0}}, "fixture: ahrs: gnss_timeout_s: must be > 0"),
        ({"receiver": {"diffuse_time_s": 0}}, "fixture: receiver: diffuse_time_s: must be > 0"),
        ({"receiver": {"diffuse_k_los_db": float("nan")}},
         "fixture: receiver.diffuse_k_los_db: expected a finite number, got nan"),
        ({"gnss": {"latency_canyon_s": 2.0}}, "fixture: gnss: latency_open_s/latency_canyon_s: must not"),
        ({"gnss": {"r_urban": 0.5}}, "fixture: gnss: r_urban: must be >= 1"),
        ({"gnss": ["x"]}, "fixture: gnss: expected a mapping"),
    ],
)
def test_bad_override_sections_give_one_line_errors(sections, message):
    with pytest.raises(ConfigError) as info:
        sim_config_for(FixtureMission(sections=sections))
    text = str(info.value)
    assert text.startswith(message) and "\n" not in text


def test_overrides_change_only_what_they_name():
    cfg = sim_config_for(FixtureMission(sections={"vehicle": {"mass_kg": 4}, "gnss": {"d_near_m": 20}}))
    default = SimConfig()
    assert cfg.vehicle.mass_kg == 4.0 and cfg.gnss.d_near_m == 20.0
    assert cfg.vehicle.inertia_kg_m2 == default.vehicle.inertia_kg_m2 and cfg.imu == default.imu


def test_lazy_samples_match_the_period_arrays_and_the_ned_fixes():
    sim = SimVehicle(FixtureMission(world=RectWorld(((-20.0, 8.0, 20.0, 30.0),))), 0, 3)
    outs = [sim.advance(None, None) for _ in range(40)]
    fixes = [(f, g) for o in outs for f, g in zip(o.gnss, o.gnss_ned, strict=True)]
    assert len(fixes) > 20
    for fix, ned in fixes:  # the wire fix is the NED fix in geodetic form
        assert fix.t_validity_us == ned.t_validity_us and fix.satellites_visible == ned.satellites
        np.testing.assert_allclose(FixtureMission().frame.to_ned_m(fix.lat_deg, fix.lon_deg, fix.alt_m),
                                   ned.p_ned_m, atol=1e-6)
    out = outs[-1]
    last, final = out.truth[-1], out.final_truth
    assert final.t_us == last.t_us == out.t_us and final.clearance_m == last.clearance_m == sim.clearance_m
    for name in ("p_ned_m", "v_ned_m_s", "q_ned_frd", "gnss_bias_ned_m"):
        np.testing.assert_array_equal(getattr(final, name), getattr(last, name))
    np.testing.assert_array_equal([s.acc_frd_m_s2 for s in out.imu], out.acc_frd_m_s2)
    np.testing.assert_array_equal([s.q_ned_frd for s in out.attitude], out.q_ned_frd)
