"""The bias range at the receiver's scale (``EstimatorConfig.sigma_bias_max_per_gnss_std``, off by
default; here 1): known answers, the paper's receivers untouched, out-of-sequence exactness with a
metre-level receiver, and a filter that is less overconfident on one."""

import dataclasses

import numpy as np
import pytest

from companion.estimator import METHODS
from companion.estimator import engine as engine_module
from companion.estimator.belief import InnovationTerms, s_of_beta
from companion.estimator.config import EstimatorConfig
from companion.estimator.engine import FusionEngine
from tests.estimator_streams import (
    OPEN_SKY,
    assert_out_of_order_equals_in_order,
    drive,
    late_and_in_order,
    multipath_stream,
)

OFF = EstimatorConfig()  # the default: the paper's range for every receiver
CFG = dataclasses.replace(OFF, sigma_bias_max_per_gnss_std=1.0)


def test_scale_known_answers():
    assert CFG.bias_scale(0.08**2) == 1.0  # the paper's receiver
    assert CFG.bias_scale(1.2**2) == 1.0  # up to the paper's bias std: unchanged
    assert CFG.bias_scale(8.0**2) == pytest.approx(8.0 / 1.2)
    assert OFF.bias_scale(8.0**2) == 1.0
    assert dataclasses.replace(CFG, sigma_bias_max_per_gnss_std=2.0).bias_scale(3.0**2) == pytest.approx(5.0)
    with pytest.raises(ValueError, match="sigma_bias_max_per_gnss_std"):
        dataclasses.replace(CFG, sigma_bias_max_per_gnss_std=float("nan")).validate()


def test_s_of_beta_is_the_scaled_bias_std():
    t = InnovationTerms((1.0, 2.0, 3.0), (0.1, 0.2, 0.3), 0.05, (4.0, 4.0, 9.0), (0.0, 0.0, 0.0), 3.0)
    for beta in (0.0, 0.4, 1.0):
        sb = 3.0 * CFG.sigma_bias_m(beta)
        S, _ = s_of_beta(beta, t, CFG)
        expect = np.array(t.s0) + 0.05 * sb * sb + CFG.r_factor(beta) * np.array(t.r_nominal)
        np.testing.assert_allclose(S, expect, rtol=1e-15)
        np.testing.assert_allclose(t.hph(CFG.sigma_bias_m(beta)), np.array(t.s0) + 0.05 * sb * sb, rtol=1e-15)


@pytest.mark.parametrize("velocity", [False, True])
def test_first_fix_bias_prior_at_the_receiver_scale(velocity):
    s = multipath_stream(np.random.default_rng(1), CFG, [(1.0, 0.0)])
    r = (16.0, 16.0, 36.0)  # a receiver stating 4 m (6 m vertical)
    e = FusionEngine(CFG, "second-order", context=OPEN_SKY)
    e.push_acc(int(s.t_us[0]), 0.0, 0.0, 0.0)
    e.push_fix(int(s.t_us[0]), s.z_ned_m[0], r, (0.0, 0.0, 0.0) if velocity else None)
    f0 = e.fusions[0]
    f = 4.0 / 1.2
    assert f0.bias_scale == pytest.approx(f)
    assert f0.sigma_bias_m == pytest.approx(f * CFG.sigma_bias_m(0.5))
    bias_var = (CFG.sigma_bias0_m * f) ** 2
    np.testing.assert_allclose(np.diag(f0.P)[6:9], bias_var)
    if velocity:  # reset_to_fix's form: the position carries the bias's variance, anti-correlated
        np.testing.assert_allclose(np.diag(f0.P)[0:3], np.array(r) + bias_var)
        np.testing.assert_allclose([f0.P[i, 6 + i] for i in range(3)], -bias_var)
    else:
        np.testing.assert_allclose(np.diag(f0.P)[0:3], r)


def test_a_decimetre_receiver_is_bit_identical_to_the_fixed_range():
    s = multipath_stream(np.random.default_rng(2), CFG, [(5.0, 0.0), (5.0, 1.2)])
    a = drive(s, FusionEngine(CFG, "second-order", context=OPEN_SKY), s.fix_t_us.copy())
    b = drive(s, FusionEngine(OFF, "second-order", context=OPEN_SKY), s.fix_t_us.copy())
    assert a.snapshot().x == b.snapshot().x and np.array_equal(a.covariance_now(), b.covariance_now())


@pytest.fixture(scope="module")
def urban_stream():
    """A metre-level receiver that states no accuracy: 3 m white noise on an 8 m Gauss-Markov bias."""
    return multipath_stream(np.random.default_rng(9), CFG, [(20.0, 8.0)], sigma_degraded_m=3.0)


@pytest.mark.parametrize("method", METHODS)
def test_out_of_order_equals_in_order_with_a_metre_level_receiver(urban_stream, method):
    late, ref = late_and_in_order(urban_stream, lambda: _learning(method))
    assert_out_of_order_equals_in_order(late, ref)
    scales = [f.bias_scale for f in ref.fusions]
    assert max(scales) > 1.3 and len(set(scales)) > 50  # the learned noise grew past the paper's range
    for f, g in zip(late.fusions[1:], ref.fusions[-len(late.fusions) + 1:], strict=True):
        assert f.bias_scale == pytest.approx(g.bias_scale, abs=1e-12)


class _Learning(FusionEngine):
    """A FusionEngine whose fixes all carry no accuracy (their R learned)."""

    def push_fix(self, t_us, z_ned_m, r_nominal_m2=None, v_ned_m_s=None, rv_m2=None):  # type: ignore[override]
        super().push_fix(t_us, z_ned_m, engine_module.LEARN, v_ned_m_s, rv_m2)


def _learning(method: str) -> FusionEngine:
    return _Learning(CFG, method, context=OPEN_SKY)


def test_less_overconfident_on_a_metre_level_receiver():
    """A receiver stating 3 m with a 6 m bias (the paper's range: 1.2 m): second-order's horizontal
    position NEES at the end of 20 s, over 12 seeds, falls by more than half with the range at the
    receiver's scale, and its error does not grow."""
    out = {}
    for cfg in (OFF, CFG):
        nees, err = [], []
        for seed in range(12):
            s = multipath_stream(np.random.default_rng(seed), cfg, [(20.0, 6.0)], sigma_degraded_m=3.0)
            e = drive(s, FusionEngine(cfg, "second-order", context=OPEN_SKY), s.fix_t_us.copy(), None,
                      (9.0, 9.0, 9.0))
            snap = e.snapshot()
            d = np.array(snap.x[:2]) - s.x_true[np.searchsorted(s.t_us, snap.t_us), :2]
            nees.append(d @ np.linalg.solve(np.array(e.covariance_now())[:2, :2], d))
            err.append(np.hypot(*d))
        out[cfg.sigma_bias_max_per_gnss_std] = (np.mean(nees), np.mean(err))
    (nees_off, err_off), (nees_on, err_on) = out[0.0], out[1.0]
    assert nees_on < 0.5 * nees_off and err_on < err_off + 0.3
