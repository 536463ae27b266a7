"""Out-of-sequence fusion (Algorithm 1) equals in-order processing; old fixes are rejected."""

import dataclasses

import numpy as np
import pytest

from companion.estimator import METHODS
from companion.estimator import engine as engine_module
from companion.estimator.config import EstimatorConfig
from companion.estimator.engine import FusionEngine
from tests.estimator_streams import OPEN_SKY, drive, multipath_stream

CFG = EstimatorConfig()


def _run(stream, method: str, arrival_us: np.ndarray, cfg: EstimatorConfig = CFG) -> FusionEngine:
    """Push IMU in time order and each fix once the IMU clock reaches its arrival time."""
    return drive(stream, FusionEngine(cfg, method, context=OPEN_SKY), arrival_us)


@pytest.fixture(scope="module")
def stream():
    return multipath_stream(np.random.default_rng(7), CFG, [(8.0, 0.0), (8.0, 1.2), (8.0, 0.0)])


# every method at the defaults, and the rules whose loss has the bias-level term with it on
LEVEL = dataclasses.replace(CFG, lambda_bias_level=1.0)
CASES = [(m, CFG) for m in METHODS] + [(m, LEVEL) for m in ("first-order", "second-order", "windowed-ml")]


@pytest.mark.parametrize(("method", "cfg"), CASES,
                         ids=[m + ("+bias-level" if c is LEVEL else "") for m, c in CASES])
def test_random_delays_and_order_equal_in_order(stream, method, cfg):
    rng = np.random.default_rng(11)
    delay_us = rng.uniform(0.0, 1.2e6, size=len(stream.fix_t_us)).astype(np.int64)
    delay_us[0] = 0  # the first fix starts the filter
    late = _run(stream, method, np.minimum(stream.fix_t_us + delay_us, stream.t_us[-1]), cfg)
    ref = _run(stream, method, stream.fix_t_us.copy(), cfg)
    c = late.counts
    assert c["gnss_out_of_order"] > 50 and c["gnss_refused"] > c["gnss_out_of_order"]
    assert c["gnss_rejected_too_old"] == 0 and ref.counts["gnss_out_of_order"] == 0
    a, b = late.snapshot(), ref.snapshot()
    assert a.t_us == b.t_us
    np.testing.assert_allclose(a.x, b.x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.var, b.var, rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.array(late.covariance_now()), np.array(ref.covariance_now()),
                               rtol=0, atol=1e-9)
    assert abs(a.beta - b.beta) < 1e-9
    # and every fusion still in the history, with its belief state
    assert [f.t_us for f in late.fusions[1:]] == [f.t_us for f in ref.fusions[-len(late.fusions) + 1:]]
    for f, g in zip(late.fusions[1:], ref.fusions[-len(late.fusions) + 1:], strict=True):
        np.testing.assert_allclose(f.x, g.x, atol=1e-9)
        assert late.method.beta(f.state) == pytest.approx(ref.method.beta(g.state), abs=1e-9)
        np.testing.assert_array_equal(f.P, f.P.T)  # symmetric exactly (model.update_fast)


def test_fix_older_than_history_is_rejected_and_counted(stream):
    e = FusionEngine(CFG, "second-order")
    n = 1000  # 5 s of IMU
    for k in range(n):
        e.push_acc(int(stream.t_us[k]), *stream.a_ned_m_s2[k].tolist())
    e.push_fix(int(stream.t_us[n - 1]) - 1_000_000, stream.z_ned_m[0])
    e.push_fix(int(stream.t_us[n - 1]) - 2_100_000, stream.z_ned_m[0])  # history is 2 s
    assert e.counts["gnss_fused"] == 1 and e.counts["gnss_rejected_too_old"] == 1
    # before the first fusion (the filter's start) is too old as well
    e.push_fix(int(stream.t_us[n - 1]) - 1_500_000, stream.z_ned_m[0])
    assert e.counts["gnss_rejected_too_old"] == 2


def test_history_stays_bounded_through_a_gnss_outage(stream):
    e = FusionEngine(CFG, "second-order")
    e.push_acc(0, 0.0, 0.0, 0.0)
    e.push_fix(0, (0.0, 0.0, 0.0))
    for k in range(1, 20_000):  # 100 s without GNSS
        e.push_acc(k * 5000, 0.0, 0.0, 0.1)
    assert len(e.imu) < 1000 and len(e.fusions) == 1
    s = e.snapshot()
    assert s.x[5] == pytest.approx(0.1 * (19_998 * 0.005), rel=1e-9)  # held from the 2nd sample on


@pytest.fixture(scope="module")
def glitch_stream():
    """Clean GNSS with the receiver's velocity (truth + 0.1 m/s noise, no vertical) and every path of
    the gate: a 1 s 8 m step (held on the velocity), a 9 s 20 m step (held 5 s, accepted, then its end
    a return), a velocity glitch (rejected by its gate), a 6 s outage ending 30 m away (rejected, then
    a reset) and a 20 m/s² error of the IMU's north acceleration for 1.5 s (the velocity fails against a
    self-consistent GNSS: the IMU-distrust hypothesis, the disagreement flagged)."""
    s = multipath_stream(np.random.default_rng(3), CFG, [(40.0, 0.0)])
    t = s.fix_t_us * 1e-6
    z = s.z_ned_m.copy()
    z[(t >= 4.0) & (t < 5.0), 0] += 8.0
    z[(t >= 8.0) & (t < 17.0), 1] -= 20.0
    z[t >= 26.0, 0] += 30.0
    keep = ~((t >= 20.0) & (t < 26.0))
    v = s.x_true[s.fix_index, 3:6] + np.random.default_rng(4).normal(0.0, 0.1, (len(t), 3))
    v[:, 2] = np.nan  # GPS_RAW_INT has no vertical
    v[np.argmin(abs(t - 18.5)), 0] += 5.0
    a = s.a_ned_m_s2.copy()
    ti = s.t_us * 1e-6
    a[(ti >= 30.0) & (ti < 31.5), 0] += 20.0
    out = s.__class__(s.t_us, a, s.x_true, s.fix_index[keep], z[keep], s.bias_std_m[keep])
    return out, v[keep]


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("learned", [False, True, "minus-bias"])
def test_gate_and_reset_are_exact_under_out_of_order_fusion(glitch_stream, method, learned):
    """Every decision (position and velocity gates, offsets held, accepted and returned, resets, the
    IMU/GNSS disagreement, the envelope, the learned R) is a function of the time-ordered fixes:
    random delays (up to 1.2 s) give the same decisions, counters and estimate as in-order
    processing, with the receiver's velocity and with the R of a receiver that reports none (also
    less a bias's share: sigma_gnss_unreported_bias_m)."""
    s, v = glitch_stream
    r = engine_module.LEARN if learned else None
    cfg = dataclasses.replace(CFG, sigma_gnss_unreported_bias_m=1.2) if learned == "minus-bias" else CFG
    rng = np.random.default_rng(5)
    delay_us = rng.uniform(0.0, 1.2e6, size=len(s.fix_t_us)).astype(np.int64)
    delay_us[0] = 0
    arrival_us = np.minimum(s.fix_t_us + delay_us, s.t_us[-1])
    late = drive(s, FusionEngine(cfg, method, context=OPEN_SKY), arrival_us, v, r)
    ref = drive(s, FusionEngine(cfg, method, context=OPEN_SKY), s.fix_t_us.copy(), v, r)
    assert late.counts["gnss_out_of_order"] > 50
    if learned == "minus-bias":  # the share removed somewhere (the learned noise above the floor)
        plain = FusionEngine(CFG, method, context=OPEN_SKY)
        assert any(ref.learned_r_m2(f)[0] < plain.learned_r_m2(f)[0] for f in ref.fusions)
    names = ("gnss_rejected_innovation", "gnss_resets", "gnss_offsets", "gnss_offset_returns", "gnss_fused",
             "gnss_vel_fused", "gnss_vel_rejected_innovation", "imu_gnss_disagreements",
             "envelope_violations")
    for name in names:
        assert late.counts[name] == ref.counts[name], name
    c = ref.counts
    assert c["gnss_offsets"] >= 1 and c["gnss_offset_returns"] == 1 and c["gnss_resets"] >= 1
    assert c["gnss_vel_rejected_innovation"] >= 1 and c["imu_gnss_disagreements"] >= 1
    a, b = late.snapshot(), ref.snapshot()
    np.testing.assert_allclose(a.x, b.x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.var, b.var, rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.array(late.covariance_now()), np.array(ref.covariance_now()),
                               rtol=0, atol=1e-9)
    assert abs(a.beta - b.beta) < 1e-9 and a.pos_valid == b.pos_valid
    for f, g in zip(late.fusions[1:], ref.fusions[-len(late.fusions) + 1:], strict=True):
        assert (f.t_us, f.glitch, f.n_rejected, f.n_resets, f.t_fused_us, f.n_offsets, f.t_offset_us,
                f.n_returns, f.disagree, f.invalid, f.n_vel_rejected) == (
            g.t_us, g.glitch, g.n_rejected, g.n_resets, g.t_fused_us, g.n_offsets, g.t_offset_us,
            g.n_returns, g.disagree, g.invalid, g.n_vel_rejected)
        assert (f.offset is None) == (g.offset is None) and (f.accepted is None) == (g.accepted is None)
        np.testing.assert_allclose((f.scale_h_m, f.noise_h_m, f.disagree_level),
                                   (g.scale_h_m, g.noise_h_m, g.disagree_level), rtol=0, atol=1e-9)
