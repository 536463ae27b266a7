"""The reported horizontal accuracy's two statistics (``companion.estimator.consistency``): the innovations'
consistency factor ``Fit.inflation`` and the fixes' own scatter and correlation ``Scatter``, on known
answers, and the floor they give (``honest_horizontal``) staying P × k on the filter's own model."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.estimator.config import EstimatorConfig
from companion.estimator.consistency import (
    C_MAX,
    Fit,
    Scatter,
    Scatter1,
    accuracy_inflation,
    fix_floor,
    honest_horizontal,
    snapshot_parts,
)
from companion.estimator.engine import FusionEngine
from tests.estimator_streams import OPEN_SKY, consistent_stream, drive

CFG = EstimatorConfig()
AXES = np.arange(3)
PERIOD_US = 200_000  # fixes at 5 Hz
WINDOW_S = 20.0


def _fit_statistic(rng: np.random.Generator, sigma: float, n: int = 300) -> float:
    """The windowed statistic (before its floor at 1) after ``n`` fixes whose N, E, D innovations over
    their assumed √S are white with std ``sigma``."""
    fit = Fit()
    for i in range(n):
        fit = fit.add(i * PERIOD_US, AXES, sigma * rng.standard_normal(3), WINDOW_S)
    return float(fit.nu_sum @ fit.nu_sum / fit.w2_sum.sum())


@pytest.mark.parametrize("sigma", [1.0, 3.0])
def test_the_innovation_factor_recovers_a_known_scale(sigma):
    """Innovations drawn with ``sigma`` × the σ the filter assumed: the statistic is σ² × χ²(3)/3 at each
    time, so its mean over 400 independent streams is σ² within 4 standard errors (χ²(3)/3 has a
    relative std of √(2/3)); the std ratio √k recovers σ (1 on consistent innovations, 3 at 3×)."""
    rng = np.random.default_rng(11)
    k = np.array([_fit_statistic(rng, sigma) for _ in range(400)])
    tol = 4.0 * math.sqrt(2.0 / 3.0) / math.sqrt(len(k))
    assert abs(k.mean() / sigma**2 - 1.0) < tol, (k.mean(), sigma**2, tol)
    assert abs(math.sqrt(k.mean()) - sigma) < sigma * tol
    floored = [max(1.0, x) for x in k]  # Fit.inflation: never below P
    assert min(floored) == 1.0 if sigma == 1.0 else np.median(floored) > 4.0


def _scatter(errors: np.ndarray, velocity: np.ndarray, positions: np.ndarray) -> Scatter:
    s = Scatter()
    for i in range(len(errors)):
        z = positions[i] + errors[i]
        s = s.add(i * PERIOD_US, (float(z[0]), float(z[1])), (float(velocity[i, 0]), float(velocity[i, 1])),
                  WINDOW_S)
    return s


def _track(n: int) -> tuple[np.ndarray, np.ndarray]:
    """A circle of 20 m radius flown at 4 m/s: positions and exact velocities (N, E) at the fixes."""
    t = np.arange(n) * PERIOD_US * 1e-6
    w = 4.0 / 20.0
    pos = 20.0 * np.column_stack([np.sin(w * t), 1.0 - np.cos(w * t)])
    vel = 4.0 * np.column_stack([np.cos(w * t), np.sin(w * t)])
    return pos, vel


@pytest.mark.parametrize("tau_s", [0.0, 3.0])
def test_the_fixes_scatter_and_correlation_are_known_answers(tau_s):
    """Fix errors N(0, 0.5²) per axis, white or a Gauss-Markov process of correlation time 3 s, on a track
    flown at 4 m/s whose velocity is known: the scatter is 0.25 m² and the correlation (1 + ρ)/(1 − ρ),
    ρ = e^(−0.2/τ) (1 white; 30.0 at τ = 3 s). Over 200 independent 60 s streams the medians are within
    20 % (the window holds ~100 fixes, ~7 independent ones at τ = 3 s: the single values scatter)."""
    rng = np.random.default_rng(5)
    n = 300
    pos, vel = _track(n)
    rho = math.exp(-PERIOD_US * 1e-6 / tau_s) if tau_s > 0.0 else 0.0
    var, cor = [], []
    for _ in range(200):
        e = np.empty((n, 2))
        e[0] = 0.5 * rng.standard_normal(2)
        for i in range(1, n):
            e[i] = rho * e[i - 1] + math.sqrt(1.0 - rho * rho) * 0.5 * rng.standard_normal(2)
        s = _scatter(e, vel, pos)
        var.append(s.variance())
        cor.append(s.correlation())
    c_true = (1.0 + rho) / (1.0 - rho)
    assert np.median(var) == pytest.approx(0.25, rel=0.2)
    assert np.median(cor) == pytest.approx(c_true, rel=0.2), (np.median(cor), c_true)


def test_the_floor_is_p_times_k_on_the_filters_own_model():
    """The filter's own model (naive, belief held, fixes white as the filter assumes, no receiver velocity:
    the filter's own carries the motion): the fixes' correlation is about 1 (its median below 1.5), so the
    reported horizontal variance stays about P × k: within 1.25 × at the median fix, 1.5 × at 90 % of them,
    never below."""
    ratios, cors = [], []
    for seed in range(3):
        s, _, _ = consistent_stream(np.random.default_rng(seed), CFG, 30.0, 1.0)
        e = FusionEngine(CFG, "naive", context=OPEN_SKY)
        drive(s, e, s.fix_t_us.copy())
        for f in e.entries:
            if f.t_us < 5_000_000 or f.z_ned_m is None:
                continue
            k = accuracy_inflation(f.fit, CFG.accuracy_window_s)
            p = np.array((f.P[0, 0], f.P[1, 1]))
            ratios.extend(honest_horizontal(p, k, f.scatter, f.r_nominal_m2[0]) / (p * k))
            cors.append(f.scatter.correlation())
    r = np.array(ratios)
    assert np.median(r) < 1.25 and np.quantile(r, 0.9) < 1.5 and r.min() >= 1.0, np.quantile(r, (0.5, 0.9))
    assert np.median(cors) < 1.5, np.median(cors)


def test_the_floor_is_one_fix_at_most_and_never_below_p_times_k():
    """max(k P, min(c k P, σ²)): σ² the larger of the scatter and the stated variance; c = 1 leaves k P."""
    s = Scatter()
    white = honest_horizontal(np.array((0.01, 0.02)), 2.0, s, 4.0)  # no fixes yet: c = 1
    np.testing.assert_allclose(white, (0.02, 0.04))
    rng = np.random.default_rng(3)
    pos, vel = _track(200)
    e = np.cumsum(0.05 * rng.standard_normal((200, 2)), axis=0)  # a random walk: c ≫ 1
    s = _scatter(e, vel, pos)
    assert s.correlation() > 20.0
    assert 0.0 < s.variance() < 4.0
    p = np.array((0.5, 0.6))  # × c > 4: capped at one fix's variance, the stated 2 m (above the scatter)
    np.testing.assert_allclose(honest_horizontal(p, 1.0, s, 4.0), (4.0, 4.0))
    np.testing.assert_allclose(honest_horizontal(p, 1.0, s, math.inf), np.maximum(p, s.variance()))
    tiny = np.array((0.001, 0.002))  # × c below the cap: c k P
    np.testing.assert_allclose(honest_horizontal(tiny, 2.0, s, 4.0), tiny * 2.0 * s.correlation())
    big = np.array((50.0, 60.0))
    np.testing.assert_allclose(honest_horizontal(big, 1.5, s, 4.0), big * 1.5)  # never below k P


def test_one_axis_scatter_is_two_equal_axes_bit_for_bit():
    """``Scatter1`` against ``Scatter`` given the same axis twice (how the vertical was kept before), over
    a seeded random sequence: fixes at 2.5-20 Hz with white, random-walk and stationary stretches (the
    changes of q exactly 0), gaps of 3 windows (the window expired), of 720 windows (the decay a
    subnormal) and of 1000 (a = 0), and restarts from empty (a reset): after every fix each sum equals
    the two-axis sum of either axis (the squared changes' pooled sums), and the variance, the correlation
    (alone and together, ``statistics``) and both floors (``fix_floor``, ``snapshot_parts``) are the same
    bits."""
    rng = np.random.default_rng(2026)
    window = 5.0
    one, two, t, drift = Scatter1(), Scatter(), 1_000_000, 0.0
    seen = {"c=1": 0, "1<c<C_MAX": 0, "c=C_MAX": 0, "s2>0": 0, "s2=0": 0}
    for i in range(6000):
        if i % 1500 == 1499:  # a reset: both start again
            one, two = Scatter1(), Scatter()
        gap = 1_000_000 * {700: 3.0 * window, 2100: 720.0 * window, 3300: 1000.0 * window}.get(i, 0.0)
        t += int(gap) or int(rng.integers(50_000, 400_000))
        phase = (i // 250) % 4
        if phase == 3:  # stationary: the same fix, no motion
            z, v = 12.5, 0.0
        else:
            drift += 0.05 * rng.standard_normal() if phase == 1 else 0.0
            v = float(rng.normal(-3.0, 0.1))  # the motion, roughly known
            z = float(-3.0 * t * 1e-6 + drift + (0.3 if phase != 2 else 3.0) * rng.standard_normal())
        one, two = one.add(t, z, v, window), two.add(t, (z, z), (v, v), window)
        assert one.t_us == two.t_us and (one.z, one.v) == (two.z[0], two.v[0]) == (two.z[1], two.v[1])
        assert (one.q_prev is None) == (two.q_prev is None)
        if one.q_prev is not None:
            assert one.q_prev == two.q_prev[0] == two.q_prev[1]
        for ax in (0, 1):
            assert (one.q, one.q_sum, one.q2_sum) == (two.q[ax], two.q_sum[ax], two.q2_sum[ax])
        assert (one.w_sum, one.w2_sum, one.d1_sum, one.d2_sum, one.d_w_sum) == (
            two.w_sum, two.w2_sum, two.d1_sum, two.d2_sum, two.d_w_sum)
        c, s2 = one.correlation(), one.variance()
        assert c == two.correlation() and s2 == two.variance()
        assert one.statistics() == two.statistics() == (c, s2)  # (both at once: the floors')
        r = float(rng.choice((0.04, 1.0, math.inf)))
        assert fix_floor(one, r) == fix_floor(two, r)
        assert snapshot_parts(one, r) == snapshot_parts(two, r)
        seen["c=1"] += c == 1.0
        seen["1<c<C_MAX"] += 1.0 < c < C_MAX
        seen["c=C_MAX"] += c == C_MAX
        seen["s2>0"] += s2 > 0.0
        seen["s2=0"] += s2 == 0.0
    assert min(seen.values()) > 5, seen  # every branch of both statistics compared
