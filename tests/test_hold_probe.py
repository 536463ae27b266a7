"""gcs_tools.evaluate.hold_probe: the held-acceleration statistic on inputs whose answer is known."""

import numpy as np
import pytest

from gcs_tools.evaluate.hold_probe import hold_density

DT = 0.005


def _velocity(a: np.ndarray) -> np.ndarray:
    return np.vstack([np.zeros(3), np.cumsum(a * DT, axis=0)])


def test_constant_jerk_gives_its_closed_form():
    """a_k = J k dt held over m ticks misses dv = J dt² m (m − 1) / 2 at every k."""
    jerk, m = np.array([0.5, -2.0, 3.0]), 8
    a = np.arange(400)[:, None] * DT * jerk
    dv = jerk * DT**2 * m * (m - 1) / 2.0
    expected = np.sqrt(3.0 * dv**2 / (m * DT) ** 3)
    np.testing.assert_allclose(hold_density(_velocity(a), DT, m), expected, rtol=1e-9)


def test_a_tick_random_walk_gives_its_density_times_the_discrete_factor():
    """A random walk of density σ² constant over each tick: E[dv²] = σ² dt³ (m − 1) m (2m − 1) / 6, so the
    statistic is σ² (m − 1)(2m − 1) / (2 m²) (0.82 σ² at m = 8; → σ² as the tick shrinks)."""
    sigma, m = np.array([1.0, 2.0, 0.5]), 8
    a = np.cumsum(np.random.default_rng(1).standard_normal((200_000, 3)) * sigma * np.sqrt(DT), axis=0)
    factor = (m - 1) * (2 * m - 1) / (2.0 * m * m)
    assert hold_density(_velocity(a), DT, m) ** 2 == pytest.approx(sigma**2 * factor, rel=0.05)
