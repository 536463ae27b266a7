"""The loose filter's reported accuracy: its position variances × the windowed consistency factor of
its own fused innovations (``companion.estimator.consistency``, the tight filter's rule). A report
only (the estimate is bit-identical with and without it), exact out of sequence, and 1 on average
on the filter's own model."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from companion.autopilot import feeds
from companion.domain.geodesy import LocalNedFrame
from companion.errors import ConfigError
from companion.estimator import Navigator
from companion.estimator.config import EstimatorConfig
from companion.estimator.consistency import accuracy_inflation, fix_floor, floored_axis, honest_horizontal
from companion.estimator.engine import FusionEngine
from tests.estimator_streams import OPEN_SKY, consistent_stream, drive, late_and_in_order, multipath_stream

CFG = EstimatorConfig()
G_M_S2 = CFG.gravity_m_s2


@pytest.fixture(scope="module")
def stream():
    return multipath_stream(np.random.default_rng(7), CFG, [(6.0, 0.0), (10.0, 1.2)])


@pytest.mark.parametrize("method", ["naive", "second-order"])
def test_a_late_fix_gives_the_in_order_accuracy(stream, method):
    """Fixes delayed by up to 1 s and fused out of order: every entry's consistency (and so the reported
    accuracy) equals in-order processing to 1e-9, as the state does."""
    late, ref = late_and_in_order(stream, lambda: FusionEngine(CFG, method, context=OPEN_SKY))
    assert late.counts["gnss_out_of_order"] > 20
    n = len(late.entries)
    for a, b in zip(late.entries[1:], ref.entries[-n + 1:], strict=True):
        assert a.t_us == b.t_us
        np.testing.assert_array_equal(a.fit.key, b.fit.key)
        np.testing.assert_allclose(a.fit.nu_sum, b.fit.nu_sum, rtol=0, atol=1e-9)
        np.testing.assert_allclose(a.fit.w2_sum, b.fit.w2_sum, rtol=0, atol=1e-9)
    k_late = accuracy_inflation(late.entries[-1].fit, CFG.accuracy_window_s)
    k_ref = accuracy_inflation(ref.entries[-1].fit, CFG.accuracy_window_s)
    assert k_late == pytest.approx(k_ref, abs=1e-9)
    fit = ref.entries[-1].fit  # the statistic before its floor at 1: not a trivial 0 = 0
    assert fit.nu_sum @ fit.nu_sum / fit.w2_sum.sum() > 0.1 and len(fit.key) == 3
    np.testing.assert_allclose(np.array(late.snapshot().var) * k_late, np.array(ref.snapshot().var) * k_ref,
                               rtol=0, atol=1e-9)
    for a, b in zip(late.entries[1:], ref.entries[-n + 1:], strict=True):  # the fixes' scatter too (N, E; D)
        for sa, sb in ((a.scatter, b.scatter), (a.scatter_v, b.scatter_v)):
            assert sa.t_us == sb.t_us
            np.testing.assert_allclose(_sums(sa), _sums(sb), rtol=0, atol=1e-9)
    for name in ("scatter", "scatter_v"):
        s_late, s_ref = getattr(late.entries[-1], name), getattr(ref.entries[-1], name)
        assert s_ref.correlation() > 1.0 and s_ref.variance() > 0.0  # not a trivial 1 = 1
        assert s_late.correlation() == pytest.approx(s_ref.correlation(), abs=1e-9)
        assert s_late.variance() == pytest.approx(s_ref.variance(), abs=1e-9)


def _sums(s) -> np.ndarray:  # a Scatter's (N, E) or a Scatter1's (D)
    return np.hstack((s.q, s.q_sum, s.q2_sum, s.w_sum, s.w2_sum, s.d1_sum, s.d2_sum, s.d_w_sum))


def _navigator(cfg: EstimatorConfig, s) -> Navigator:
    """The stream through a Navigator (level attitude: the FRD specific force is the NED acceleration
    less gravity), each fix on time reporting the clean noise (0.08 m)."""
    nav = Navigator(cfg, "naive", LocalNedFrame(50.0, 8.0, 100.0))
    f = s.a_ned_m_s2 - np.array([0.0, 0.0, G_M_S2])
    q = np.tile([1.0, 0.0, 0.0, 0.0], (len(s.t_us), 1))
    j = 0
    for k0 in range(0, len(s.t_us), 10):
        nav.push_imu_batch(s.t_us[k0:k0 + 10], f[k0:k0 + 10], q[k0:k0 + 10])
        while j < len(s.fix_index) and s.fix_index[j] < k0 + 10:
            nav.push_fix_ned(int(s.fix_t_us[j]), s.z_ned_m[j], 0.08, 0.08)
            j += 1
    return nav


def test_the_accuracy_is_a_report_the_estimate_is_bit_identical(stream):
    """accuracy_window_s 0 (P as it is) and 20 s: the same bits in every entry and in the estimate;
    the reported position variances differ by the factor alone, velocity and bias variances not at all."""
    off, on = (_navigator(dataclasses.replace(CFG, accuracy_window_s=w), stream) for w in (0.0, 20.0))
    for a, b in zip(off.engine.entries, on.engine.entries, strict=True):
        assert a.t_us == b.t_us and a.x == b.x and np.array_equal(a.P, b.P)
    e0, e1 = off.estimate(), on.estimate()
    assert e0 is not None and e1 is not None
    for name in ("p_ned_m", "v_ned_m_s", "b_ned_m"):
        np.testing.assert_array_equal(getattr(e0, name), getattr(e1, name))
    k = on.accuracy_inflation()
    assert off.accuracy_inflation() == 1.0 and k > 1.0
    np.testing.assert_array_equal(e1.cov_diag[3:], e0.cov_diag[3:])
    last = on.engine.entries[-1]  # horizontally: the fixes' correlation and scatter floor k P
    honest = honest_horizontal(e0.cov_diag[0:2], k, last.scatter, last.r_nominal_m2[0])
    vertical = floored_axis(float(e0.cov_diag[2]), k, *fix_floor(last.scatter_v, last.r_nominal_m2[2]))
    assert e1.cov_diag[2] == pytest.approx(vertical, rel=1e-12) and vertical >= e0.cov_diag[2] * k
    np.testing.assert_allclose(e1.cov_diag[0:2], honest, rtol=1e-12)
    assert np.all(e1.cov_diag[0:2] >= e0.cov_diag[0:2] * k)
    # what the autopilot gets: GPS_INPUT's horiz_accuracy, ODOMETRY's and VISION_POSITION_ESTIMATE's
    # position covariance carry the honest variances (EKF3 takes horiz_accuracy as its measurement noise)
    frame, cfg = LocalNedFrame(50.0, 8.0, 100.0), feeds.FeedConfig()
    gps = feeds.gps_input(e1, frame, cfg, unix_s=1_700_000_000.0)
    assert gps.fix_type == 3
    assert gps.horiz_accuracy == pytest.approx(math.sqrt(honest[0] + honest[1]), rel=1e-6)
    assert gps.horiz_accuracy > math.sqrt(k * (e0.cov_diag[0] + e0.cov_diag[1])) * 1.5  # floored here
    assert gps.vert_accuracy == pytest.approx(math.sqrt(vertical), rel=1e-6)
    level = np.array((1.0, 0.0, 0.0, 0.0))
    odo = feeds.odometry(e1, level, np.zeros(3), cfg)
    vis = feeds.vision_position(e1, level, cfg)
    for cov in (odo.pose_covariance, vis.covariance):
        assert (cov[0], cov[6]) == (pytest.approx(honest[0], rel=1e-6), pytest.approx(honest[1], rel=1e-6))
    for bad in (-1.0, math.nan, math.inf):
        with pytest.raises(ConfigError, match="accuracy_window_s"):
            Navigator(dataclasses.replace(CFG, accuracy_window_s=bad))


def test_on_its_own_model_the_factor_is_about_one():
    """The filter's own model (naive, belief held): innovations white with unit variance, so the factor
    stays near 1 (a χ²(3)/3 draw of the window means, floored at 1: conservative, never below P) and
    the reported accuracy covers the error at least as P does (2-D Gaussian: 39 % / 86 %)."""
    k_all, nees = [], []
    for seed in range(3):
        s, _, _ = consistent_stream(np.random.default_rng(seed), CFG, 30.0, 1.0)
        e = FusionEngine(CFG, "naive", context=OPEN_SKY)
        steps = []
        orig = e._fuse

        def spy(prev, t_us, fix, orig=orig, steps=steps):
            out = orig(prev, t_us, fix)
            steps.append(out)
            return out

        e._fuse = spy  # type: ignore[method-assign]
        drive(s, e, s.fix_t_us.copy())
        truth = {int(t): s.x_true[i] for t, i in zip(s.fix_t_us, s.fix_index, strict=True)}
        for f in steps:
            if f.t_us < 5_000_000:
                continue
            err = np.asarray(f.x[0:2]) - truth[f.t_us][0:2]
            k = accuracy_inflation(f.fit, CFG.accuracy_window_s)
            k_all.append(k)
            nees.append((err[0] ** 2 / f.P[0, 0] + err[1] ** 2 / f.P[1, 1], k))
    k_all_a, n = np.array(k_all), np.array(nees)
    assert 1.0 <= np.median(k_all_a) < 1.5
    p_only = (np.mean(n[:, 0] <= 1.0), np.mean(n[:, 0] <= 4.0))
    reported = (np.mean(n[:, 0] / n[:, 1] <= 1.0), np.mean(n[:, 0] / n[:, 1] <= 4.0))
    assert 0.33 < p_only[0] < 0.47 and 0.8 < p_only[1] < 0.93  # P is consistent here
    assert reported[0] >= p_only[0] and reported[1] >= p_only[1] and reported[1] < 0.99
