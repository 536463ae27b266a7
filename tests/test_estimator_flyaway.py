"""Never fly away: the receiver's velocity fused with its own gate, resets that recover, the fly-away
guard, and the learned R of a receiver that states no accuracy (known answers and statistics)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.estimator import _core, model
from companion.estimator import engine as engine_module
from companion.estimator.config import EstimatorConfig
from companion.estimator.engine import FusionEngine

CFG = EstimatorConfig()


def _still(e: FusionEngine, t0_us: int, t1_us: int, a=(0.0, 0.0, 0.0)) -> None:
    for t in range(t0_us + 5000, t1_us + 1, 5000):
        e.push_acc(t, *a)


def _spd(rng: np.random.Generator, n: int = 15) -> np.ndarray:
    G = rng.standard_normal((n, n))
    return G @ G.T + 0.1 * np.eye(n)


def test_velocity_update_equals_the_joint_kalman_update_and_skips_what_is_not_reported():
    rng = np.random.default_rng(0)
    x, P = tuple(rng.standard_normal(15).tolist()), _spd(rng)
    zv, r = (1.0, -2.0, 0.5), (0.09, 0.09, 0.25)
    H = np.zeros((3, 15))
    H[:, 3:6] = np.eye(3)
    S = H @ P @ H.T + np.diag(r)
    K = P @ H.T @ np.linalg.inv(S)
    y = np.array(zv) - np.array(x[3:6])
    xo, Po = _core.update_vel(x, P, zv, r)
    np.testing.assert_allclose(xo, np.array(x) + K @ y, rtol=0, atol=1e-12)
    np.testing.assert_allclose(Po, P - K @ S @ K.T, rtol=0, atol=1e-12)
    assert np.array_equal(Po, Po.T)
    nis_h, nis_d = _core.vel_nis(x, P, zv, r)
    Sh = S[0:2, 0:2]
    assert nis_h == pytest.approx(float(y[0:2] @ np.linalg.solve(Sh, y[0:2])), rel=1e-12)
    assert nis_d == pytest.approx(y[2] ** 2 / S[2, 2], rel=1e-12)
    # no vertical (GPS_RAW_INT): the north-east update alone, the vertical velocity untouched by it
    x2, P2 = _core.update_vel(x, P, (1.0, -2.0, math.nan), r)
    H2 = H[0:2]
    K2 = P @ H2.T @ np.linalg.inv(H2 @ P @ H2.T + np.diag(r[0:2]))
    np.testing.assert_allclose(x2, np.array(x) + K2 @ y[0:2], rtol=0, atol=1e-12)
    assert _core.vel_nis(x, P, (1.0, -2.0, math.nan), r)[1] == 0.0


@pytest.mark.parametrize("inside", [True, False])
def test_the_velocity_gate_is_exact_and_counted(inside):
    e = FusionEngine(CFG, "naive")
    e.push_acc(0, 0.0, 0.0, 0.0)
    e.push_fix(0, (0.0, 0.0, 0.0), None, (0.0, 0.0, math.nan))
    _still(e, 0, 200_000)
    prev = e.fusions[-1]
    T = 0.2
    P = model.predict_cov(prev.P, T, CFG.sigma_bias_m(CFG.beta_fixed), CFG)
    s = P[3, 3] + CFG.sigma_gnss_velocity_m_s**2
    edge = CFG.gnss_vel_gate_sigma * math.sqrt(s) * (0.999 if inside else 1.001)  # north, one axis
    e.push_fix(200_000, (0.0, 0.0, 0.0), None, (edge, 0.0, math.nan))
    c = e.counts
    # (the first fix starts the filter: its velocity is its initial one, not tested)
    assert (c["gnss_vel_fused"], c["gnss_vel_rejected_innovation"]) == ((1, 0) if inside else (0, 1))
    assert e.fusions[-1].vel_ratio == pytest.approx((0.999 if inside else 1.001) ** 2, rel=1e-6)
    assert c["gnss_fused"] == 2  # the position passed its own gate either way


def test_a_reset_takes_the_receiver_velocity_and_the_returning_track_is_not_fought():
    """Fixes on a track at 4 m/s north; 6 s of outage while the IMU (wrongly) decelerates the estimate
    at 2 m/s²; the GNSS returns 36 m away, past the time-out: one reset onto the fix AND the
    receiver's velocity, the IMU error states re-opened; every fix after it passes (no second
    reset)."""
    e = FusionEngine(CFG, "second-order")
    v = (4.0, 0.0, math.nan)
    e.push_acc(0, 0.0, 0.0, 0.0)
    t = 0
    while t < 3_000_000:
        _still(e, t, t + 200_000)
        t += 200_000
        e.push_fix(t, (4.0 * t * 1e-6, 0.0, 0.0), None, v)
    _still(e, t, t + 6_000_000, a=(-2.0, 0.0, 0.0))  # the IMU (wrongly) brakes and reverses the estimate
    t += 6_000_000
    resets_at = []
    while t < 22_000_000:
        _still(e, t, t + 200_000)
        t += 200_000
        e.push_fix(t, (4.0 * t * 1e-6, 0.0, 0.0), None, v)
        if e.counts["gnss_resets"] > len(resets_at):
            resets_at.append(t)
            f = e.fusions[-1]
            assert f.x[3] == 4.0 and f.P[3, 3] == CFG.sigma_gnss_velocity_m_s**2  # the receiver's velocity
            assert f.P[9, 9] >= CFG.sigma_acc_bias0_m_s2**2  # the IMU error states re-opened
    assert len(resets_at) == 1
    snap = e.snapshot()
    assert snap.x[0] == pytest.approx(4.0 * t * 1e-6, abs=0.3) and snap.pos_valid


def test_the_fly_away_guard_flags_an_estimate_outside_the_envelope_and_the_next_fix_resets_it():
    """A bogus 30 m/s² IMU for 1.5 s between two fixes: the estimate's speed leaves the envelope (45
    m/s > 30) and it is flagged invalid at once, not after the time-out; the next fix (failing the
    gate) resets it and it is valid again."""
    cfg = EstimatorConfig(gnss_reset_timeout_s=30.0)  # only the guard can reset here
    e = FusionEngine(cfg, "naive")
    e.push_acc(0, 0.0, 0.0, 0.0)
    e.push_fix(0, (0.0, 0.0, 0.0))
    t = 0
    for _ in range(5):
        _still(e, t, t + 200_000)
        t += 200_000
        e.push_fix(t, (0.0, 0.0, 0.0))
    _still(e, t, t + 1_500_000, a=(30.0, 0.0, 0.0))
    t += 1_500_000
    snap = e.snapshot()
    assert snap.x[3] > cfg.envelope_speed_max_m_s and not snap.pos_valid  # 1.5 s after the last fix
    _still(e, t, t + 200_000)
    t += 200_000
    e.push_fix(t, (0.0, 0.0, 0.0))  # fails the gate: rejected, the entry now flagged invalid
    assert e.fusions[-1].invalid and e.counts["envelope_violations"] == 1 and e.counts["gnss_resets"] == 0
    _still(e, t, t + 200_000)
    t += 200_000
    e.push_fix(t, (0.0, 0.0, 0.0))  # the guard's reset
    assert e.counts["gnss_resets"] == 1
    snap = e.snapshot()
    assert snap.pos_valid and abs(snap.x[0]) < 0.5 and not e.fusions[-1].invalid


def test_a_smooth_acceleration_inside_the_envelope_is_not_flagged():
    e = FusionEngine(CFG, "naive")
    e.push_acc(0, 0.0, 0.0, 0.0)
    e.push_fix(0, (0.0, 0.0, 0.0))
    t, a = 0, 15.0  # 1.5 g for 1.5 s: inside the 20 m/s² envelope, 22.5 m/s inside 30 m/s
    while t < 1_500_000:
        _still(e, t, t + 100_000, a=(a, 0.0, 0.0))
        t += 100_000
        p = 0.5 * a * (t * 1e-6) ** 2
        e.push_fix(t, (p, 0.0, 0.0), None, (a * t * 1e-6, 0.0, math.nan))
    assert e.counts["envelope_violations"] == 0 and e.snapshot().pos_valid


@pytest.mark.parametrize("sigma_m", [0.3, 3.0])
def test_the_learned_r_of_a_receiver_without_accuracy_is_its_white_noise(sigma_m):
    """Fixes of a still receiver with white noise σ and no accuracy (engine.LEARN): the noise learned
    from its fixes and the IMU alone settles at σ (its mean over the last 30 s within 10 %), whatever
    the filter's own state."""
    rng = np.random.default_rng(1)
    e = FusionEngine(CFG, "naive")
    e.push_acc(0, 0.0, 0.0, 0.0)
    t = 0
    learned = []
    for i in range(300):
        _still(e, t, t + 200_000)
        t += 200_000
        e.push_fix(t, tuple(rng.normal(0.0, sigma_m, 3)), engine_module.LEARN)
        if i >= 150:  # settled (from the 0.5 m start: ~20 s)
            f = e.fusions[-1]
            learned.append((f.noise_h_m / engine_module._SCALE_H, f.noise_v_m / engine_module._SCALE_V))
    np.testing.assert_allclose(np.mean(learned, axis=0), sigma_m, rtol=0.1)
    assert e.counts["gnss_rejected_innovation"] <= 6 and e.counts["gnss_resets"] == 0  # 2 %: while it learns


def test_the_running_centre_constants_are_those_of_gaussian_innovations():
    """_SCALE_H, _SCALE_V: where the clipped log-domain running centre of |horizontal (2 dof)| and
    |vertical (1 dof)| Gaussian innovations of unit std settles (the core's update, 40,000 steps)."""
    rng = np.random.default_rng(2)
    scales = (1.0, 1.0, 1.0, 1.0)
    k, ek = 0.01, math.exp(0.01)
    a = b = (0.0,) * 40  # integrals (history.py)
    hist_h, hist_v = [], []
    for i in range(40_000):
        y = tuple(rng.standard_normal(3).tolist())
        scales = _core.receiver_spread(a, b, (0.0,) * 3, None, None, (0.0,) * 3, 0.0, 0.2, y, scales[0:4],
                                       k, ek, k, ek)[0:4]
        if i > 5_000:
            hist_h.append(scales[0])
            hist_v.append(scales[1])
    assert np.mean(hist_h) == pytest.approx(engine_module._SCALE_H, rel=0.02)
    assert np.mean(hist_v) == pytest.approx(engine_module._SCALE_V, rel=0.02)


def test_an_urban_receiver_without_accuracy_is_not_mostly_rejected():
    """Fixes with a 10 m Gauss-Markov error (10 s correlation) and 3 m white noise, no accuracy: the
    gate's floor (the robust spread of the receiver's innovations) keeps rejections few and resets
    rare, where a 0.5 m floor rejected most."""
    rng = np.random.default_rng(3)
    e = FusionEngine(CFG, "second-order")
    e.push_acc(0, 0.0, 0.0, 0.0)
    b = rng.normal(0.0, 10.0, 3)
    t = 0
    k = math.exp(-0.2 / 10.0)
    for _ in range(600):  # 2 min at 5 Hz
        _still(e, t, t + 200_000)
        t += 200_000
        b = k * b + math.sqrt(1 - k * k) * rng.normal(0.0, 10.0, 3)
        e.push_fix(t, tuple((b + rng.normal(0.0, 3.0, 3)).tolist()), engine_module.LEARN)
    c = e.counts
    assert c["gnss_rejected_innovation"] < 0.05 * 600 and c["gnss_resets"] <= 1


def _gauss_markov(rng: np.random.Generator, n: int, sigma_m: float, tau_s: float, T_s: float) -> np.ndarray:
    """n samples T_s apart of a stationary Gauss-Markov process per axis (3 axes)."""
    a = math.exp(-T_s / tau_s)
    w = rng.normal(0.0, sigma_m * math.sqrt(1.0 - a * a), (n, 3))
    b = np.empty((n, 3))
    b[0] = rng.normal(0.0, sigma_m, 3)
    for i in range(1, n):
        b[i] = a * b[i - 1] + w[i]
    return b


def test_the_bias_share_of_the_noise_statistic_is_that_of_a_simulated_gauss_markov_bias():
    """model.bias_share_of_noise_m2: the variance of (b₂ − 2 b₁ + b₀)/√6 of a simulated 2 m bias of 3 s
    correlation at 5 Hz (60,000 samples per axis) within 3 %."""
    b = _gauss_markov(np.random.default_rng(4), 60_000, 2.0, 3.0, 0.2)
    d2 = (b[2:] - 2.0 * b[1:-1] + b[:-2]) / math.sqrt(6.0)
    assert np.mean(d2 * d2) == pytest.approx(model.bias_share_of_noise_m2(2.0, 0.2, 3.0), rel=0.03)


@pytest.mark.parametrize("bias_m", [0.0, 2.0])
def test_the_learned_r_without_the_bias_share_is_the_white_noise(bias_m):
    """A still receiver without accuracy whose fixes carry a 2 m Gauss-Markov bias (3 s, the filter's
    bias_tau_s) and 0.5 m of white noise. Its fix-to-fix noise holds both: the learned R (mean over the
    last 560 s) is σ_w² + the bias share (0.25 + 0.18 m²) when sigma_gnss_unreported_bias_m is 0, and the
    white noise's 0.25 m² when it is the bias's 2 m, whatever the method's state: within 10 % and 20 %
    (the white part is the difference of two variances; over 12 seeds it was 0.23-0.28 m², mean 0.256)."""
    rng = np.random.default_rng(5)
    cfg = EstimatorConfig(sigma_gnss_unreported_bias_m=bias_m)
    e = FusionEngine(cfg, "naive")
    e.push_acc(0, 0.0, 0.0, 0.0)
    n = 3000  # 10 min at 5 Hz: the learned R's running centre (10 s) is known to ~15 % at any instant
    z = _gauss_markov(rng, n, 2.0, cfg.bias_tau_s, 0.2) + rng.normal(0.0, 0.5, (n, 3))
    t, learned = 0, []
    for i in range(n):
        _still(e, t, t + 200_000)
        t += 200_000
        e.push_fix(t, tuple(z[i].tolist()), engine_module.LEARN)
        if i >= 200:  # settled
            learned.append(e.learned_r_m2(e.fusions[-1])[0])
    share = model.bias_share_of_noise_m2(2.0, 0.2, cfg.bias_tau_s)
    expected = 0.25 + (share if bias_m == 0.0 else 0.0)
    assert np.mean(learned) == pytest.approx(expected, rel=0.1 if bias_m == 0.0 else 0.2)
