"""The bound on the real-flight campaign (``python -m gcs_tools.evaluate.real_bound``): the filters'
known answers, the campaign's windows, the best-in-hindsight choice and bad arguments."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from ansfl_helpers import write_flight

from gcs_tools.evaluate import real_bound as rb
from gcs_tools.replay.synthetic_gnss import load_error_series


@pytest.fixture(scope="module")
def corpus(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("ansfl")
    write_flight(root / "a", seconds=20.0, offset_s=0.2, seed=1)
    series = root / "series.csv"
    t = np.arange(0.0, 120.0, 0.2)
    rng = np.random.default_rng(3)
    err = np.column_stack((4 * np.sin(t / 9), 2 * np.cos(t / 13), np.zeros_like(t)))
    err += rng.normal(0, 3, (len(t), 3))
    h_acc = 3.0 + np.abs(np.sin(t))
    rows = "\n".join(f"{a:.3f},{e[0]:.4f},{e[1]:.4f},{e[2]:.4f},{h:.3f},5.0"
                     for a, e, h in zip(t, err, h_acc, strict=True))
    series.write_text("t_s,err_n_m,err_e_m,err_d_m,h_acc_m,v_acc_m\n" + rows + "\n")
    return root, series


def test_a_constant_error_is_estimated_at_once():
    err = np.tile([3.0, 4.0], (50, 1))  # every filter's constant is the first fix's error: |e| = 5
    G = 3
    med = rb.filter_medians(err, np.full((G, 50), 4.0), np.array([1.0, 3.0, 10.0]),
                            np.array([2.0, 10.0, 30.0]), np.array([0.0, 2.0, 3.0]))
    np.testing.assert_allclose(med, 5.0, rtol=1e-3)  # the bias takes ~(σ_b² + r) / 1e6 of the first fix


def test_white_noise_averages_down_and_an_outlier_is_gated():
    rng = np.random.default_rng(1)
    err = rng.normal(0.0, 5.0, (400, 2))
    err[200] = (300.0, 0.0)  # one wild fix
    r = np.full((2, 400), 25.0)
    med = rb.filter_medians(err, r, np.array([0.01, 0.01]), np.array([10.0, 10.0]), np.array([0.0, 3.0]))
    raw = np.median(np.hypot(err[:, 0], err[:, 1]))
    assert med[1] < 0.25 * raw  # a running mean of white noise (σ/√k), the outlier gated out
    assert med[0] > med[1]  # without a gate the 300 m fix drags the mean for the rest of the window


def test_a_huber_update_bounds_an_outlier_pull_and_is_the_kalman_update_inside_its_threshold():
    rng = np.random.default_rng(1)
    err = rng.normal(0.0, 5.0, (400, 2))
    r = np.full((3, 400), 25.0)
    args = (np.full(3, 0.01), np.full(3, 10.0), np.zeros(3))
    clean = rb.filter_medians(err, r, *args, np.array([0.0, 1e9, 1.5]))
    # off / never active / rarely active
    assert clean[1] == clean[0] and clean[2] == pytest.approx(clean[0], rel=0.1)
    err[200] = (300.0, 0.0)
    plain, never, huber = rb.filter_medians(err, r, *args, np.array([0.0, 1e9, 1.5]))
    assert never == plain and huber < 0.8 * plain  # the 300 m fix pulls by ~1.5σ / k, not 300 m / k


def test_the_step_variance_is_the_largest_recent_jump_of_the_errors():
    err = np.zeros((7, 2))
    err[3:] = (6.0, 8.0)  # one 10 m jump at fix 3: 10²/2 = 50 m² per axis at fixes 3, 4, 5
    np.testing.assert_array_equal(rb.step_var_m2(err), [0.0, 0.0, 0.0, 50.0, 50.0, 50.0, 0.0])
    assert all("step_c" in c for c in rb.grid("none", "step")) and len(rb.grid("none", "step")) == 1600
    assert not any("step_c" in c or "huber_c" in c for c in rb.grid("none"))


def test_windows_are_the_campaign_fixes_and_the_best_filter_beats_raw(corpus):
    root, series = corpus
    wins = rb.windows(root, "a", str(series), [0, 1])
    assert len(wins) == 2
    s = load_error_series(series)
    for err, h_acc in wins:  # errors and accuracies from the series (linear interpolation between epochs)
        assert err.shape[1] == 2 and len(err) == len(h_acc) > 80
        lo, hi = s.err_ned_m[:, 0].min(), s.err_ned_m[:, 0].max()
        assert err[:, 0].min() >= lo - 1e-9 and err[:, 0].max() <= hi + 1e-9
        assert np.all((h_acc >= 3.0 - 1e-9) & (h_acc <= 4.0 + 1e-9))
    for accuracy in ("reported", "none"):
        b = rb.bound(wins, accuracy)
        assert b["filters"] == len(rb.grid(accuracy)) and b["windows"] == 2
        assert b["best_filter_median_m"] < b["raw_median_m"]
        cfg = b["best_filter"]
        key = "c_hacc" if accuracy == "reported" else "sigma_w_m"
        one = [np.array([cfg[k]]) for k in ("sigma_b_m", "tau_s", "gate_sigma")]
        med = np.mean([  # the reported best is the best of the grid, re-computed alone
            rb.filter_medians(e, _white(cfg[key], h, accuracy)[None], *one)[0] for e, h in wins])
        assert med == pytest.approx(b["best_filter_median_m"], rel=1e-12)
        assert b["best_huber_filter"]["huber_c"] in rb.HUBER_C
        assert b["best_step_filter"]["step_c"] in rb.STEP_C
        assert max(b["best_huber_filter_median_m"], b["best_step_filter_median_m"]) < b["raw_median_m"]


def _white(w: float, h_acc: np.ndarray, accuracy: str) -> np.ndarray:
    return (w * h_acc) ** 2 if accuracy == "reported" else np.full(len(h_acc), w * w)


def test_bad_arguments_are_one_line_errors(corpus, capsys):
    root, series = corpus
    base = ["--corpus", str(root), "--flights"]
    assert rb.main([*base, "a", "--errors", "model"]) == 2
    assert rb.main([*base, "a", "--errors", str(series), "--accuracy", "eph"]) == 2
    assert rb.main([*base, "nope", "--errors", str(series)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3 and all(line.startswith("real_bound: error: ") for line in err)
