"""``companion.metrics``: online estimate-vs-reference errors and bounded distributions,
with known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.metrics import Distribution, PositionErrors, compare_series, error_statistics


def _ramp(t_us: int) -> np.ndarray:
    """Estimate moving north at 1 m/s and up at 0.5 m/s."""
    return np.array([t_us / 1e6, 0.0, -0.5 * t_us / 1e6])


def test_references_are_compared_with_the_interpolated_estimate() -> None:
    """Estimates every 100 ms; references between them, some arriving late (in the past),
    some early (ahead of the estimates): all compared with the linear interpolation."""
    m = PositionErrors()
    offset = np.array([0.3, -0.4, 0.0])  # reference = estimate - offset: error (0.3, -0.4, 0)
    refs = [(t, _ramp(t) - offset) for t in range(150_000, 2_000_000, 200_000)]
    est_times = list(range(100_000, 2_100_000, 100_000))
    for k, t in enumerate(est_times):
        m.add_estimate(t, _ramp(t))
        if k % 3 == 0:  # references delivered in bursts: past ones and one ahead
            while refs and refs[0][0] <= t + 120_000:
                m.add_reference(*refs.pop(0))
    for r in refs:
        m.add_reference(*r)
    err = m.errors_ned_m()
    assert err.shape == (10, 3)
    assert np.allclose(err, offset, atol=1e-6)  # float32 storage
    s = m.statistics()
    assert s["error_horizontal_m"]["median"] == pytest.approx(0.5, abs=1e-6)
    assert s["error_3d_m"]["max"] == pytest.approx(0.5, abs=1e-6) and s["unmatched"] == 0


def test_references_outside_the_estimates_are_not_compared() -> None:
    m = PositionErrors(window_us=1_000_000)
    m.add_reference(50_000, np.zeros(3))  # before the first estimate
    for t in range(100_000, 5_100_000, 100_000):
        m.add_estimate(t, _ramp(t))
    m.add_reference(1_000_000, _ramp(1_000_000))  # older than the window
    m.add_reference(4_950_000, _ramp(4_950_000))  # inside: error 0
    m.add_reference(9_000_000, np.zeros(3))  # after the last estimate
    s = m.statistics()
    assert s["n"] == 1 and s["unmatched"] == 3 and s["error_3d_m"]["max"] == pytest.approx(0, abs=1e-6)


def test_references_across_a_gap_in_the_estimates_are_not_compared() -> None:
    m = PositionErrors(max_gap_us=300_000)
    for t in (0, 100_000, 900_000, 1_000_000):
        m.add_estimate(t, _ramp(t))
    for t in (50_000, 500_000, 950_000):
        m.add_reference(t, _ramp(t))
    assert m.statistics()["n"] == 2 and m.unmatched == 1


def test_restart_keeps_the_errors_and_takes_a_new_time_base() -> None:
    m = PositionErrors()
    for t in (0, 100_000):
        m.add_estimate(t, _ramp(t))
    m.add_reference(50_000, _ramp(50_000) + [1.0, 0, 0])
    m.add_reference(500_000, np.zeros(3))  # pending when the log restarts: unmatched
    m.restart()
    for t in (0, 100_000):
        m.add_estimate(t, _ramp(t) + [0, 2.0, 0])
    m.add_reference(50_000, _ramp(50_000))
    assert np.allclose(m.errors_ned_m(), [[-1.0, 0, 0], [0, 2.0, 0]], atol=1e-6)
    assert m.statistics()["unmatched"] == 1
    with pytest.raises(ValueError, match="time order"):
        m.add_estimate(0, np.zeros(3))


def test_alignments() -> None:
    rng = np.random.default_rng(4)
    noise = rng.normal(0, 0.1, (400, 3))
    err = noise + [5.0, -3.0, 20.0]
    geo = error_statistics(err, "geodetic")
    mean = error_statistics(err, "mean_offset")
    vert = error_statistics(err, "vertical_mean_offset")
    assert geo["error_horizontal_m"]["median"] == pytest.approx(math.hypot(5, 3), abs=0.05)
    assert np.allclose(mean["offset_ned_m"], [5, -3, 20], atol=0.02) and mean["error_3d_m"]["median"] < 0.25
    assert vert["offset_ned_m"][:2] == [0.0, 0.0] and vert["offset_ned_m"][2] == pytest.approx(20, abs=0.02)
    assert vert["error_horizontal_m"] == geo["error_horizontal_m"]
    # 3-D norms of N(0, 0.1² I): median of a chi with 3 dof times 0.1 = 0.1538
    assert mean["error_3d_m"]["median"] == pytest.approx(0.1538, rel=0.08)
    with pytest.raises(ValueError):
        error_statistics(err, "best_fit")
    assert error_statistics(np.zeros((0, 3)))["error_3d_m"]["n"] == 0


def test_distribution_quantiles_within_half_a_bin() -> None:
    rng = np.random.default_rng(8)
    beta = rng.uniform(0, 1, 50_001)
    d = Distribution(0.0, 1.0, 10_000)
    for chunk in np.array_split(beta, 7):
        d.add(chunk)
    s = d.summary()
    assert s["n"] == beta.size and s["final"] == beta[-1]
    assert s["min"] == beta.min() and s["max"] == beta.max()
    assert s["mean"] == pytest.approx(beta.mean(), rel=1e-12)
    assert abs(s["median"] - np.median(beta)) <= 1e-4 and abs(s["p5"] - np.percentile(beta, 5)) <= 1e-4
    nis = rng.chisquare(2, 20_000)
    d = Distribution(1e-6, 1e6, 27_640, log=True)
    d.add(np.append(nis, [np.nan, np.inf]))  # non-finite values are not counted
    assert d.n == nis.size
    assert d.quantile(0.5) == pytest.approx(np.median(nis), rel=2e-3)
    assert Distribution(0, 1, 10).summary() == {"n": 0}


def test_batch_form_and_median_offset() -> None:
    """compare_series (what the live companion calls) = the online matcher; the median offset
    ignores a few outliers that pull the mean."""
    t = np.arange(0, 2_000_000, 50_000)
    p = np.array([_ramp(int(x)) for x in t])
    ref_t = np.arange(25_000, 1_900_000, 100_000)
    ref = np.array([_ramp(int(x)) for x in ref_t]) - [1.0, 2.0, 0.0]
    ref[:3] += 50.0  # three outliers
    ref[5] = np.nan  # not compared
    med = compare_series(t, p, ref_t, ref, "median_offset")
    mean = compare_series(t, p, ref_t, ref, "mean_offset")
    assert med["n"] == ref_t.size - 1 and med["unmatched"] == 1
    assert np.allclose(med["offset_ned_m"], [1.0, 2.0, 0.0], atol=1e-6)
    assert med["error_3d_m"]["median"] == pytest.approx(0.0, abs=1e-5)
    assert mean["error_3d_m"]["median"] > 5.0  # the mean is pulled by the outliers
    online = PositionErrors()
    for x, q in zip(t, p, strict=True):
        online.add_estimate(int(x), q)
    for x, r in zip(ref_t, ref, strict=True):
        if np.isfinite(r).all():
            online.add_reference(int(x), r)
    assert online.statistics("median_offset")["error_horizontal_m"] == med["error_horizontal_m"]


def test_coverage_of_the_reported_accuracy_known_answers():
    """Errors of known size against reported variances (σ_N² = 1, σ_E² = 4 m², interpolated between
    estimates like the position): NEES_h = e_N² + e_E²/4 counted inside 1 and 2 σ; no coverage block
    without ``coverage``, none counted where the variances are not finite."""
    m = PositionErrors(coverage=True)
    plain = PositionErrors()
    for t in range(0, 11):  # estimates at 0..10 s at the origin; the variances grow 1 → 3 (N), 4 → 12 (E)
        f = 1.0 + 2.0 * t / 10.0
        m.add_estimate(t * 1_000_000, (0.0, 0.0, 0.0), (f, 4.0 * f))
        plain.add_estimate(t * 1_000_000, (0.0, 0.0, 0.0), (f, 4.0 * f))
    # NEES at t = 0 s: 0.9² = 0.81 (in 1 σ); t = 1 s (σ² 1.2, 4.8): 3² / 4.8 = 1.875 (in 2 σ);
    # t = 2.5 s (σ² 1.5, 6): 3² / 6 = 1.5 (in 2 σ); t = 5 s (σ² 2, 8): 3² / 2 = 4.5 (outside)
    for t_s, e in ((0.0, (0.9, 0.0)), (1.0, (0.0, 3.0)), (2.5, (0.0, 3.0)), (5.0, (3.0, 0.0))):
        m.add_reference(int(t_s * 1e6), (-e[0], -e[1], 0.0))
    cov = m.statistics()["coverage_horizontal"]
    assert cov["n"] == 4 and cov["within_1_sigma"] == 0.25 and cov["within_2_sigma"] == 0.75
    assert "coverage_horizontal" not in plain.statistics()
    m2 = PositionErrors(coverage=True)
    m2.add_estimate(0, (0.0, 0.0, 0.0))  # no variances given: matched, not counted
    m2.add_reference(0, (1.0, 0.0, 0.0))
    assert m2.statistics()["coverage_horizontal"]["n"] == 0 and m2.matched == 1


def test_vertical_coverage_of_the_reported_accuracy_known_answers():
    """The vertical error against the reported σ_D² (4 m², interpolated like the position): |e_D| ≤ σ_D
    and ≤ 2 σ_D counted; none counted without a vertical variance (two given) or where it is not finite."""
    m = PositionErrors(coverage=True)
    for t in range(0, 11):  # σ_D² 4 → 12 m² over 10 s
        m.add_estimate(t * 1_000_000, (0.0, 0.0, 0.0), (1.0, 1.0, 4.0 * (1.0 + 2.0 * t / 10.0)))
    # t = 0: |1.9| ≤ 2 (1 σ); t = 1 s (σ_D² 4.8, σ 2.19): 3 (2 σ); t = 5 s (σ_D² 8, σ 2.83): 6 (outside)
    for t_s, d in ((0.0, 1.9), (1.0, 3.0), (5.0, -6.0)):
        m.add_reference(int(t_s * 1e6), (0.0, 0.0, -d))
    cov = m.statistics()["coverage_vertical"]
    assert cov["n"] == 3 and cov["within_1_sigma"] == 1 / 3 and cov["within_2_sigma"] == 2 / 3
    m2 = PositionErrors(coverage=True)
    m2.add_estimate(0, (0.0, 0.0, 0.0), (1.0, 1.0))  # horizontal only: counted horizontally alone
    m2.add_estimate(1_000_000, (0.0, 0.0, 0.0), (1.0, 1.0, math.nan))
    m2.add_reference(0, (1.0, 0.0, 0.0))
    m2.add_reference(1_000_000, (1.0, 0.0, 0.0))
    s = m2.statistics()
    assert s["coverage_horizontal"]["n"] == 2 and s["coverage_vertical"]["n"] == 0
