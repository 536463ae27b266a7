"""Seeded synthetic streams for the estimator tests (and the estimator benchmark).

Every stream is generated from the filter's own linear model (eq. 12-14 with the exact
discretisation of ``companion.estimator.model``), so a consistent filter must be consistent on
it; truth is returned beside the inputs and never fed to the filter.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from companion.estimator import model
from companion.estimator.config import EstimatorConfig
from companion.estimator.methods import MethodContext

IMU_PERIOD_US = 5_000  # 200 Hz
GNSS_EVERY = 10  # one fix per 10 IMU samples: 20 Hz


@dataclass(frozen=True)
class Stream:
    """IMU inputs, fixes and truth on a common 200 Hz grid."""

    t_us: np.ndarray  # (n,) IMU times
    a_ned_m_s2: np.ndarray  # (n, 3) gravity-compensated NED acceleration as measured
    x_true: np.ndarray  # (n, 15) true [p, v, b, a, d] (a: accelerometer bias, body axes; d: NED acc. error)
    fix_index: np.ndarray  # (k,) IMU index at which each fix is valid
    z_ned_m: np.ndarray  # (k, 3) fixes
    bias_std_m: np.ndarray  # (k,) std of the multipath bias in force at each fix (0 = clean)
    rot: np.ndarray | None = None  # (n, 9) R_ned_frd held with each IMU sample (row-major); None = identity

    @property
    def fix_t_us(self) -> np.ndarray:
        return self.t_us[self.fix_index]


def _input(t_s: np.ndarray) -> np.ndarray:
    """A smooth, known manoeuvre (m/s²)."""
    return np.stack([0.5 * np.sin(0.4 * t_s), 0.3 * np.cos(0.25 * t_s), 0.1 * np.sin(0.7 * t_s)], axis=1)


def consistent_stream(rng: np.random.Generator, cfg: EstimatorConfig, duration_s: float,
                      beta: float, yaw_rate_rad_s: float = 0.0) -> tuple[Stream, np.ndarray, np.ndarray]:
    """The filter's model exactly, with belief ``beta`` held: returns (stream, x̂₀, P₀).

    The truth starts from N(x̂₀, P₀) around the filter's own initial estimate at the first
    fix (time 0), so the filter's initial belief is correct by construction. With
    ``yaw_rate_rad_s`` the body yaws and rolls (a body-frame accelerometer bias then moves in
    NED); the attitude is held over each 5 ms step, where the model is exact.
    """
    n = int(round(duration_s * 1e6 / IMU_PERIOD_US)) + 1
    dt = IMU_PERIOD_US * 1e-6
    t_us = np.arange(n, dtype=np.int64) * IMU_PERIOD_US
    a = _input(t_us * 1e-6)
    B = model.input_matrix(dt)
    yaw, roll = yaw_rate_rad_s * t_us * 1e-6, 0.3 * np.sin(yaw_rate_rad_s * t_us * 1e-6)
    cy, sy, cr, sr = np.cos(yaw), np.sin(yaw), np.cos(roll), np.sin(roll)
    zero = np.zeros(n)
    rot = np.stack([cy, -sy * cr, sy * sr, sy, cy * cr, -cy * sr, zero, sr, cr], axis=1)  # Rz(yaw) Rx(roll)
    z0 = np.array([10.0, -5.0, -30.0])
    x_hat0 = np.concatenate([z0, np.zeros(model.N_STATE - 3)])
    P0 = model.initial_cov(cfg)
    x = np.empty((n, model.N_STATE))
    x[0] = x_hat0 - np.linalg.cholesky(P0) @ rng.standard_normal(model.N_STATE)
    w = rng.standard_normal((n, model.N_STATE))
    F, L = model.transition(dt, cfg), np.linalg.cholesky(model.process_noise(dt, cfg.sigma_bias_m(beta), cfg))
    if yaw_rate_rad_s != 0.0:
        steps = _rotating_steps(rot, dt, cfg, beta, yaw_rate_rad_s)
    for k in range(n - 1):
        if yaw_rate_rad_s != 0.0:
            F, L = steps[k]
        x[k + 1] = F @ x[k] + B @ a[k] + L @ w[k]
    idx = np.arange(0, n, GNSS_EVERY)
    Lr = np.linalg.cholesky(cfg.r_nominal_m2())
    z = x[idx, 0:3] + x[idx, 6:9] + rng.standard_normal((len(idx), 3)) @ Lr.T
    z[0] = z0  # the filter starts from the first fix
    return Stream(t_us, a, x, idx, z, np.zeros(len(idx)), None if yaw_rate_rad_s == 0.0 else rot), x_hat0, P0


_STEPS: dict[tuple[Any, ...], list[tuple[np.ndarray, np.ndarray]]] = {}


def _rotating_steps(rot: np.ndarray, dt: float, cfg: EstimatorConfig, beta: float,
                    yaw_rate_rad_s: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """(F, chol Q) of every step of a rotating stream: the same for every stream of the same length, rate
    and config (the attitude is a function of time only), so computed once and kept (the same arrays)."""
    key = (len(rot), dt, cfg, beta, yaw_rate_rad_s)
    if key not in _STEPS:
        if len(_STEPS) >= 4:
            _STEPS.clear()
        _STEPS[key] = [
            (model.transition(dt, cfg, r9),
             np.linalg.cholesky(model.process_noise(dt, cfg.sigma_bias_m(beta), cfg, r9)))
            for r9 in map(tuple, rot[:-1])
        ]
    return _STEPS[key]


def multipath_stream(rng: np.random.Generator, cfg: EstimatorConfig, segments: list[tuple[float, float]],
                     sigma_clean_m: float = 0.08, sigma_degraded_m: float = 0.10,
                     bias_tau_s: float = 3.0) -> Stream:
    """Clean and degraded segments ``[(duration_s, bias_std_m), ...]``.

    A degraded segment carries a first-order Gauss-Markov bias (std ``bias_std_m``, time
    constant ``bias_tau_s``, started from its stationary distribution) and noise
    ``sigma_degraded_m``; clean segments have no bias and noise ``sigma_clean_m``. The IMU has
    white noise ``cfg.sigma_acc_m_s2`` (per sample, as the filter's density assumes).
    """
    dt = IMU_PERIOD_US * 1e-6
    n = int(round(sum(d for d, _ in segments) / dt)) + 1
    t_us = np.arange(n, dtype=np.int64) * IMU_PERIOD_US
    a_true = _input(t_us * 1e-6)
    v = np.vstack([np.zeros(3), np.cumsum(a_true[:-1] * dt, axis=0)])
    p = np.vstack([np.zeros(3), np.cumsum(v[:-1] * dt + 0.5 * a_true[:-1] * dt * dt, axis=0)])
    a_meas = a_true + rng.standard_normal((n, 3)) * (cfg.sigma_acc_m_s2 / np.sqrt(dt))
    std = np.empty(n)
    k0 = 0
    for duration, s in segments:
        k1 = min(n, k0 + int(round(duration / dt)))
        std[k0:k1] = s
        k0 = k1
    std[k0:] = segments[-1][1]
    phi = np.exp(-dt / bias_tau_s)
    b = np.zeros((n, 3))
    e = rng.standard_normal((n, 3))
    for k in range(1, n):
        if std[k] == 0.0:
            b[k] = 0.0
        elif std[k - 1] != std[k]:
            b[k] = std[k] * e[k]
        else:
            b[k] = phi * b[k - 1] + std[k] * np.sqrt(1 - phi * phi) * e[k]
    idx = np.arange(0, n, GNSS_EVERY)
    noise = np.where(std[idx] > 0, sigma_degraded_m, sigma_clean_m)[:, None]
    z = p[idx] + b[idx] + noise * rng.standard_normal((len(idx), 3))
    x = np.hstack([p, v, b, np.zeros((n, model.N_STATE - 9))])
    return Stream(t_us, a_meas, x, idx, z, std[idx])


def drive(stream: Stream, engine: Any, arrival_us: np.ndarray, velocity: np.ndarray | None = None,
          r_m2: Any = None) -> Any:
    """Push the IMU in time order into a ``FusionEngine`` and each fix once the IMU clock reaches
    its arrival time (``arrival_us[i]`` for fix i; equal to ``stream.fix_t_us`` = in order), with
    the receiver's velocity ``velocity[i]`` ((k, 3), NaN = not reported; None: none) and the R
    ``r_m2`` (None: the config's; ``engine.LEARN``: learned)."""
    order = np.argsort(arrival_us, kind="stable")
    j = 0
    for k, t in enumerate(stream.t_us.tolist()):
        engine.push_acc(t, *stream.a_ned_m_s2[k].tolist())
        while j < len(order) and arrival_us[order[j]] <= t:
            i = order[j]
            v = None if velocity is None else tuple(velocity[i].tolist())
            engine.push_fix(int(stream.fix_t_us[i]), stream.z_ned_m[i], r_m2, v)
            j += 1
    return engine


def late_and_in_order(stream: Stream, make_engine: Any, seed: int = 5) -> tuple[Any, Any]:
    """The stream through two fresh engines from ``make_engine()``: every fix delayed by a seeded
    uniform 0-1 s (the first on time, none arriving after the stream's end), and in order."""
    delay_us = np.random.default_rng(seed).uniform(0.0, 1.0e6, size=len(stream.fix_t_us)).astype(np.int64)
    delay_us[0] = 0
    late = drive(stream, make_engine(), np.minimum(stream.fix_t_us + delay_us, stream.t_us[-1]))
    return late, drive(stream, make_engine(), stream.fix_t_us.copy())


def assert_out_of_order_equals_in_order(late: Any, ref: Any) -> None:
    """Many fixes really arrived out of order, and the late run ends in the in-order run's state."""
    assert late.counts["gnss_out_of_order"] > 20
    a, b = late.snapshot(), ref.snapshot()
    np.testing.assert_allclose(a.x, b.x, rtol=0, atol=1e-9)
    assert abs(a.beta - b.beta) <= 1e-9


# The map methods need a map: a world without buildings (clearance infinite everywhere) is open sky.
OPEN_SKY = MethodContext(clearance_m=lambda north_m, east_m: float("inf"))
