"""Navigator front end: FRD→NED + gravity, geodesy, batch path, and every gated input reason."""

import math

import numpy as np
import pymap3d
import pytest

from companion.domain.geodesy import LocalNedFrame
from companion.domain.rotation import rotation_ned_frd, rotation_scaled
from companion.domain.samples import AttitudeSample, GnssFix, ImuSample
from companion.estimator import EstimatorConfig, Navigator
from tests.estimator_streams import multipath_stream

CFG = EstimatorConfig()
HOME = LocalNedFrame(-37.8136, 144.9631, 40.0)
G = CFG.gravity_m_s2
Q_LEVEL = np.array([1.0, 0.0, 0.0, 0.0])


def _fix(t_us: int, p_ned_m=(0.0, 0.0, 0.0), **kw) -> GnssFix:
    lat, lon, alt = HOME.to_geodetic(np.asarray(p_ned_m, dtype=float))
    return GnssFix(t_us, lat, lon, alt, kw.pop("fix_type", 3), 12, **kw)


def _imu(t_us: int, f=(0.0, 0.0, -G)) -> ImuSample:
    return ImuSample(t_us, np.asarray(f, dtype=float), np.zeros(3))


def _started(method: str = "naive") -> Navigator:
    nav = Navigator(CFG, method, HOME)
    nav.push(AttitudeSample(0, Q_LEVEL))
    nav.push(_imu(0))
    nav.push(_fix(0))
    return nav


def test_rotation_matches_axis_angle():
    yaw = 0.7
    q = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
    R = np.array(rotation_ned_frd(*q, math.sqrt)).reshape(3, 3)
    c, s = math.cos(yaw), math.sin(yaw)
    np.testing.assert_allclose(R, [[c, -s, 0], [s, c, 0], [0, 0, 1]], atol=1e-15)


def test_folded_quaternion_rotation_equals_the_matrix():
    """rotation_scaled (normalisation folded into s = 2/|q|²) = R(q/|q|), floats and arrays alike."""
    rng = np.random.default_rng(11)
    q = rng.normal(size=(50, 4)) * rng.uniform(0.5, 2.0, size=(50, 1))  # not unit norm
    w, x, y, z = q.T
    s = 2.0 / (w * w + x * x + y * y + z * z)
    got = np.stack(rotation_scaled(w, x, y, z, s), axis=1)
    for k in range(50):
        R = np.array(rotation_ned_frd(*q[k], math.sqrt))
        np.testing.assert_allclose(got[k], R, rtol=0, atol=1e-14)
        assert rotation_scaled(*q[k].tolist(), float(s[k])) == tuple(got[k])  # same bits


def test_hover_is_zero_acceleration_and_pitched_thrust_accelerates_north():
    nav = _started()
    for k in range(1, 201):
        nav.push(AttitudeSample(k * 5000, Q_LEVEL))
        nav.push(_imu(k * 5000))
    est = nav.estimate()
    np.testing.assert_allclose(est.v_ned_m_s, 0.0, atol=1e-12)
    # nose down by 0.1 rad with thrust balancing gravity vertically: a_north = g tan(0.1)
    th = -0.1
    q = np.array([math.cos(th / 2), 0.0, math.sin(th / 2), 0.0])
    f = (0.0, 0.0, -G / math.cos(th))
    for k in range(201, 401):
        nav.push(AttitudeSample(k * 5000, q))
        nav.push(_imu(k * 5000, f))
    est = nav.estimate()
    # the hover sample at k = 200 is held until k = 201: 199 periods of tilted thrust
    assert est.v_ned_m_s[0] == pytest.approx(G * math.tan(0.1) * 199 * 0.005, rel=1e-9)
    assert abs(est.v_ned_m_s[2]) < 1e-9


def test_geodetic_fix_becomes_local_ned_and_first_fix_is_home():
    nav = Navigator(CFG, "naive", frame=None)
    nav.push(AttitudeSample(0, Q_LEVEL))
    nav.push(_imu(0))
    nav.push(_fix(0, (12.0, -7.0, -3.0)))
    first = _fix(0, (12.0, -7.0, -3.0))
    assert nav.frame is not None and nav.frame.home_lat_deg == pytest.approx(first.lat_deg)
    np.testing.assert_allclose(nav.estimate().p_ned_m, 0.0, atol=1e-9)
    nav2 = _started()
    nav2.push(_fix(0 + 5000, (0.05, -0.03, 0.0)))  # waits for the IMU, then is fused
    nav2.push(AttitudeSample(5000, Q_LEVEL))
    nav2.push(_imu(5000))
    assert nav2.counters()["gnss_fused"] == 2
    assert nav2.estimate().p_ned_m[0] > 0.01  # pulled towards the second fix


def _feed(nav: Navigator, s, batch: bool, q: np.ndarray, f_all: np.ndarray) -> None:
    k0 = 0
    for j, k in enumerate(s.fix_index.tolist()):
        if j % 8 == 7 or j == len(s.fix_index) - 1:  # push IMU in blocks of 8 fixes (80 samples)
            ks = slice(k0, k + 1)
            f_frd = f_all[ks]
            if batch:
                nav.push_imu_batch(s.t_us[ks], f_frd, q[ks])
            else:
                for t, fk, qk in zip(s.t_us[ks].tolist(), f_frd, q[ks], strict=True):
                    nav.push(AttitudeSample(t, qk))
                    nav.push(ImuSample(t, fk, np.zeros(3)))
            for jj in range(j - 7 if j >= 7 else 0, j + 1):
                nav.push(_fix(int(s.fix_t_us[jj]), s.z_ned_m[jj]))
            k0 = k + 1


def test_batch_path_equals_per_sample_path():
    s = multipath_stream(np.random.default_rng(3), CFG, [(6.0, 0.0), (4.0, 1.2)])
    n = len(s.t_us)
    yaw = 0.3 * np.sin(0.5 * s.t_us * 1e-6)  # NED inputs are rotated back into a yawing body
    q = np.stack([np.cos(yaw / 2), np.zeros(n), np.zeros(n), np.sin(yaw / 2)], axis=1)
    f = s.a_ned_m_s2 - [0.0, 0.0, G]
    c, sn = np.cos(yaw), np.sin(yaw)
    f_frd = np.stack([c * f[:, 0] + sn * f[:, 1], -sn * f[:, 0] + c * f[:, 1], f[:, 2]], axis=1)
    a, b = Navigator(CFG, "second-order", HOME), Navigator(CFG, "second-order", HOME)
    _feed(a, s, batch=True, q=q, f_all=f_frd)
    _feed(b, s, batch=False, q=q, f_all=f_frd)
    ea, eb = a.estimate(), b.estimate()
    c = a.counters()
    assert c == b.counters() and c["gnss_fused"] + c["gnss_rejected_innovation"] == len(s.fix_t_us)
    for name in ("p_ned_m", "v_ned_m_s", "b_ned_m", "cov_diag"):
        np.testing.assert_allclose(getattr(ea, name), getattr(eb, name), rtol=1e-12, atol=1e-12)
    assert ea.beta == pytest.approx(eb.beta, abs=1e-12)
    assert a.engine.imu.rows[-50:] == b.engine.imu.rows[-50:]  # bit-for-bit inputs
    truth_gnss = s.x_true[-1, :3] + s.x_true[-1, 6:9]
    assert np.linalg.norm(ea.p_ned_m + ea.b_ned_m - truth_gnss) < 0.5  # and it navigates


def test_every_rejection_reason_is_counted_and_output_stays_finite():
    nav = Navigator(CFG, "second-order", HOME)
    nav.push(_imu(0))  # no attitude yet
    nav.push(_fix(0))  # no IMU yet
    nav.push(AttitudeSample(0, np.array([np.nan, 0.0, 0.0, 0.0])))
    nav.push(AttitudeSample(0, np.zeros(4)))
    nav.push(AttitudeSample(0, Q_LEVEL))
    nav.push(_imu(0))
    nav.push(_fix(0))
    for k in range(1, 400):
        nav.push(_imu(k * 5000))
    now = 399 * 5000
    nav.push(_imu(now, (np.nan, 0.0, 0.0)))
    nav.push(_imu(now, (np.inf, 0.0, 0.0)))
    nav.push(_imu(now))  # same time again
    nav.push(_imu(now - 20_000))  # backwards
    nav.push(_fix(now, fix_type=2))
    nav.push(GnssFix(now, float("nan"), 144.0, 10.0, 3, 10))
    nav.push(GnssFix(now, 95.0, 144.0, 10.0, 3, 10))
    nav.push(_fix(now - 2_500_000))  # older than the history
    nav.push(_fix(now + 500_000))  # from the future
    nav.push(_fix(now - 100_000))
    nav.push(_fix(now - 100_000))  # duplicate of a fused fix
    nav.push(_fix(now + 20_000))  # waits for the IMU (within the future tolerance)
    nav.push(_fix(now + 20_000))  # duplicate of a waiting fix
    nav.push(_imu(now + 300_000))  # 0.3 s gap
    c = nav.counters()
    expected = {
        "imu_rejected_no_attitude": 1, "gnss_rejected_before_imu": 1, "attitude_rejected_nonfinite": 2,
        "imu_rejected_nonfinite": 2, "imu_rejected_time_backwards": 2, "gnss_rejected_fix_type": 1,
        "gnss_rejected_nonfinite": 2, "gnss_rejected_too_old": 1, "gnss_rejected_future": 1,
        "gnss_rejected_duplicate": 2, "imu_gaps": 1, "gnss_fused": 3, "imu_used": 401,
    }
    assert {k: c[k] for k in expected} == expected
    est = nav.estimate()
    for v in (est.p_ned_m, est.v_ned_m_s, est.b_ned_m, est.cov_diag):
        assert np.isfinite(v).all()
    assert math.isfinite(est.beta) and math.isfinite(est.nis)
    with pytest.raises(TypeError):
        nav.push("not a sample")  # type: ignore[arg-type]


def test_imu_beyond_full_scale_is_counted_not_fused():
    """A finite specific force beyond 16 g on an axis (the readers' and the MAVLink codec's gate) pushed
    through the Python API (``push``, ``push_imu_batch``; the tight navigator shares the core) was fused:
    now counted, and the estimate is exactly the one without those samples."""
    from companion.domain.physics import MAX_SPECIFIC_FORCE_M_S2
    from companion.tight import TightConfig
    from companion.wiring import tight_navigator_for
    from gcs_tools.gnss.synthetic import store

    t = np.arange(1, 201) * 5000
    f = np.tile([0.3, -0.2, -G], (200, 1))
    bad_t = t[[40, 120]] + 2500  # between samples: without them, the stream is the clean one
    bad_f = np.array([[1e30, 0.0, -G], [0.0, -1.01 * MAX_SPECIFIC_FORCE_M_S2, -G]])
    clean, per_sample, batch = _started(), _started(), _started()
    for k in range(200):
        for nav in (clean, per_sample):
            nav.push(AttitudeSample(int(t[k]), Q_LEVEL))
            nav.push(_imu(int(t[k]), f[k]))
        if k in (40, 120):
            per_sample.push(AttitudeSample(int(bad_t[k // 80]), Q_LEVEL))
            per_sample.push(_imu(int(bad_t[k // 80]), bad_f[k // 80]))
    order = np.argsort(np.r_[t, bad_t], kind="stable")
    batch.push_imu_batch(np.r_[t, bad_t][order], np.r_[f, bad_f][order], np.tile(Q_LEVEL, (202, 1)))
    for nav in (clean, per_sample, batch):
        nav.push(_fix(1_000_000, (0.5, 0.2, 0.0)))
    want = clean.estimate()
    for nav in (per_sample, batch):
        assert nav.counters()["imu_rejected_out_of_range"] == 2
        assert nav.counters()["imu_used"] == clean.counters()["imu_used"]
        np.testing.assert_array_equal(nav.estimate().p_ned_m, want.p_ned_m)
        np.testing.assert_array_equal(nav.estimate().cov_diag, want.cov_diag)
    assert clean.counters()["imu_rejected_out_of_range"] == 0
    tight = tight_navigator_for(None, "second-order", config=TightConfig(), ephemerides=store())
    tight.push(AttitudeSample(1000, Q_LEVEL))
    tight.push(_imu(1000, (0.0, 0.0, 1e30)))
    assert tight.counters()["imu_rejected_out_of_range"] == 1


def test_bad_config_is_a_one_line_user_error():
    from companion.mission.schema import ConfigError, build

    with pytest.raises(ConfigError, match="history_s"):
        Navigator(EstimatorConfig(history_s=1.0))
    with pytest.raises(ConfigError, match=r"^estimator: alpha_fast"):
        build(EstimatorConfig, {"alpha_fast": 0.99, "alpha_slow": 0.9}, "estimator")


def test_push_fix_ned_equals_geodetic_fix():
    a, b = _started(), _started()
    for nav in (a, b):
        for k in range(1, 41):
            nav.push(AttitudeSample(k * 5000, Q_LEVEL))
            nav.push(_imu(k * 5000))
    fix = _fix(200_000, (3.0, -2.0, -1.0))
    a.push(fix)
    b.push_fix_ned(fix.t_validity_us, HOME.to_ned_m(fix.lat_deg, fix.lon_deg, fix.alt_m))
    np.testing.assert_array_equal(a.estimate().p_ned_m, b.estimate().p_ned_m)
    with pytest.raises(ValueError, match="frame"):
        Navigator(CFG, "naive", frame=None).push_fix_ned(0, np.zeros(3))


def test_ned_converter_equals_local_ned_frame():
    from companion.estimator.navigator import NedConverter

    conv = NedConverter(HOME)
    rng = np.random.default_rng(5)
    for p in rng.uniform(-3000.0, 3000.0, size=(20, 3)):
        lat, lon, alt = HOME.to_geodetic(p)
        np.testing.assert_allclose(conv(lat, lon, alt), HOME.to_ned_m(lat, lon, alt), rtol=0, atol=1e-8)
        # pymap3d's geodetic2ecef, operation for operation: the same bits
        x, y, z = (float(v) for v in pymap3d.geodetic2ecef(lat, lon, alt))
        hx, hy, hz = conv.home_ecef_m
        d = (x - hx, y - hy, z - hz)
        assert conv(lat, lon, alt) == tuple(sum(r * v for r, v in zip(row, d, strict=True))
                                            for row in conv.r_ned_ecef)


def _ned_numpy_reference(conv, lat_deg: float, lon_deg: float, alt_m: float) -> tuple[float, float, float]:
    """``NedConverter.__call__`` as it was before the C core: pymap3d's geodetic2ecef formula on numpy's
    cos, sin and hypot (the functions pymap3d calls)."""
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    cos_lat, sin_lat = float(np.cos(lat)), float(np.sin(lat))
    n = conv._A2 / float(np.hypot(conv._A * cos_lat, conv._B * sin_lat))
    x = (n + alt_m) * cos_lat * float(np.cos(lon))
    y = (n + alt_m) * cos_lat * float(np.sin(lon))
    z = (n * conv._B_A_2 + alt_m) * sin_lat
    hx, hy, hz = conv.home_ecef_m
    dx, dy, dz = x - hx, y - hy, z - hz
    (a, b, c), (d, e, f), (g, h, i) = conv.r_ned_ecef
    return (a * dx + b * dy + c * dz, d * dx + e * dy + f * dz, g * dx + h * dy + i * dz)


def test_ned_converter_in_c_equals_its_numpy_form_bit_for_bit():
    """The C core's geodesy (``_core.geodetic_ned``) against the numpy form it replaced, on fixes near and far
    from home, at the poles and the antimeridian, and NaN/inf inputs (NaN where NaN): the same bits (numpy's
    float64 cos, sin and hypot are libm's on this platform, which this test checks)."""
    from companion.domain.geodesy import LocalNedFrame
    from companion.estimator.navigator import NedConverter

    rng = np.random.default_rng(8)
    for home in (HOME, LocalNedFrame(-33.9, 151.2, 40.0), LocalNedFrame(89.9, -179.9, 0.0)):
        conv = NedConverter(home)
        near = rng.uniform(-0.05, 0.05, (2, 4000))
        lats = np.concatenate((home.home_lat_deg + near[0], rng.uniform(-90.0, 90.0, 4000),
                               [90.0, -90.0, 0.0, math.nan, math.inf]))
        lons = np.concatenate((home.home_lon_deg + near[1], rng.uniform(-180.0, 180.0, 4000),
                               [180.0, -180.0, 0.0, 1.0, 2.0]))
        alts = np.concatenate((rng.uniform(-100.0, 3000.0, 8000), [0.0, 1e4, -math.inf, 5.0, 6.0]))
        for lat, lon, alt in zip(lats.tolist(), lons.tolist(), alts.tolist(), strict=True):
            with np.errstate(invalid="ignore"):  # (cos and sin of inf: NaN)
                got, want = conv(lat, lon, alt), _ned_numpy_reference(conv, lat, lon, alt)
            assert type(got) is tuple and all(type(v) is float for v in got)
            same = all(g == w or (g != g and w != w) for g, w in zip(got, want, strict=True))
            assert same, (lat, lon, alt, got, want)
