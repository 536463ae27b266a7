"""The per-satellite probe (gcs_tools.evaluate.sat_probe): its statistics on series with known answers, and
a short canyon flight where the simulator's truth is known."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gcs_tools.evaluate.sat_probe import DT_S, auc, canyon, probe_stats


def test_auc_known_answers():
    bad = np.array([False, False, True, True])
    assert auc(bad, np.array([0.1, 0.2, 0.3, 0.4])) == 1.0
    assert auc(bad, np.array([0.4, 0.3, 0.2, 0.1])) == 0.0
    assert auc(bad, np.ones(4)) == 0.5  # ties count half
    assert auc(bad, np.array([0.1, 0.3, 0.2, 0.4])) == 0.75  # 3 of the 4 pairs ordered
    assert math.isnan(auc(np.zeros(4, dtype=bool), np.arange(4.0)))


def test_probe_stats_on_series_with_known_answers():
    """Two satellites over 400 epochs: one clean (white noise), one with NLOS episodes of 10 s (50 m late)
    every 20 s whose β falls 0.4 s after each onset; C/N0 separates them, elevation does not."""
    rng = np.random.default_rng(3)
    n = 400
    t = np.arange(n) * int(DT_S * 1e6)
    nlos = (np.arange(n) // 50) % 2 == 1  # 10 s on, 10 s off
    err_b = np.where(nlos, 50.0, 0.0) + rng.normal(0, 1, n)
    beta_b = np.where(nlos & np.roll(nlos, 2), 0.5, 0.95)  # falls two epochs after the onset
    err_a = rng.normal(0, 1, n)
    s = probe_stats(np.r_[t, t], np.r_[np.zeros(n, int), np.ones(n, int)], np.r_[err_a, err_b],
                    np.r_[np.full(n, 0.95), beta_b], np.r_[err_a, err_b],
                    np.r_[np.full(n, 45.0), np.where(nlos, 30.0, 45.0)], np.full(2 * n, 30.0), 100.0, 0.25,
                    np.r_[np.zeros(n, bool), nlos], np.ones(2 * n, bool))
    d = s["detection_auc"]["NLOS"]
    assert d["-C/N0"] == 1.0 and d["-elevation"] == 0.5 and d["|y|"] == 1.0
    assert 0.95 < d["1 - beta"] < 1.0  # two epochs of each episode missed
    assert d["fde TPR"] == 0.0 and d["fde FPR"] == 0.0  # FDE used everything
    assert s["nlos_episode_s_median"] == pytest.approx(10.0)
    assert s["onset_beta_drop_fraction"] == 1.0 and s["onset_beta_drop_lag_s_median"] == pytest.approx(0.4)
    # the clean one's autocorrelation falls below 1/e after one epoch (0.2 s); a square wave of period 20 s
    # falls as 1 − lag / 5 s: below 1/e at 3.2 s; the median of the two satellites is their mean
    assert s["correlation_time_s_median"] == pytest.approx(0.5 * (0.2 + 3.2), abs=0.2)
    assert math.isnan(s["epoch_median_error_m"])  # epochs of fewer than 5 satellites are not counted
    top = s["by_error"][-1]
    assert top["from_m"] == 40.0 and top["beta_median"] < 0.6
    assert top["r_over_model_median"] == pytest.approx(0.25 * 100.0 ** 0.5)


def test_canyon_probe_reads_the_simulators_truth():
    """20 s of a tuning flight in the calibrated canyon: most observations are reflections, C/N0 tells
    them apart far better than chance (the simulator's C/N0 loses the reflection's loss), and the belief
    does better than chance too."""
    r = canyon("default-tuning", [0], [1000], max_duration_s=20.0)
    assert r["observations"] > 1000 and 0.5 < r["nlos_fraction"] < 1.0
    d = r["detection_auc"]["NLOS"]
    assert d["-C/N0"] > 0.85 and d["1 - beta"] > 0.6, d
