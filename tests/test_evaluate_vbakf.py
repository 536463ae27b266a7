"""The variational-Bayes adaptive KF baseline learns measurement noise it was not told."""

import numpy as np
import pytest

from companion.estimator import EstimatorConfig
from companion.estimator.vbakf import NoisePosterior, VbConfig, vb_update


def run_stream(R_true, R0, cfg, n, seed, q=1e-4):
    """Random-walk 3-D position observed directly; returns the R̂ history."""
    rng = np.random.default_rng(seed)
    m = R_true.shape[0]
    H, Q = np.eye(m), q * np.eye(m)
    L = np.linalg.cholesky(R_true)
    truth = np.zeros(m)
    x, P = np.zeros(m), np.eye(m)
    noise = NoisePosterior.prior(R0, cfg)
    history = []
    for _ in range(n):
        truth = truth + rng.normal(0.0, np.sqrt(q), m)
        P = P + Q
        noise = noise.predict(cfg)
        z = truth + L @ rng.standard_normal(m)
        x, P, noise = vb_update(x, P, z, H, noise, cfg)
        history.append(noise.R_hat)
    return np.array(history), x, truth


def test_learns_a_constant_inflated_R():
    # The filter is told GNSS σ = 0.08 m; the stream's noise is 6-10x larger and correlated.
    R_true = np.array([[0.25, 0.05, 0.0], [0.05, 0.36, 0.0], [0.0, 0.0, 0.64]])
    R0 = 0.08**2 * np.eye(3)
    history, x, truth = run_stream(R_true, R0, VbConfig.of(EstimatorConfig()), n=3000, seed=4)
    R_mean = history[1000:].mean(axis=0)
    assert np.allclose(np.diag(R_mean), np.diag(R_true), rtol=0.1)
    assert R_mean[0, 1] == pytest.approx(0.05, abs=0.03)
    # A slow learner (ρ → 1) converges tighter on the same stream.
    slow, _, _ = run_stream(R_true, R0, VbConfig(0.999, 3, 10.0), n=3000, seed=4)
    assert np.allclose(np.diag(slow[-1]), np.diag(R_true), rtol=0.1)
    # It tracks the truth at least as well as the noise allows.
    assert np.linalg.norm(x - truth) < 3.0 * np.sqrt(np.trace(R_true) / 50)


def test_known_answer_with_a_perfectly_known_state():
    # P = 0: the residual is exactly z − x, so with ρ = 1 the posterior scale is the prior
    # plus the sum of outer products, whatever the number of iterations.
    cfg = VbConfig(forgetting=1.0, iterations=4, prior_dof=3.0)
    rng = np.random.default_rng(0)
    R0 = np.diag([1.0, 2.0])
    noise = NoisePosterior.prior(R0, cfg)
    x, P, H = np.array([1.0, -2.0]), np.zeros((2, 2)), np.eye(2)
    zs = x + rng.normal(size=(20, 2))
    for z in zs:
        x2, _, noise = vb_update(x, P, z, H, noise.predict(cfg), cfg)
        assert np.array_equal(x2, x)
    e = zs - x
    expected = (3.0 * R0 + e.T @ e) / (3.0 + 20)
    assert np.allclose(noise.R_hat, expected, atol=1e-12)


def test_config_ranges_are_checked():
    for bad in ({"vb_forgetting": 0.0}, {"vb_iterations": 0}, {"vb_prior_dof": -1.0}):
        with pytest.raises(ValueError):
            EstimatorConfig(**bad).validate()


def test_measurement_space_iteration_equals_the_full_state_iteration():
    # Reference: Särkkä & Nummenmaa's loop written on the full state (x, P), with a bias-
    # augmented state like the estimator's (z = p + b + ν, H = [I 0 I]).
    rng = np.random.default_rng(11)
    A = rng.normal(size=(9, 9))
    P = A @ A.T / 9 + 0.1 * np.eye(9)
    x = rng.normal(size=9)
    H = np.hstack([np.eye(3), np.zeros((3, 3)), np.eye(3)])
    z = H @ x + rng.normal(size=3)
    cfg = VbConfig(0.98, 5, 10.0)
    prior = NoisePosterior.prior(np.diag([0.3, 0.5, 0.7]), cfg).predict(cfg)
    dof, scale = prior.dof + 1.0, prior.scale
    for _ in range(cfg.iterations):
        R = scale / dof
        K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
        x_post, P_post = x + K @ (z - H @ x), (np.eye(9) - K @ H) @ P
        e = z - H @ x_post
        scale = prior.scale + np.outer(e, e) + H @ P_post @ H.T
    x2, P2, post = vb_update(x, P, z, H, prior, cfg)
    np.testing.assert_allclose(x2, x_post, atol=1e-12)
    np.testing.assert_allclose(P2, P_post, atol=1e-12)
    np.testing.assert_allclose(post.scale, scale, atol=1e-12)
    assert post.dof == dof


def test_vbakf_method_in_the_filter_learns_inflated_gnss_noise():
    # Through the real registry and fusion engine: fixes with σ = 0.4 m (25x the nominal
    # variance), no multipath bias. The learned R̂ must approach 0.16 m² on every axis.
    from companion.estimator import METHODS
    from companion.estimator.engine import FusionEngine
    from tests.estimator_streams import multipath_stream

    assert "vbakf" in METHODS
    cfg = EstimatorConfig(vb_forgetting=0.995)
    stream = multipath_stream(np.random.default_rng(2), cfg, [(60.0, 0.0)], sigma_clean_m=0.4)
    engine = FusionEngine(cfg, "vbakf")
    fix_k = dict(zip(stream.fix_index.tolist(), range(len(stream.fix_index)), strict=True))
    for k, t in enumerate(stream.t_us.tolist()):
        engine.push_acc(t, *stream.a_ned_m_s2[k].tolist())
        if k in fix_k:
            engine.push_fix(t, stream.z_ned_m[fix_k[k]])
    R_hat = engine.fusions[-1].state.R_hat
    assert engine.counts["gnss_fused"] == len(stream.fix_index)
    np.testing.assert_allclose(np.diag(R_hat), 0.16, rtol=0.25)
    assert np.mean(np.diag(R_hat)) == pytest.approx(0.16, rel=0.12)
