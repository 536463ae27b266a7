"""The tight filter's reported accuracy: its position covariance inflated by its own measured
consistency (``engine.Fit``), known answers and the two synthetic cases (clean, one biased satellite)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.estimator.consistency import Fit
from companion.tight import TightConfig
from companion.tight.engine import TightEngine
from tests.test_tight import FRAME, _synthetic_epochs


def test_fit_known_answers():
    dt_s, window_s, c = 0.2, 10.0, 0.7
    a = math.exp(-dt_s / window_s)
    fit = Fit()
    for k in range(30):  # satellite 7 always ν = c; satellite 9 only in the first epoch, ν = 2
        key = np.array([7, 9]) if k == 0 else np.array([7])
        nu = np.array([c, 2.0]) if k == 0 else np.array([c])
        fit = fit.add(round(1e6 + k * dt_s * 1e6), key, nu, window_s)
    w = a ** np.arange(30)
    num = (c * w.sum()) ** 2 + (2.0 * w[-1]) ** 2
    den = (w**2).sum() + w[-1] ** 2
    assert fit.inflation() == pytest.approx(num / den, rel=1e-12)
    assert list(fit.key) == [7, 9]
    # a satellite long gone is forgotten; the window 0 keeps the last epoch alone
    fit = fit.add(round(1e6 + 200 * dt_s * 1e6), np.array([7]), np.array([c]), window_s)
    assert list(fit.key) == [7]
    assert Fit().add(0, np.array([1, 2]), np.array([3.0, 0.0]), 0.0).add(
        200_000, np.array([1, 2]), np.array([0.5, 0.5]), 0.0).inflation() == 1.0
    assert Fit().add(0, np.array([1, 2]), np.array([3.0, 1.0]), 0.0).inflation() == pytest.approx(5.0)
    assert Fit().inflation() == 1.0
    # the same satellites in another order (the general path) == in the stored order (the fast path)
    key, nu = np.array([3, 5, 8]), np.array([0.3, -1.0, 2.0])
    a = Fit().add(0, key, nu, window_s).add(200_000, key, 2 * nu, window_s)
    b = Fit().add(0, key, nu, window_s).add(200_000, key[::-1], 2 * nu[::-1], window_s)
    assert a.inflation() == pytest.approx(b.inflation(), rel=1e-12) and list(b.key) == [3, 5, 8]
    # ... exactly, through the permutation path, and equal to the general one (a channel added)
    e = math.exp(-0.2 / window_s)
    for later in (b.add(400_000, key[[1, 2, 0]], nu[[1, 2, 0]], window_s),
                  b.add(400_000, np.array([5, 8, 3, 11]), np.array([nu[1], nu[2], nu[0], 0.0]), window_s)):
        np.testing.assert_array_equal(later.key[:3], key)
        np.testing.assert_array_equal(later.nu_sum[:3], e * (e * nu + 2 * nu) + nu)
        np.testing.assert_array_equal(later.w2_sum[:3], (e * e) * ((e * e) * 1.0 + 1.0) + 1.0)


def _run(bias_m: float | None, runs: int = 12, n: int = 100) -> dict[str, np.ndarray]:
    """Horizontal NEES (P alone, reported) and the inflation of every epoch after the first 10 s."""
    cfg = TightConfig.for_ground_vehicle(sigma_clock0_m=1e3)
    rng = np.random.default_rng(11)
    out: dict[str, list[float]] = {"nees_p": [], "nees_reported": [], "inflation": []}
    for _ in range(runs):
        epochs, truth = _synthetic_epochs(rng, cfg, n, bias=None if bias_m is None else {0: (bias_m, 0)})
        eng = TightEngine(cfg, "naive", frame=FRAME)  # fixed weights: the bias is not caught
        for k in range(n):
            t_us = 1_000_000 + 200_000 * k
            eng.push_acc(t_us, 0.0, 0.0, 0.0)
            eng.push_epoch(t_us, epochs[k])
            if k >= 50:
                e = eng.entries[-1]
                d = (e.x - truth[k])[0:2]
                nees = float(d @ np.linalg.solve(e.P[0:2, 0:2], d))
                out["nees_p"].append(nees)
                out["nees_reported"].append(nees / e.fit.inflation())
                out["inflation"].append(e.fit.inflation())
    return {k: np.asarray(v) for k, v in out.items()}


def test_reported_accuracy_stays_with_clean_satellites_and_covers_a_biased_one():
    """Clean pseudoranges (the filter's own model): the inflation stays near 1 and the reported
    covariance covers the error as P does (2-D Gaussian: 39 % inside 1 σ, 86 % inside 2 σ). One
    satellite biased by 15 m (3 σ, inside the gate, fixed weights): P alone covers the error in well
    under half the epochs, the reported accuracy in at least the nominal 86 % (conservatively: the
    factor is global, the bias moves the position through one satellite only)."""
    clean = _run(None)
    assert np.median(clean["inflation"]) < 1.15 and np.mean(clean["inflation"]) < 1.4
    for key in ("nees_p", "nees_reported"):
        assert 0.3 < np.mean(clean[key] <= 1.0) < 0.55 and 0.8 < np.mean(clean[key] <= 4.0) < 0.97
    biased = _run(15.0)
    assert np.mean(biased["nees_p"] <= 4.0) < 0.5
    assert np.mean(biased["nees_reported"] <= 4.0) >= 0.865 and np.median(biased["inflation"]) > 5.0


def test_accuracy_window_zero_reports_p_and_a_bad_window_is_a_config_error():
    from companion.domain.samples import AttitudeSample, ImuSample
    from companion.errors import ConfigError
    from companion.tight import RawGnss, TightNavigator
    from tests.gnss_helpers import RX_ECEF, T0, observe
    from tests.test_tight import STORE

    rng = np.random.default_rng(2)
    navs = [TightNavigator(TightConfig(accuracy_window_s=w), "naive", ephemerides=STORE) for w in (0.0, 10.0)]
    for k in range(100):  # 2 s at 50 Hz, an epoch per 0.2 s with one pseudorange 20 m long
        t_us = 1_000_000 + 20_000 * k
        for nav in navs:
            nav.push(AttitudeSample(t_us, np.array([1.0, 0.0, 0.0, 0.0])))
            nav.push(ImuSample(t_us, np.array([0.0, 0.0, -9.80665]), np.zeros(3)))
        if k % 10 == 0:
            ep, _ = observe(STORE, T0 + k * 0.02, RX_ECEF)
            z = ep.pseudorange_m + rng.normal(0.0, 1.0, ep.n)
            z[0] += 20.0
            for nav in navs:
                nav.push(RawGnss(t_us, ep.replace(pseudorange_m=z)))
    off, on = (nav.estimate() for nav in navs)
    assert off is not None and on is not None and navs[0].accuracy_inflation() == 1.0
    k = navs[1].accuracy_inflation()
    np.testing.assert_allclose(off.cov_diag[3:], on.cov_diag[3:], rtol=1e-9)  # velocities: P
    assert (on.cov_diag[0:3] >= off.cov_diag[0:3] * k * (1 - 1e-12)).all()  # positions: at least k P
    np.testing.assert_array_equal(off.cov_diag[0:3], navs[0].engine.output_now()[1][9:12])  # window 0: P
    assert navs[1].accuracy_inflation() > 2.0
    for bad in (-1.0, math.nan, math.inf):
        with pytest.raises(ConfigError, match="accuracy_window_s"):
            TightNavigator(TightConfig(accuracy_window_s=bad))
