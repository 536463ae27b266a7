"""Rigid-body dynamics (eq. 6-8): known answers and invariants."""

import math

import numpy as np
import pytest

from companion.domain.rotation import euler_to_quaternion, quaternion_to_euler, rotation_matrix
from simvehicle.config import VehicleConfig
from simvehicle.dynamics import RigidBody

CFG = VehicleConfig()
DT = 0.005


def paper_rotation(phi: float, theta: float, psi: float) -> np.ndarray:
    """The paper's ϱ(φ, θ, ψ) exactly as printed under eq. 7."""
    cf, sf, ct, st, cp, sp = (f(a) for a in (phi, theta, psi) for f in (math.cos, math.sin))
    return np.array(
        [
            [cp * ct, cp * st * sf - sp * cf, cp * st * cf + sp * sf],
            [sp * ct, sp * st * sf + cp * cf, sp * st * cf - cp * sf],
            [-st, ct * sf, ct * cf],
        ]
    )


def test_quaternion_matches_paper_rotation_and_euler_round_trip():
    rng = np.random.default_rng(3)
    for _ in range(50):
        phi, theta, psi = rng.uniform(-1.4, 1.4), rng.uniform(-1.4, 1.4), rng.uniform(-3.1, 3.1)
        q = euler_to_quaternion(phi, theta, psi)
        np.testing.assert_allclose(rotation_matrix(q), paper_rotation(phi, theta, psi), atol=1e-14)
        np.testing.assert_allclose(quaternion_to_euler(q), (phi, theta, psi), atol=1e-12)


def test_hover_with_exact_thrust_stays_put():
    body = RigidBody(CFG, [10.0, -5.0, -30.0], yaw_rad=0.7)
    for _ in range(2000):  # 10 s
        body.step(DT, CFG.mass_kg * CFG.gravity_m_s2, 0.0, 0.0, 0.0)
    s = body.state12()
    np.testing.assert_allclose(s[0:3], [10.0, -5.0, -30.0], atol=1e-9)
    np.testing.assert_allclose(s[3:6], 0.0, atol=1e-9)
    np.testing.assert_allclose(s[6:9], [0.0, 0.0, 0.7], atol=1e-12)


def test_free_fall_matches_g():
    cfg = VehicleConfig(drag_n_s_m=0.0)
    body = RigidBody(cfg, [0.0, 0.0, -100.0])
    n = 600
    for _ in range(n):
        body.step(DT, 0.0, 0.0, 0.0, 0.0)
    t = n * DT
    s = body.state12()
    # RK4 is exact on a polynomial of degree 2 in time
    assert s[2] == pytest.approx(-100.0 + 0.5 * cfg.gravity_m_s2 * t * t, abs=1e-9)
    assert s[5] == pytest.approx(cfg.gravity_m_s2 * t, abs=1e-9)
    np.testing.assert_allclose(s[[0, 1, 3, 4]], 0.0, atol=1e-12)


def test_drag_gives_exponential_velocity_decay():
    cfg = VehicleConfig(drag_n_s_m=1.0)
    body = RigidBody(cfg, [0.0, 0.0, -30.0])
    body.x[3] = 4.0  # 4 m/s north, hover thrust: north velocity decays as exp(-c t / m)
    for _ in range(400):
        body.step(DT, cfg.mass_kg * cfg.gravity_m_s2, 0.0, 0.0, 0.0)
    assert body.x[3] == pytest.approx(4.0 * math.exp(-1.0 * 2.0 / cfg.mass_kg), rel=1e-9)


def test_rotation_stays_orthonormal_and_torque_free_momentum_is_conserved():
    cfg = VehicleConfig(inertia_kg_m2=(0.02, 0.03, 0.045))
    body = RigidBody(cfg, [0.0, 0.0, -30.0])
    body.x[10:13] = [3.0, -2.0, 1.5]  # tumbling, asymmetric inertia: ω × Iω is non-zero
    inertia = np.diag(cfg.inertia_kg_m2)

    def momentum_ned() -> np.ndarray:
        return body.rotation() @ inertia @ np.array(body.x[10:13])

    h0 = momentum_ned()
    for _ in range(20_000):  # 100 s torque-free
        body.step(DT, 0.0, 0.0, 0.0, 0.0)
    np.testing.assert_allclose(momentum_ned(), h0, rtol=1e-5, atol=1e-7)
    for k in range(40_000):  # then 200 s under varying torques
        t = k * DT
        body.step(DT, 40.0, 0.05 * math.sin(3 * t), 0.04 * math.cos(2 * t), 0.02 * math.sin(t))
    R = body.rotation()
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-13)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-13)


def rk4_from_deriv(body: RigidBody, dt: float, thrust: float, tx: float, ty: float, tz: float) -> list[float]:
    """One RK4 step built from ``_deriv`` (the reference form), with ``step``'s combination order."""
    n, e, d, *y = body.x  # y = v (3), q (4), ω (3)
    a = thrust * (1.0 / body.cfg.mass_kg)

    def f(state):
        return body._deriv(*state, a, tx, ty, tz)

    k1 = f(y)
    y1 = [yi + 0.5 * dt * ki for yi, ki in zip(y, k1, strict=True)]
    k2 = f(y1)
    y2 = [yi + 0.5 * dt * ki for yi, ki in zip(y, k2, strict=True)]
    k3 = f(y2)
    y3 = [yi + dt * ki for yi, ki in zip(y, k3, strict=True)]
    k4 = f(y3)
    s = dt / 6.0
    pos = [pi + s * (y[i] + 2 * y1[i] + 2 * y2[i] + y3[i]) for i, pi in enumerate((n, e, d))]
    new = [yi + s * (a1 + 2 * (a2 + a3) + a4) for yi, a1, a2, a3, a4 in zip(y, k1, k2, k3, k4, strict=True)]
    inv = 1.0 / math.sqrt(sum(c * c for c in new[3:7]))
    return [*pos, *new[:3], *(c * inv for c in new[3:7]), *new[7:]]


def test_inline_rk4_step_is_bit_for_bit_the_deriv_form():
    cfg = VehicleConfig(inertia_kg_m2=(0.02, 0.03, 0.045), drag_n_s_m=0.4)
    body = RigidBody(cfg, [1.0, -2.0, -30.0])
    rng = np.random.default_rng(8)
    for _ in range(500):
        x = rng.normal(size=13)
        x[6:10] /= np.linalg.norm(x[6:10])
        body.x = x.tolist()
        thrust, tx, ty, tz = 49.0 + 10.0 * rng.normal(), *rng.normal(scale=0.5, size=3)
        expected = rk4_from_deriv(body, DT, thrust, tx, ty, tz)
        body.step(DT, thrust, tx, ty, tz)
        assert body.x == expected
