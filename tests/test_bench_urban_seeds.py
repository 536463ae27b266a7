"""``python -m gcs_tools.bench.urban_seeds`` (the urban-like receiver without a velocity over several
seeds, against the bias-only and 1 s low-pass references) and the ``bench robustness`` helpers it
shares: the white-noise scale of ``urban_like``, ``without_velocity``, ``distances_to_clean``."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from companion.domain.samples import GnssFix
from gcs_tools.bench import robustness as rb
from gcs_tools.bench import urban_seeds as us


@pytest.fixture(scope="module")
def log() -> rb.Log:
    return rb.load()


def _errors(log: rb.Log, received: rb.Log) -> np.ndarray:
    """Each fix's horizontal error (NED, m) against the clean fix of the same validity."""
    t, p = rb.clean_track(received)
    tc, pc = rb.clean_track(log)
    assert np.array_equal(t, tc)
    return p[:, :2] - pc[:, :2]


def test_white_scale_zero_leaves_the_same_seeds_correlated_error(log):
    """urban_like(seed, white_scale=0) is the seed's Gauss-Markov error alone: the difference to the
    full error is white noise of 3 m per horizontal axis, the error alone is correlated fix to fix
    (10 s at 5 Hz: e^(-0.02) ≈ 0.98), and the default scale is the bench's receiver exactly."""
    full, bias = _errors(log, rb.urban_like(log, 3)), _errors(log, rb.urban_like(log, 3, white_scale=0.0))
    white = full - bias
    assert white.shape[0] > 500
    for axis in range(2):
        w, b = white[:, axis], bias[:, axis]
        assert 2.7 < w.std() < 3.3
        assert abs(np.corrcoef(w[1:], w[:-1])[0, 1]) < 0.15
        assert np.corrcoef(b[1:], b[:-1])[0, 1] > 0.95
    assert np.array_equal(_errors(log, rb.urban_like(log, 3, white_scale=1.0)), full)


def test_ema_known_answers():
    t = np.arange(5) * 0.5
    step = np.array([[0.0], [1.0], [1.0], [1.0], [1.0]])
    out = us.ema(t, step, 1.0)
    w = 1.0 - math.exp(-0.5)
    assert out[0, 0] == 0.0 and out[1, 0] == pytest.approx(w)
    assert out[4, 0] == pytest.approx(1.0 - (1.0 - w) ** 4)
    assert np.allclose(us.ema(t, step, 1e-6), step)  # a vanishing time constant passes the input
    const = np.full((5, 2), 7.0)
    assert np.array_equal(us.ema(t, const, 1.0), const)


def test_seed_zero_at_5_hz_is_the_bench_receiver(log):
    """Seed 0 at 5 Hz is `bench robustness`'s "urban-like 5 Hz, no accuracy" case without the
    receiver's velocity: the same p95 and max, for the estimate and the raw fixes."""
    clean = rb.clean_track(log)
    case = us.seed_case(log, clean, 0, 1, ["naive"])
    bench = rb.receiver_case(rb.receivers(log)["urban-like 5 Hz, no accuracy"], clean, "u", "naive", False)
    raw = bench["raw_fixes_distance_to_clean_m"]
    assert case["raw_p95_m"] == pytest.approx(raw["p95"], rel=1e-12)
    est = bench["distance_to_clean_m"]
    assert case["rows"]["naive"]["p95"] == pytest.approx(est["p95"] / raw["p95"], rel=1e-12)
    assert case["rows"]["naive"]["max"] == pytest.approx(est["max"] / raw["max"], rel=1e-12)
    # without the white noise the fixes are closer to the clean track (3 m per axis under an 8 m error)
    assert case["rows"]["bias-only"]["p95"] < 1.0 and case["rows"]["bias-only"]["median"] < 1.0


def test_without_velocity_drops_only_the_velocity(log):
    out = rb.without_velocity(log)
    fixes = [s for s in out.samples if type(s) is GnssFix]
    before = [s for s in log.samples if type(s) is GnssFix]
    assert len(fixes) == len(before) and len(out.samples) == len(log.samples)
    assert all(f.v_ned_m_s is None for f in fixes) and any(f.v_ned_m_s is not None for f in before)
    assert [(f.lat_deg, f.lon_deg, f.t_validity_us) for f in fixes] == \
        [(f.lat_deg, f.lon_deg, f.t_validity_us) for f in before]


def test_cli_json_and_errors(capsys):
    assert us.main(["--seeds", "1", "--methods", "naive", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out["summary"]) == {f"{r} Hz, {row}" for r in (5, 1) for row in ("naive", *us.REFERENCES)}
    assert [c["rate_hz"] for c in out["cases"]] == [5.0, 1.0]
    assert all(s["seeds"] == 1 and s["seeds_ok"] in (0, 1) for s in out["summary"].values())
    assert us.main(["--methods", "nonsense"]) == 2
    assert "urban_seeds: error: --methods" in capsys.readouterr().err
    assert us.main(["--set", "estimator.no_such_field=1"]) == 2
    with pytest.raises(SystemExit):
        us.main(["--seeds", "0"])
