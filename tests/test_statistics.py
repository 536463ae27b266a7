"""companion.domain.statistics: the one vocabulary of summary statistics (known answers)."""

import math

import numpy as np
import pytest

from companion.domain.statistics import STATISTICS, describe


def test_known_answers_on_finite_values():
    s = describe([4.0, 1.0, math.nan, 3.0, 2.0, math.inf], list(STATISTICS))
    assert s == {"n": 4, "mean": 2.5, "median": 2.5, "p95": pytest.approx(3.85), "p99": pytest.approx(3.97),
                 "iqr": 1.5, "rmse": math.sqrt(7.5), "min": 1.0, "max": 4.0}
    assert list(describe([1.0], ("max", "n"))) == ["max", "n"]  # the caller's order


def test_empty_sample_and_unknown_name():
    s = describe(np.array([math.nan]), ("n", "median", "p95"))
    assert s["n"] == 0 and math.isnan(s["median"]) and math.isnan(s["p95"])
    with pytest.raises(ValueError, match="p50"):
        describe([1.0], ("p50",))


def test_same_bits_as_the_forms_it_replaces():
    x = np.abs(np.random.default_rng(3).standard_t(3, 2001))
    p25, p50, p75, p95 = np.percentile(x, [25.0, 50.0, 75.0, 95.0])
    s = describe(x, ("median", "p95", "iqr", "rmse"))
    assert s == {"median": float(np.median(x)), "p95": float(p95), "iqr": float(p75 - p25),
                 "rmse": float(np.sqrt(np.mean(x**2)))}
