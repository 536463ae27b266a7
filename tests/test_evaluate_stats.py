"""Campaign statistics on inputs with known answers."""

import numpy as np
import pytest

from gcs_tools.evaluate import stats


def test_summary_of_known_samples():
    s = stats.summarize(np.arange(1.0, 102.0))  # 1..101
    assert s["median"] == 51.0
    assert s["iqr"] == pytest.approx(76.0 - 26.0)
    assert s["p95"] == pytest.approx(96.0)
    assert s["n"] == 101
    with_nan = stats.summarize(np.array([np.nan, 1.0, 3.0, np.inf]))
    assert with_nan["median"] == 2.0 and with_nan["n"] == 2
    assert np.isnan(stats.summarize(np.array([]))["median"])


def test_bootstrap_ci_of_a_normal_median_covers_and_has_the_right_width():
    # Median of n N(mu, 1) draws has standard error ≈ sqrt(pi/2)/sqrt(n); the 95 % interval
    # is ≈ 2·1.96·that wide. Coverage over repeated experiments must be near 95 %.
    rng = np.random.default_rng(7)
    n, mu, trials = 200, 3.0, 200
    covered, widths = 0, []
    for _ in range(trials):
        x = rng.normal(mu, 1.0, n)
        lo, hi = stats.bootstrap_ci(x, np.random.default_rng(int(rng.integers(1 << 31))), n_resamples=500)
        covered += lo <= mu <= hi
        widths.append(hi - lo)
    expected_width = 2 * 1.96 * np.sqrt(np.pi / 2) / np.sqrt(n)
    assert 0.88 <= covered / trials <= 0.99
    assert np.median(widths) == pytest.approx(expected_width, rel=0.2)


def test_bootstrap_is_deterministic_for_a_seed_and_nan_for_one_unit():
    x = np.random.default_rng(1).exponential(size=60)
    a = stats.bootstrap_ci(x, np.random.default_rng(5))
    b = stats.bootstrap_ci(x, np.random.default_rng(5))
    assert a == b and a[0] < np.median(x) < a[1]
    assert all(np.isnan(stats.bootstrap_ci(np.array([1.0]), np.random.default_rng(0))))


def test_paired_reduction_and_its_interval():
    rng = np.random.default_rng(3)
    naive = rng.uniform(1.0, 2.0, 80)
    method = 0.2 * naive * rng.uniform(0.95, 1.05, 80)  # ≈ −80 %
    value, lo, hi = stats.paired_reduction_ci(method, naive, np.random.default_rng(0))
    assert value == pytest.approx(-0.8, abs=0.02)
    assert lo <= value <= hi and hi - lo < 0.03
    assert stats.reduction(0.7, 1.0) == pytest.approx(-0.3)
    assert np.isnan(stats.reduction(1.0, 0.0))


def test_settling_time_of_a_first_order_step():
    # β(t) = 1 − 0.5·exp(−t/τ) settles within 0.05 of its final value 1 at t = τ·ln(10).
    t = np.arange(0.0, 60.0, 0.05)
    tau = 2.0
    beta = 1.0 - 0.5 * np.exp(-t / tau)
    assert stats.settling_time_s(t, beta, band=0.05) == pytest.approx(tau * np.log(10.0), abs=0.06)
    assert stats.settling_time_s(t, np.full_like(t, 0.3)) == 0.0
    # A late excursion resets the settling time; NaN before initialisation counts as outside.
    late = beta.copy()
    late[1000] = 0.0
    assert stats.settling_time_s(t, late) == pytest.approx(t[1001])
    early_nan = np.where(t < 1.0, np.nan, 0.5)
    assert stats.settling_time_s(t, early_nan) == pytest.approx(1.0)


def test_oscillation_ignores_slow_trends_and_measures_chatter():
    t = np.arange(0.0, 60.0, 0.05)
    slow = 0.5 + 0.3 * np.sin(2 * np.pi * t / 40.0)  # 40 s period: environment change
    assert stats.oscillation_rms(t, slow) < 0.005
    chatter = slow + 0.1 * np.sign(np.sin(2 * np.pi * t / 0.2))  # ±0.1 square wave at 5 Hz
    assert stats.oscillation_rms(t, chatter) == pytest.approx(0.1, rel=0.1)


def test_rank_order():
    med = {"naive": 4.0, "adaptive": 3.0, "first-order": 2.0, "second-order": 1.0}
    assert stats.rank_order(med, ["naive", "adaptive", "first-order", "second-order"])
    assert not stats.rank_order(med, ["adaptive", "naive"])
    assert not stats.rank_order(med, ["naive", "vbakf"])
