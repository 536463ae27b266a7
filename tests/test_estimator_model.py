"""Known answers for the 15-state model (body-frame accelerometer bias, NED acceleration error):
predict = F P Fᵀ + Q, update = closed form, blocks from prefix integrals = stepping sample by sample."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from companion.estimator import model
from companion.estimator.config import EstimatorConfig
from companion.estimator.history import ImuHistory, rotation_blocks

CFG = EstimatorConfig()
N = model.N_STATE  # 15: p, v, b (NED), a (body), d (NED)


def _random_cov(rng: np.random.Generator) -> np.ndarray:
    A = rng.standard_normal((N, N))
    return A @ A.T + 0.1 * np.eye(N)


def _rot9(rng: np.random.Generator) -> tuple[float, ...]:
    return tuple(Rotation.random(random_state=rng).as_matrix().ravel().tolist())


def _q_rw_exact(T: float, rot_of_s, w: float, n: int = 4001) -> np.ndarray:
    """σ_w² ∫ G(u) G(u)ᵀ du on (p, v, a) by quadrature: G(u) = the effect at T of a unit bias kick
    at u (p: −∫_u^T (T − s) R(s) ds, v: −∫_u^T R(s) ds, a: I), for an attitude R(s)."""
    s = np.linspace(0.0, T, n)
    R = np.array([rot_of_s(v) for v in s])  # (n, 3, 3)
    ds = s[1] - s[0]
    # cumulative integrals from the end (trapezoid), of R and of (T − s) R
    def tail(f):
        inc = 0.5 * (f[1:] + f[:-1]) * ds
        return np.concatenate([np.cumsum(inc[::-1], axis=0)[::-1], np.zeros((1, 3, 3))])
    Gv, Gp = -tail(R), -tail((T - s)[:, None, None] * R)
    G = np.concatenate([Gp, Gv, np.broadcast_to(np.eye(3), (n, 3, 3))], axis=1)  # (n, 9, 3)
    return w * np.trapezoid(G @ G.transpose(0, 2, 1), s, axis=0)


def test_predict_at_a_constant_attitude_equals_F_P_Ft_plus_exact_Q():
    rng = np.random.default_rng(1)
    P = _random_cov(rng)
    T, sigma_b = 0.05, 0.37
    r9 = _rot9(rng)
    R = np.array(r9).reshape(3, 3)
    F = np.eye(N)
    F[0:3, 3:6] = T * np.eye(3)
    F[0:3, 9:12] = -T * T / 2 * R  # v̇ = ã − R a − d (a in body axes, d in NED)
    F[3:6, 9:12] = -T * R
    F[0:3, 12:15] = -T * T / 2 * np.eye(3)
    F[3:6, 12:15] = -T * np.eye(3)
    F[6:9, 6:9] = np.exp(-T / CFG.bias_tau_s) * np.eye(3)
    q = CFG.sigma_acc_m_s2**2
    w, e = 0.3**2, 0.2**2  # large densities, so the random-walk terms are visible
    cfg = EstimatorConfig(sigma_acc_bias_rw_m_s2_sqrt_s=0.3, sigma_acc_ned_rw_m_s2_sqrt_s=0.2)
    Q = np.zeros((N, N))
    Q[0:3, 0:3] = q * T**3 / 3 * np.eye(3)
    Q[0:3, 3:6] = Q[3:6, 0:3] = q * T**2 / 2 * np.eye(3)
    Q[3:6, 3:6] = q * T * np.eye(3)
    Q[6:9, 6:9] = (1 - np.exp(-2 * T / CFG.bias_tau_s)) * sigma_b**2 * np.eye(3)
    idx = np.r_[0:6, 9:12]
    Q[np.ix_(idx, idx)] += _q_rw_exact(T, lambda s: R, w)
    idx = np.r_[0:6, 12:15]
    Q[np.ix_(idx, idx)] += _q_rw_exact(T, lambda s: np.eye(3), e)  # d: a bias fixed in NED
    expected = F @ P @ F.T + Q
    np.testing.assert_allclose(model.predict_cov(P, T, sigma_b, cfg, r9), expected, rtol=1e-6, atol=1e-12)
    alpha = model.bias_decay(T, CFG)
    got = model.predict_block(P, T, T * R, T * T / 2 * R, alpha, q, (1 - alpha**2) * sigma_b**2, w, e)
    np.testing.assert_allclose(got, expected, rtol=1e-6, atol=1e-12)


def test_fast_block_propagator_equals_the_reference():
    rng = np.random.default_rng(7)
    w, e = 0.3**2, 0.2**2
    prop = model.BlockPropagator(0.1, w, e)
    for _ in range(3):
        P = _random_cov(rng)
        A, B = rng.standard_normal(9), rng.standard_normal(9)
        T, alpha, q_b = 0.05 + rng.uniform(), 0.97, 0.01
        ref = model.predict_block(P, T, A.reshape(3, 3), B.reshape(3, 3), alpha, 0.1, q_b, w, e)
        got = prop.predict(P, T, (-A).tolist(), (-B).tolist(), alpha, q_b)
        np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12)
        var = prop.variances(P, T, (-A).tolist(), (-B).tolist(), alpha, q_b)
        np.testing.assert_allclose(var, np.diag(ref)[0:9], rtol=1e-12, atol=1e-12)


def test_blocks_compose_exactly_at_a_constant_attitude():
    rng = np.random.default_rng(2)
    P = _random_cov(rng)
    r9 = _rot9(rng)
    stepped = P
    for _ in range(240):
        stepped = model.predict_cov(stepped, 0.005, 0.5, CFG, r9)
    np.testing.assert_allclose(model.predict_cov(P, 1.2, 0.5, CFG, r9), stepped, rtol=1e-10, atol=1e-12)


def test_rotating_block_transition_is_exact_and_its_q_close_and_psd():
    """A block whose attitude turns 2 rad/s for 0.2 s: F from the prefix integrals = the product of
    the per-sample F's; Q with the mean rotation is PSD and within 1 % (Frobenius) of the exact Q."""
    dt, n = 0.005, 40
    rots = [Rotation.from_rotvec([0.1 * k * dt, 0.2 * k * dt, 2.0 * k * dt]).as_matrix() for k in range(n)]
    h = ImuHistory(hold_max_s=0.1)
    for k in range(n + 1):
        h.append(k * 5000, 0.0, 0.0, 0.0, tuple(rots[min(k, n - 1)].ravel().tolist()))
    nA, nB = rotation_blocks(h.integrals(0), h.integrals(n * 5000))
    A, B = -np.array(nA).reshape(3, 3), -np.array(nB).reshape(3, 3)
    F_prod = np.eye(N)
    for k in range(n):
        F_prod = model.transition(dt, CFG, tuple(rots[k].ravel())) @ F_prod
    T = n * dt
    np.testing.assert_allclose(model.transition_block(T, A, B, model.bias_decay(T, CFG)), F_prod, atol=1e-13)
    w = 0.3**2
    Q = np.zeros((N, N))
    model.add_process_noise(Q, T, A / T, 0.0, 0.0, w, 0.0)
    idx = np.r_[0:6, 9:12]
    exact = _q_rw_exact(T, lambda s: rots[min(int(s / dt), n - 1)], w, n=8001)
    approx = Q[np.ix_(idx, idx)]
    assert np.linalg.norm(approx - exact) < 0.01 * np.linalg.norm(exact)
    assert np.linalg.eigvalsh(approx).min() > -1e-15
    assert np.linalg.norm(A / T - rots[0]) > 0.1  # the attitude really turned


def test_update_equals_closed_form():
    rng = np.random.default_rng(3)
    P = _random_cov(rng)
    x = rng.standard_normal(N)
    z = rng.standard_normal(3)
    r = (0.01, 0.02, 0.03)
    H = model.H
    S = H @ P @ H.T + np.diag(r)
    K = P @ H.T @ np.linalg.inv(S)
    y = z - H @ x
    x_exp = x + K @ y
    P_exp = (np.eye(N) - K @ H) @ P
    xr, Pr, _, _, nis_r = model.update(x, P, z, np.diag(r))
    np.testing.assert_allclose(xr, x_exp, atol=1e-12)
    np.testing.assert_allclose(Pr, P_exp, atol=1e-12)
    xf, Pf, nis = model.update_fast(tuple(x), P, tuple(y), r)
    np.testing.assert_allclose(xf, x_exp, atol=1e-12)
    np.testing.assert_allclose(Pf, P_exp, atol=1e-12)
    assert nis == pytest.approx(float(y @ np.linalg.solve(S, y)), rel=1e-12)
    assert nis_r == pytest.approx(nis, rel=1e-12)
    np.testing.assert_allclose(np.array(model.inv3(S.tolist())).reshape(3, 3), np.linalg.inv(S), rtol=1e-12)


def test_mean_from_prefix_integrals_equals_stepping_sample_by_sample():
    """Irregular sample times and a turning attitude with a body-frame accelerometer bias: one call
    over the whole interval == x ← F(dt, R_k) x + B a_k per sample."""
    rng = np.random.default_rng(4)
    dts_us = rng.integers(3000, 9000, size=300)
    t_us = np.concatenate([[1_000_000], 1_000_000 + np.cumsum(dts_us)])
    a = rng.standard_normal((len(t_us), 3))
    rots = [_rot9(rng) for _ in t_us]
    h = ImuHistory(hold_max_s=0.1)
    for t, ak, rk in zip(t_us.tolist(), a.tolist(), rots, strict=True):
        h.append(t, *ak, rk)
    x0 = rng.standard_normal(N)
    t_end = int(t_us[-1]) + 2500  # past the last sample: its input is held
    x = x0.copy()
    times = [*t_us.tolist(), t_end]
    for k in range(len(t_us)):
        dt = (times[k + 1] - times[k]) * 1e-6
        x = model.transition(dt, CFG, rots[k]) @ x + model.input_matrix(dt) @ a[k]
    alpha = model.bias_decay((t_end - t_us[0]) * 1e-6, CFG)
    got = h.propagate_mean(tuple(x0), int(t_us[0]), t_end, alpha)
    np.testing.assert_allclose(got, x, rtol=1e-10, atol=1e-10)
    # any sub-interval too, starting between samples
    t_a = int(t_us[10]) + 1234
    mid = h.propagate_mean(tuple(x0), int(t_us[0]), t_a, model.bias_decay((t_a - t_us[0]) * 1e-6, CFG))
    rest = h.propagate_mean(mid, t_a, t_end, model.bias_decay((t_end - t_a) * 1e-6, CFG))
    np.testing.assert_allclose(rest, x, rtol=1e-10, atol=1e-10)


def test_batch_append_equals_per_sample_append_bit_for_bit():
    rng = np.random.default_rng(6)
    t_us = 5000 * np.arange(1, 201, dtype=np.int64)
    a = rng.standard_normal((200, 3))
    rot = np.array([_rot9(rng) for _ in range(200)])
    one, many = ImuHistory(0.1), ImuHistory(0.1)
    for h in (one, many):
        h.append(0, 0.1, 0.2, 0.3, _rot9(np.random.default_rng(0)))
    for t, ak, rk in zip(t_us.tolist(), a.tolist(), rot.tolist(), strict=True):
        one.append(t, *ak, tuple(rk))
    many.append_batch(t_us, a, rot)
    assert one.rows == many.rows


def test_gap_coasts_instead_of_holding_a_stale_input():
    h = ImuHistory(hold_max_s=0.1)
    assert not h.append(0, 1.0, 0.0, 0.0)
    assert h.append(1_000_000, 0.0, 0.0, 0.0)  # 1 s gap
    x = h.propagate_mean((0.0,) * N, 0, 1_000_000, 1.0)
    # 1 m/s² held for 0.1 s only, then constant velocity
    assert x[3] == pytest.approx(0.1)
    assert x[0] == pytest.approx(0.5 * 0.1**2 + 0.1 * 0.9)
    # a body-frame bias of 1 m/s² along x with the body yawed 90°: −1 m/s² east over the 1 s
    h2 = ImuHistory(hold_max_s=0.1)
    yaw90 = (0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    h2.append(0, 0.0, 0.0, 0.0, yaw90)
    h2.append(1_000_000, 0.0, 0.0, 0.0, yaw90)
    x2 = h2.propagate_mean((0.0,) * 9 + (1.0, 0.0, 0.0, 0.0, 0.0, 0.0), 0, 1_000_000, 1.0)
    assert x2[3] == pytest.approx(0.0, abs=1e-15) and x2[4] == pytest.approx(-1.0)
    assert x2[1] == pytest.approx(-0.5) and math.isclose(x2[9], 1.0)
    # ... and a NED error of 1 m/s² down is not rotated
    x3 = h2.propagate_mean((0.0,) * 14 + (1.0,), 0, 1_000_000, 1.0)
    assert x3[5] == pytest.approx(-1.0) and x3[2] == pytest.approx(-0.5) and x3[4] == 0.0
