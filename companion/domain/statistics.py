"""Summary statistics of a sample: one vocabulary (names and definitions) for every report.

Like evo's ``StatisticsType``, each name means one thing wherever it appears: flight summaries
(``estimation_error_m``, ``tracking_error_m``), replay and live-companion error statistics
(``companion.metrics``), campaign tables (``gcs_tools.evaluate.stats.summarize``), delays and
latencies (``command_delay_ms``, ``gnss_to_odometry_latency_ms``). A report picks the names it
shows; the unit goes in the name of the block (``..._m``, ``..._ms``), not in the statistic's.

``n``       number of finite values (non-finite values are dropped before anything else)
``mean``    arithmetic mean
``median``  ``np.median``
``p95``     95th percentile, linear interpolation (numpy's default); ``p99`` likewise
``iqr``     interquartile range p75 − p25 (linear interpolation)
``rmse``    root mean square, ``sqrt(mean(x²))`` (of errors: their RMS)
``min`` / ``max``

An empty sample gives ``n = 0`` and NaN for every other statistic.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

STATISTICS: dict[str, Callable[[np.ndarray], float]] = {
    "n": lambda a: a.size,
    "mean": lambda a: float(np.mean(a)),
    "median": lambda a: float(np.median(a)),
    "p95": lambda a: float(np.percentile(a, 95.0)),
    "p99": lambda a: float(np.percentile(a, 99.0)),
    "iqr": lambda a: float(np.percentile(a, 75.0) - np.percentile(a, 25.0)),
    "rmse": lambda a: float(np.sqrt(np.mean(a * a))),
    "min": lambda a: float(a.min()),
    "max": lambda a: float(a.max()),
}
ERROR_STATISTICS = ("median", "p95", "rmse")  # a flight's estimation / tracking error (summary.json)
LATENCY_STATISTICS = ("n", "median", "p99", "max")  # process delays and jitter (estimator.json, vehicle.json)


def finite(x: np.ndarray | Sequence[float]) -> np.ndarray:
    """The finite values of ``x``, flattened, as float64."""
    a = np.asarray(x, dtype=float).ravel()
    return a[np.isfinite(a)]


def describe(x: np.ndarray | Sequence[float], names: Sequence[str] = ERROR_STATISTICS,
             ) -> dict[str, float]:
    """``{name: statistic}`` of the finite values of ``x`` for each of ``names`` (in that order)."""
    unknown = [name for name in names if name not in STATISTICS]
    if unknown:
        raise ValueError(f"unknown statistics {unknown}; known: {', '.join(STATISTICS)}")
    a = finite(x)
    if a.size == 0:
        return {name: 0 if name == "n" else math.nan for name in names}
    return {name: STATISTICS[name](a) for name in names}
