"""Known answers for the 12-state model: predict = F P Fᵀ + Q, update = closed form, exact blocks."""

import numpy as np
import pytest

from companion.estimator import model
from companion.estimator.config import EstimatorConfig
from companion.estimator.history import ImuHistory

CFG = EstimatorConfig()


def _random_axis_cov(rng: np.random.Generator) -> model.Cov:
    blocks = []
    for _ in range(3):
        A = rng.standard_normal((4, 4))
        M = A @ A.T + 0.1 * np.eye(4)
        blocks.append(tuple(M[u, v] for u, v in ((0, 0), (0, 1), (0, 2), (0, 3), (1, 1), (1, 2), (1, 3),
                                                 (2, 2), (2, 3), (3, 3))))
    return tuple(blocks)  # type: ignore[return-value]


def test_predict_equals_F_P_Ft_plus_Q():
    rng = np.random.default_rng(1)
    P = _random_axis_cov(rng)
    T, sigma_b = 0.005, 0.37
    F = np.eye(12)
    F[0:3, 3:6] = T * np.eye(3)
    F[0:3, 9:12] = -T * T / 2 * np.eye(3)  # v̇ = ã − a
    F[3:6, 9:12] = -T * np.eye(3)
    F[6:9, 6:9] = np.exp(-T / CFG.bias_tau_s) * np.eye(3)
    q = CFG.sigma_acc_m_s2**2
    w = CFG.sigma_acc_bias_rw_m_s2_sqrt_s**2
    # Q of the random walk a through (p, v, a): ∫ g(s) w g(s)ᵀ ds by quadrature, g(s) = the effect
    # on (p, v, a) of a unit kick of a, s seconds before T (v̇ = −a)
    s_grid = np.linspace(0.0, T, 20001)
    g = np.stack([-s_grid**2 / 2, -s_grid, np.ones_like(s_grid)])
    Q_rw = w * np.trapezoid(g[:, None, :] * g[None, :, :], s_grid, axis=2)
    Q = np.zeros((12, 12))
    Q[0:3, 0:3] = q * T**3 / 3 * np.eye(3)
    Q[0:3, 3:6] = Q[3:6, 0:3] = q * T**2 / 2 * np.eye(3)
    Q[3:6, 3:6] = q * T * np.eye(3)
    Q[6:9, 6:9] = (1 - np.exp(-2 * T / CFG.bias_tau_s)) * sigma_b**2 * np.eye(3)
    for u, iu in enumerate((0, 3, 9)):
        for v, iv in enumerate((0, 3, 9)):
            Q[iu:iu + 3, iv:iv + 3] += Q_rw[u, v] * np.eye(3)
    expected = F @ model.cov_to_matrix(P) @ F.T + Q
    reference = model.predict_cov(model.cov_to_matrix(P), T, sigma_b, CFG)
    np.testing.assert_allclose(reference, expected, atol=1e-12)
    alpha = model.bias_decay(T, CFG)
    fast = model.predict_axes(P, T, alpha, q, model.bias_noise_unit(T, CFG) * sigma_b**2, w)
    np.testing.assert_allclose(model.cov_to_matrix(fast), expected, atol=1e-12)
    var = model.predict_var_axes(P, T, alpha, q, model.bias_noise_unit(T, CFG) * sigma_b**2, w)
    np.testing.assert_allclose(var, np.diag(expected)[[0, 1, 2, 3, 4, 5, 6, 7, 8]], rtol=1e-12, atol=1e-15)


def test_blocks_of_predictions_compose_exactly():
    rng = np.random.default_rng(2)
    P = model.cov_to_matrix(_random_axis_cov(rng))
    stepped = P
    for _ in range(240):
        stepped = model.predict_cov(stepped, 0.005, 0.5, CFG)
    np.testing.assert_allclose(model.predict_cov(P, 1.2, 0.5, CFG), stepped, rtol=1e-10, atol=1e-12)


def test_update_equals_closed_form():
    rng = np.random.default_rng(3)
    Pa = _random_axis_cov(rng)
    P = model.cov_to_matrix(Pa)
    x = rng.standard_normal(12)
    z = rng.standard_normal(3)
    r = (0.01, 0.02, 0.03)
    H = model.H
    S = H @ P @ H.T + np.diag(r)
    K = P @ H.T @ np.linalg.inv(S)
    y = z - H @ x
    x_exp = x + K @ y
    P_exp = (np.eye(12) - K @ H) @ P
    xr, Pr, _, _, nis_r = model.update(x, P, z, np.diag(r))
    np.testing.assert_allclose(xr, x_exp, atol=1e-12)
    np.testing.assert_allclose(Pr, P_exp, atol=1e-12)
    xf, Pf, nis = model.update_axes(tuple(x), Pa, tuple(z), r)
    np.testing.assert_allclose(xf, x_exp, atol=1e-12)
    np.testing.assert_allclose(model.cov_to_matrix(Pf), P_exp, atol=1e-12)
    assert nis == pytest.approx(float(y @ np.linalg.solve(S, y)), rel=1e-12)
    assert nis_r == pytest.approx(nis, rel=1e-12)


def test_mean_from_prefix_integrals_equals_stepping_eq12():
    """Irregular sample times, one call over the whole interval == x ← F x + B a per sample."""
    rng = np.random.default_rng(4)
    dts_us = rng.integers(3000, 9000, size=300)
    t_us = np.concatenate([[1_000_000], 1_000_000 + np.cumsum(dts_us)])
    a = rng.standard_normal((len(t_us), 3))
    h = ImuHistory(hold_max_s=0.1)
    for t, ak in zip(t_us.tolist(), a.tolist(), strict=True):
        h.append(t, *ak)
    x0 = rng.standard_normal(12)
    t_end = int(t_us[-1]) + 2500  # past the last sample: its input is held
    x = x0.copy()
    times = [*t_us.tolist(), t_end]
    for k in range(len(t_us)):
        dt = (times[k + 1] - times[k]) * 1e-6
        x = model.transition(dt, CFG) @ x + model.input_matrix(dt) @ a[k]
    alpha = model.bias_decay((t_end - t_us[0]) * 1e-6, CFG)
    got = h.propagate_mean(tuple(x0), int(t_us[0]), t_end, alpha)
    np.testing.assert_allclose(got, x, rtol=1e-10, atol=1e-10)
    # any sub-interval too, starting between samples
    t_a = int(t_us[10]) + 1234
    mid = h.propagate_mean(tuple(x0), int(t_us[0]), t_a, model.bias_decay((t_a - t_us[0]) * 1e-6, CFG))
    rest = h.propagate_mean(mid, t_a, t_end, model.bias_decay((t_end - t_a) * 1e-6, CFG))
    np.testing.assert_allclose(rest, x, rtol=1e-10, atol=1e-10)


def test_gap_coasts_instead_of_holding_a_stale_input():
    h = ImuHistory(hold_max_s=0.1)
    assert not h.append(0, 1.0, 0.0, 0.0)
    assert h.append(1_000_000, 0.0, 0.0, 0.0)  # 1 s gap
    x = h.propagate_mean((0.0,) * 12, 0, 1_000_000, 1.0)
    # 1 m/s² held for 0.1 s only, then constant velocity
    assert x[3] == pytest.approx(0.1)
    assert x[0] == pytest.approx(0.5 * 0.1**2 + 0.1 * 0.9)
