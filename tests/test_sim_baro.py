"""The simulator's barometer (simvehicle.baro) and its HIGHRES_IMU fields: statistics with stated tolerances,
seeded, on its own random stream (the flight and every other sensor unchanged)."""

import dataclasses
import math

import numpy as np
from vehicle_world import FixtureMission

from companion.mavlink import codec as mc
from simvehicle import SimVehicle
from simvehicle.baro import Barometer, standard_pressure_hpa
from simvehicle.config import ImuConfig, sim_config_for
from tests.test_mavlink_codec import wire


def test_standard_atmosphere_known_answers():
    # the ICAO standard atmosphere's table at geopotential altitudes 0, 1000 and 5000 m (hPa)
    np.testing.assert_allclose(standard_pressure_hpa(np.array([0.0, 1000.0, 5000.0])),
                               [1013.25, 898.75, 540.20], atol=0.02)


def test_barometer_noise_drift_and_datum_are_as_configured_and_seeded():
    cfg = ImuConfig(baro_sigma_m=0.15, baro_drift_m_s=0.01, baro_walk_m_rt_s=0.0, baro_datum_sigma_m=30.0)
    n, rate = 20_000, 200.0
    t = np.arange(1, n + 1) / rate
    h = 5.0 * np.sin(t)
    b = Barometer(cfg, np.random.default_rng(3), rate, 34.0)
    pa, hpa, temp = b.measure(t, h)
    err = pa - (34.0 + h) - b.datum_m - b.drift_rate_m_s * t  # the white part alone (no walk)
    # 20k samples: std of the std estimate 0.5 % -> 3 %; mean within 5 standard errors
    assert abs(err.std() / 0.15 - 1.0) < 0.03 and abs(err.mean()) < 5 * 0.15 / math.sqrt(n)
    assert b.datum_m != 0.0 and b.drift_rate_m_s != 0.0
    np.testing.assert_allclose(hpa, standard_pressure_hpa(pa))
    assert np.all((temp > 20.0) & (temp < 30.0))
    again = Barometer(cfg, np.random.default_rng(3), rate, 34.0).measure(t, h)[0]
    np.testing.assert_array_equal(pa, again)
    # the random walk: the variance of its n-sample increments is walk² n / rate
    walk = dataclasses.replace(cfg, baro_sigma_m=0.0, baro_drift_m_s=0.0, baro_datum_sigma_m=0.0,
                               baro_walk_m_rt_s=0.02)
    w = Barometer(walk, np.random.default_rng(4), rate, 0.0).measure(t, np.zeros(n))[0]
    steps = np.diff(w[::200])  # 1 s apart: σ 0.02 m; 99 of them: the std within 25 %
    assert abs(steps.std() / 0.02 - 1.0) < 0.25


def test_vehicle_sends_its_barometer_and_flies_the_same_without_it():
    m = FixtureMission()
    cfg = sim_config_for(m)
    off = dataclasses.replace(cfg, imu=dataclasses.replace(cfg.imu, baro=False))
    a, b = SimVehicle(m, 0, 5, cfg), SimVehicle(m, 0, 5, off)
    for _ in range(40):  # 2 s
        oa, ob = a.advance(None, None), b.advance(None, None)
        np.testing.assert_array_equal(oa.acc_frd_m_s2, ob.acc_frd_m_s2)
        np.testing.assert_array_equal(oa.p_ned_m, ob.p_ned_m)
        assert ob.baro is None and all(s.pressure_alt_m is None for s in ob.imu)
    alt = np.array([s.pressure_alt_m for s in oa.imu])
    truth = m.frame.home_alt_m - oa.p_ned_m[:, 2]
    # datum (σ 30 m) + 2 s of drift (σ 0.02 m) + white 0.15 m: the same offset on every sample to ±1 m
    off_m = alt - truth
    assert abs(off_m - a.baro.datum_m).max() < 1.0 and off_m.std() < 0.3
    msg = wire(mc.encode_imu(oa.imu[-1], float(oa.baro[1][-1]), float(oa.baro[2][-1])))
    assert msg.fields_updated == 63 | (1 << 9) | (1 << 11) | (1 << 12)
    assert msg.abs_pressure == np.float32(oa.baro[1][-1])
    assert mc.decode_imu(msg).pressure_alt_m == np.float32(alt[-1])
