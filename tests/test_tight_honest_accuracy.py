"""The tight filter's reported accuracy floored by its own epochs' snapshot positions
(``snapshot.epoch_fix`` into ``consistency.Scatter``, horizontal and vertical; docs/tight.md "Reported
accuracy"): known answers, coverage of a correlated error of known variance, no inflation on white
errors, a report only (the estimate bit-identical), exact out of sequence."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.estimator.consistency import (
    Scatter,
    Scatter1,
    snapshot_axis,
    snapshot_parts,
    white_and_slow,
)
from companion.tight import TightConfig, TightNavigator, _tight
from companion.tight import engine as tight_engine
from companion.tight.model import I_CLK, pseudorange, range_rate
from companion.tight.snapshot import delay_bias, epoch_fix, epoch_velocity
from tests.test_tight import FRAME, _feed, _synthetic_epochs

PERIOD_US = 200_000


def test_epoch_fix_is_the_weighted_least_squares_position_known_answer():
    """Innovations y = G δ exactly (position N, E, D and two clocks): δ's position part back to 1e-9, its
    variances diag((Gᵀ W G)⁻¹) (W = 1/r); without a redundant satellite: None."""
    rng = np.random.default_rng(1)
    m = 9
    los = rng.normal(size=(m, 3))
    los[:, 2] = -np.abs(los[:, 2]) - 0.3  # above the horizon
    los /= np.linalg.norm(los, axis=1)[:, None]
    slot = np.array([0, 0, 0, 0, 0, 2, 2, 2, 2])
    H = np.zeros((m, I_CLK + 4))
    H[:, 0:3] = -los
    H[np.arange(m), I_CLK + slot] = 1.0
    delta = np.array([3.0, -2.0, 5.0])
    clocks = {0: 40.0, 2: -7.0}
    y = -los @ delta + np.array([clocks[int(s)] for s in slot])
    r = rng.uniform(1.0, 9.0, m)
    got = epoch_fix(H, y, r, slot)
    assert got is not None
    np.testing.assert_allclose(got[0], delta, rtol=0, atol=1e-9)
    G = np.column_stack([-los, slot == 0, slot == 2]).astype(float)
    want = np.diag(np.linalg.inv(G.T @ (G / r[:, None])))[0:3]
    np.testing.assert_allclose(got[1], want, rtol=1e-12)
    few = [0, 1, 2, 3, 5]  # 5 satellites on two clocks: 5 unknowns, none redundant
    assert epoch_fix(H[few], y[few], r[few], slot[few]) is None
    assert epoch_fix(H[:5], y[:5], r[:5], slot[:5]) is not None  # 5 on one clock: one redundant


def test_the_c_snapshot_equals_the_numpy_reference():
    """``_tight.snapshot`` (the engine's, in C) == ``snapshot.epoch_fix`` + the prediction,
    ``snapshot.epoch_velocity`` at that position and ``snapshot.delay_bias``, over the used satellites (to
    1e-9), on a synthetic epoch with Doppler; None without a redundant satellite; the velocity NaN with
    fewer than 5 rates."""
    cfg = TightConfig.for_ground_vehicle()
    rng = np.random.default_rng(3)
    epochs, truth = _synthetic_epochs(rng, cfg, 1)
    e = _with_doppler(rng, truth[0], epochs[0])
    x = truth[0] + np.r_[rng.normal(0.0, 20.0, 3), np.zeros(len(truth[0]) - 3)]  # a prediction 20 m off
    y, H, _, _, _ = _tight.innovations(x, np.eye(len(x)), FRAME.r0_ecef_m, FRAME.c_ecef_ned, e.sat_pos_ecef_m,
                                       e.slot_f, e.z_m)
    r = rng.uniform(4.0, 40.0, len(y))
    used = np.ones(len(y), dtype=bool)
    used[[1, 4]] = False
    u = np.flatnonzero(used)
    rr = rng.uniform(0.01, 0.05, len(y))
    got = _tight.snapshot(H, y, r, used.astype(float), x[0:3], e.sat_pos_ecef_m, e.sat_vel_ecef_m_s,
                          e.z_rate_m_s, rr, FRAME.r0_ecef_m, FRAME.c_ecef_ned)
    fix = epoch_fix(H[u], y[u], r[u], e.slot[u])
    assert got is not None and fix is not None
    p = x[0:3] + fix[0]
    v = epoch_velocity(e.sat_pos_ecef_m[u], e.sat_vel_ecef_m_s[u], FRAME.ecef(p), FRAME.c_ecef_ned,
                       e.z_rate_m_s[u], rr[u])
    b = delay_bias(H[u], r[u], e.slot[u])
    assert v is not None and b is not None and np.abs(b).max() > 0.1
    np.testing.assert_allclose(got, np.r_[p, fix[1], v, b], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(v, truth[0][3:6], atol=0.5)  # the true velocity, to its noise
    rate = e.z_rate_m_s.copy()
    rate[u[4:]] = np.nan  # 4 rates left
    few = _tight.snapshot(H, y, r, used.astype(float), x[0:3], e.sat_pos_ecef_m, e.sat_vel_ecef_m_s, rate, rr,
                          FRAME.r0_ecef_m, FRAME.c_ecef_ned)
    assert few is not None and np.isnan(few[6:9]).all() and np.array_equal(few[0:6], got[0:6])
    assert np.array_equal(few[9:12], got[9:12])
    one = np.flatnonzero(e.slot == e.slot[0])  # one clock: 4 unknowns
    assert len(one) >= 5
    for n, redundant in ((4, False), (5, True)):
        only = np.zeros(len(y))
        only[one[:n]] = 1.0
        got = _tight.snapshot(H, y, r, only, x[0:3], e.sat_pos_ecef_m, e.sat_vel_ecef_m_s, e.z_rate_m_s, rr,
                              FRAME.r0_ecef_m, FRAME.c_ecef_ned)
        assert (got is not None) == redundant


@pytest.mark.parametrize("tau_s", [0.0, 3.0])
def test_vertical_scatter_and_correlation_are_known_answers(tau_s):
    """One axis (the vertical, given as two equal axes) climbing at 1 m/s whose rate is known, errors
    N(0, 0.5²) white or Gauss-Markov (τ = 3 s): scatter 0.25 m², correlation (1 + ρ)/(1 − ρ),
    ρ = e^(−0.2/τ) (1; 30.0), the medians over 200 independent 60 s streams within 20 % (the scatter) and
    30 % (the correlation: one axis has half the horizontal's independent samples, and c = r / (2 − r) of
    the ratio r = 1 + ρ magnifies its noise near r = 2, so the median of c falls below c; the horizontal's
    test holds it to 20 %)."""
    rng = np.random.default_rng(5)
    n = 300
    rho = math.exp(-PERIOD_US * 1e-6 / tau_s) if tau_s > 0.0 else 0.0
    var, cor = [], []
    for _ in range(200):
        s, e = Scatter(), 0.5 * rng.standard_normal()
        for i in range(n):
            if i:
                e = rho * e + math.sqrt(1.0 - rho * rho) * 0.5 * rng.standard_normal()
            d = -1.0 * i * PERIOD_US * 1e-6 + e
            s = s.add(i * PERIOD_US, (d, d), (-1.0, -1.0), 20.0)  # one axis: given twice
        var.append(s.variance())
        cor.append(s.correlation())
    assert np.median(var) == pytest.approx(0.25, rel=0.2)
    assert np.median(cor) == pytest.approx((1.0 + rho) / (1.0 - rho), rel=0.3)


def _gauss_markov(rng: np.random.Generator, n: int, m: int, sigma: float, tau_s: float) -> np.ndarray:
    """(n, m): m independent Gauss-Markov series of std ``sigma`` and correlation time ``tau_s`` at 5 Hz."""
    rho = math.exp(-PERIOD_US * 1e-6 / tau_s)
    e = np.empty((n, m))
    e[0] = sigma * rng.standard_normal(m)
    for i in range(1, n):
        e[i] = rho * e[i - 1] + math.sqrt(1.0 - rho * rho) * sigma * rng.standard_normal(m)
    return e


def _h_pos(x: np.ndarray, e: tight_engine.SatEpoch) -> np.ndarray:
    """(m, 3): the pseudoranges' derivative by the position (N, E, D) at the state ``x``."""
    return pseudorange(x, FRAME, e.sat_pos_ecef_m, e.slot)[1][:, 0:3]


def _with_doppler(rng: np.random.Generator, x: np.ndarray, e: tight_engine.SatEpoch) -> tight_engine.SatEpoch:
    """The epoch with its (resting) satellites' exact pseudorange rates at the true state + 0.1 m/s white."""
    vel = np.zeros_like(e.sat_pos_ecef_m)
    rate = range_rate(x, FRAME, e.sat_pos_ecef_m, vel)[0] + rng.normal(0.0, 0.1, len(e.z_m))
    return e._replace(sat_vel_ecef_m_s=vel, z_rate_m_s=rate, r_rate_m2_s2=np.full(len(e.z_m), 0.01))


def _common_mode_epochs(rng: np.random.Generator, cfg: TightConfig, n: int, sigma_gm: float,
                        sigma_white: float, tau_s: float
                        ) -> tuple[list[tight_engine.SatEpoch], list[np.ndarray]]:
    """``n`` epochs (and true states) with white errors of ``sigma_white``, the satellites agreeing on a
    position off by a Gauss-Markov b(t) (``sigma_gm`` per axis, ``tau_s``), Doppler (``_with_doppler``);
    prepared with ``cfg``'s σ."""
    epochs, truth = _synthetic_epochs(rng, TightConfig.for_ground_vehicle(sigma_uniform_m=sigma_white), n)
    ref = _synthetic_epochs(np.random.default_rng(0), cfg, 1)[0][0]  # the filter's σ: its own variances
    b = _gauss_markov(rng, n, 3, sigma_gm, tau_s) if sigma_gm > 0.0 else np.zeros((n, 3))
    return [_with_doppler(rng, truth[k], e._replace(z_m=e.z_m + _h_pos(truth[k], e) @ b[k],
                                                    r_uniform_m2=ref.r_uniform_m2))
            for k, e in enumerate(epochs)], truth


def _coverage(sigma_gm: float, sigma_white: float = 5.0, sigma_filter: float = 5.0, tau_s: float = 2.0,
              runs: int = 10, n: int = 250, skip: int = 100) -> dict[str, np.ndarray]:
    """Fixed weights (σ_uniform = ``sigma_filter``) on pseudoranges with white errors of ``sigma_white``
    whose satellites also agree on a position off by a Gauss-Markov error b(t) (``sigma_gm`` per axis, τ =
    ``tau_s``; 0 and the same σ: the filter's own model): z += H_p b, the error a reflection-rich street
    puts on every satellite's solution alike, which the filter follows (its innovations stay white); exact
    pseudorange rates + 0.1 m/s white (the receiver's Doppler, fused too). Per epoch after ``skip``: the
    horizontal NEES and the vertical one against P × k and against the reported variance, and the reported
    over k P."""
    cfg = TightConfig.for_ground_vehicle(sigma_clock0_m=1e3, sigma_uniform_m=sigma_filter)
    rng = np.random.default_rng(17)
    out: dict[str, list[float]] = {"h_kp": [], "h_rep": [], "v_kp": [], "v_rep": [], "ratio": [], "h_old": []}
    for _ in range(runs):
        epochs, truth = _common_mode_epochs(rng, cfg, n, sigma_gm, sigma_white, tau_s)
        nav = TightNavigator(cfg, "naive")
        eng = nav.engine
        eng.frame = FRAME
        for k in range(n):
            t_us = 1_000_000 + PERIOD_US * k
            eng.push_acc(t_us, 0.0, 0.0, 0.0)
            eng.push_epoch(t_us, epochs[k])
            if k < skip:
                continue
            est = nav.estimate()
            assert est is not None
            kk = nav.accuracy_inflation()
            e = eng.entries[-1]
            d = np.asarray(est.p_ned_m) - truth[k][0:3]
            p = np.diag(e.P)[0:3]  # the estimate is the last entry's (the IMU's time is the epoch's)
            rep = np.asarray(est.cov_diag[0:3])
            out["h_kp"].append(float(d[0] ** 2 / (kk * p[0]) + d[1] ** 2 / (kk * p[1])))
            out["h_rep"].append(float(d[0] ** 2 / rep[0] + d[1] ** 2 / rep[1]))
            out["v_kp"].append(float(d[2] ** 2 / (kk * p[2])))
            out["v_rep"].append(float(d[2] ** 2 / rep[2]))
            out["ratio"].extend((rep / (kk * p)).tolist())
            old = (_old_rule(p[0], kk, e), _old_rule(p[1], kk, e))
            out["h_old"].append(float(d[0] ** 2 / old[0] + d[1] ** 2 / old[1]))
    return {k: np.asarray(v) for k, v in out.items()}


def _old_rule(p: float, k: float, e: tight_engine.Entry) -> float:
    """The horizontal floor before the white/slow split: max(k P, min(c max(1, s²/r) P, max(s², r))), c from
    the squared changes over one and two snapshots alone (``Scatter.correlation``)."""
    c, s2 = e.scatter_h.statistics()
    r = e.fix_var_m2[0]
    return max(k * p, min(c * max(1.0, s2 / r) * p, max(s2, r)))


def test_white_and_slow_known_answers():
    """σ_w², σ_s², ρ back exactly from the moments of white + Gauss-Markov (δ1 = σ_w² + σ_s²(1 − ρ),
    δ2 = σ_w² + σ_s²(1 − ρ²), s² = σ_w² + σ_s²), and the edges: no slow part (white alone), no decay over
    two epochs (ρ = 1)."""
    for w, s, rho in ((1.0, 9.0, 0.96), (0.0, 4.0, 0.5), (3.0, 0.5, 0.2)):
        got = white_and_slow(w + s, w + s * (1 - rho), w + s * (1 - rho * rho))
        np.testing.assert_allclose(got, (w, s, rho), rtol=1e-12, atol=1e-12)
    assert white_and_slow(2.0, 2.0, 2.0) == (2.0, 0.0, 0.0)  # δ1 = s²: white
    assert white_and_slow(2.0, 1.0, 2.5) == (2.0, 0.0, 0.0)  # δ2 ≥ s²: white
    assert white_and_slow(5.0, 1.0, 0.8) == (1.0, 4.0, 1.0)  # δ2 ≤ δ1: no decay


def test_a_slow_error_under_white_noise_is_seen():
    """Snapshots with white N(0, 1) and a Gauss-Markov error of σ 3 m, τ 5 s (ρ = e^(−0.04) per 0.2 s)
    through ``Scatter`` (the window 20 s): the two-lag correlation alone (the old rule's c) sees a white part
    comparable to the slow one's step and misses the correlation ((1 + ρ)/(1 − ρ) = 49; its median is below
    10), while the white/slow split gives ρ, σ_s² and σ_w² (medians over 100 streams within 0.03, 35 % and
    50 %: the window's scatter sees part of a slow error's variance)."""
    rng = np.random.default_rng(9)
    rho = math.exp(-0.2 / 5.0)
    c_old, got = [], []
    for _ in range(100):
        sc, g = Scatter1(), 3.0 * rng.standard_normal()
        for i in range(400):
            g = rho * g + math.sqrt(1.0 - rho * rho) * 3.0 * rng.standard_normal()
            sc = sc.add(i * PERIOD_US, 2.0 * i * PERIOD_US * 1e-6 + g + rng.standard_normal(), 2.0, 20.0)
        c_old.append(sc.correlation())
        d = 0.25 / sc.d_w_sum
        got.append(white_and_slow(sc.variance(), sc.d1_sum * d, sc.d2_sum * d))
    w, s, r = np.median(np.array(got), axis=0)
    assert np.median(c_old) < 10.0, np.median(c_old)
    assert abs(r - rho) < 0.03 and s == pytest.approx(9.0, rel=0.35) and w == pytest.approx(1.0, rel=0.5)


def test_a_slow_error_under_white_noise_is_covered_better():
    """The filter told 1 m per pseudorange, white 1 m and every satellite agreeing on a Gauss-Markov error
    (3 m, τ 5 s) that the filter follows: P × k covers almost nothing, the old floor (c from two lags) too
    little, the white/slow split much more, without covering more than a Gaussian (2 σ: 86.5 %). Still short
    (measured 21 / 55 %): the window's scatter sees part of a 5 s error's variance."""
    c = _coverage(3.0, sigma_white=1.0, sigma_filter=1.0, tau_s=5.0, runs=6)
    kp, old, new = (np.mean(c[k] <= 4.0) for k in ("h_kp", "h_old", "h_rep"))
    assert kp < 0.2 and old < 0.4 and new > old + 0.15 and new < 0.9, (kp, old, new)


def test_a_correlated_error_of_known_variance_is_covered():
    """Every satellite agreeing on a position off by a Gauss-Markov error (σ 3 m per axis, τ 2 s: 10
    epochs), the filter told 4 m per pseudorange (about the error's size) and white 0.1 m: the filter
    averages the epochs as independent and follows the error, so P × k misses it (2 σ: below 40 %); the
    reported accuracy covers it as a Gaussian would within the bounds of ~10 × 150 epochs correlated over
    ~10 (~150 independent errors: ±4 σ of 39 / 86 % is ±16 / ±11 points; 1-D 68 / 95 %)."""
    c = _coverage(3.0, sigma_white=0.1, sigma_filter=4.0, tau_s=2.0)
    assert np.mean(c["h_kp"] <= 4.0) < 0.4, np.mean(c["h_kp"] <= 4.0)  # before: short
    r1, r2 = np.mean(c["h_rep"] <= 1.0), np.mean(c["h_rep"] <= 4.0)
    v1, v2 = np.mean(c["v_rep"] <= 1.0), np.mean(c["v_rep"] <= 4.0)
    assert 0.23 < r1 < 0.55 and 0.75 < r2 <= 0.97, (r1, r2)
    assert 0.52 < v1 < 0.95 and v2 > 0.9, (v1, v2)
    assert np.mean(c["v_kp"] <= 4.0) < v2 - 0.1


def test_white_consistent_errors_are_not_inflated():
    """The filter's own model (white pseudoranges of the σ it assumes): the reported accuracy stays about
    P × k (its median ratio below 1.3) and covers as a consistent Gaussian does: 2-D 39.3 / 86.5 % and
    1-D 68.3 / 95.4 % within ±4 binomial standard errors of 1,500 epochs (correlated over a few epochs:
    ±4 σ of the independent count is about ±2 of the effective one)."""
    c = _coverage(0.0)
    r = c["ratio"]
    assert np.median(r) < 1.3 and r.min() >= 1.0 - 1e-12, np.quantile(r, (0.5, 0.9))
    n = len(c["h_rep"])
    for nees, dof_p in ((c["h_rep"], (0.393, 0.865)), (c["v_rep"], (0.683, 0.954))):
        for bound, p in zip((1.0, 4.0), dof_p, strict=True):
            tol = 4.0 * math.sqrt(p * (1 - p) / n) * 2.0
            assert abs(np.mean(nees <= bound) - p) < tol, (np.mean(nees <= bound), p, tol)


def test_the_floor_is_a_report_the_estimate_is_bit_identical(monkeypatch):
    """With and without the snapshots (``_tight.snapshot`` returning None: no floor) every entry's state and
    covariance are equal bit for bit; the floor's inputs are set only with them."""
    cfg = TightConfig.for_ground_vehicle()
    rng = np.random.default_rng(4)
    epochs, _ = _synthetic_epochs(rng, cfg, 60, bias={0: (30.0, 10)})
    gm = _gauss_markov(rng, 60, len(epochs[0].z_m), 3.0, 5.0)
    epochs = [e._replace(z_m=e.z_m + gm[k]) for k, e in enumerate(epochs)]
    t_us = [1_000_000 + PERIOD_US * k for k in range(len(epochs))]
    a = _feed(cfg, "second-order", epochs, t_us, list(range(len(epochs))))
    monkeypatch.setattr(tight_engine._tight, "snapshot", lambda *args: None)
    b = _feed(cfg, "second-order", epochs, t_us, list(range(len(epochs))))
    for ea, eb in zip(a.entries, b.entries, strict=True):
        assert np.array_equal(ea.x, eb.x) and np.array_equal(ea.P, eb.P)
        assert eb.scatter_h.t_us < 0 and math.isnan(eb.fix_var_m2[0])
    last = a.entries[-1]
    assert last.scatter_h.t_us > 0 and last.scatter_v.t_us == last.scatter_h.t_us
    assert np.isfinite(last.fix_var_m2).all() and min(last.fix_var_m2) > 0.0


def test_reported_variance_is_the_floor_of_the_last_entry():
    """The navigator's variances: per axis max(k P, min(P σ_w²/r + min(σ_s², P σ_s² c_s/r), σ²), (f b)²) with
    the white and slow parts of the last entry's horizontal and vertical scatter (``consistency.
    snapshot_parts``), r its snapshot's variance, b its delay bias and f ``accuracy_delay_fraction``;
    velocities as P."""
    cfg = TightConfig.for_ground_vehicle(sigma_clock0_m=1e3, sigma_uniform_m=4.0)
    epochs, _ = _common_mode_epochs(np.random.default_rng(8), cfg, 150, 3.0, 0.1, 2.0)
    nav = TightNavigator(cfg, "naive")
    nav.engine.frame = FRAME
    for k, e in enumerate(epochs):
        t_us = 1_000_000 + PERIOD_US * k
        nav.engine.push_acc(t_us, 0.0, 0.0, 0.0)
        nav.engine.push_epoch(t_us, e)
    est = nav.estimate()
    assert est is not None
    last = nav.engine.entries[-1]
    _, out, _ = nav.engine.output_now()
    k = nav.accuracy_inflation()
    f_h = snapshot_parts(last.scatter_h, last.fix_var_m2[0], last.kept[0])
    f_v = snapshot_parts(last.scatter_v, last.fix_var_m2[1], last.kept[1])
    assert f_h is not None and f_v is not None and f_h.slow > 0.0
    assert max(last.delay_m2) < 1e-12  # equal weights: a common delay goes to the clock
    want = [snapshot_axis(out[9], k, f_h), snapshot_axis(out[10], k, f_h), snapshot_axis(out[11], k, f_v)]
    np.testing.assert_array_equal(est.cov_diag[0:3], want)
    np.testing.assert_array_equal(est.cov_diag[3:6], out[12:15])
    assert est.cov_diag[0] > k * out[9] and est.cov_diag[2] > k * out[11]  # the floor acts here


def _delayed_run(fraction: float, n: int = 150
                 ) -> tuple[list[tight_engine.Entry], np.ndarray, np.ndarray, np.ndarray]:
    """Every satellite late by 0.4 × its own σ (the C/N0 + elevation model's, which the fixed-weight
    cn0-elevation row fuses with: larger at low elevation) beside 0.1 m white noise, the report with
    ``accuracy_delay_fraction`` = ``fraction``: (the entries kept, the errors N, E, D, the reported variances
    and the last entry's ``delay_m2`` after the first 10 s)."""
    cfg = TightConfig.for_ground_vehicle(sigma_clock0_m=1e3, sigma_uniform_m=0.1,
                                         accuracy_delay_fraction=fraction)
    epochs, truth = _synthetic_epochs(np.random.default_rng(21), cfg, n)
    epochs = [e._replace(z_m=e.z_m + 0.4 * np.sqrt(e.r_model_m2)) for e in epochs]
    nav = TightNavigator(cfg, "cn0-elevation")
    nav.engine.frame = FRAME
    err, rep, delay = [], [], []
    for k, e in enumerate(epochs):
        t_us = 1_000_000 + PERIOD_US * k
        nav.engine.push_acc(t_us, 0.0, 0.0, 0.0)
        nav.engine.push_epoch(t_us, e)
        if k >= 50:
            est = nav.estimate()
            assert est is not None
            err.append(np.asarray(est.p_ned_m) - truth[k][0:3])
            rep.append(np.asarray(est.cov_diag[0:3]))
            delay.append(nav.engine.entries[-1].delay_m2)
    return list(nav.engine.entries), np.array(err), np.array(rep), np.array(delay)


def test_one_signed_delays_are_covered_and_the_estimate_is_unchanged():
    """Satellites late by 0.4 σ each (a street's one-signed delays; ``_delayed_run``): the filter's height
    settles on the snapshot's response to them, 0.4 b (``snapshot.delay_bias``: the weighted least squares of
    every satellite late by its σ; within 15 %), which its innovations do not show (the satellites agree on
    that position): without the delay term the report misses it (outside 1 σ in nearly every epoch), with
    ``accuracy_delay_fraction`` = 0.4 it is at least (0.4 b)² on every axis, |e_D| within 2 σ throughout. The
    estimate and every entry's state and covariance are the same bits with and without the term."""
    off, e_off, v_off, d_off = _delayed_run(0.0)
    on, e_on, v_on, d_on = _delayed_run(0.4)
    for a, b in zip(off, on, strict=True):
        assert np.array_equal(a.x, b.x) and np.array_equal(a.P, b.P) and a.delay_m2 == b.delay_m2
    assert np.array_equal(e_off, e_on) and np.array_equal(d_off, d_on)
    bias = np.sqrt(np.array(on[-1].delay_m2))
    assert bias[2] > 1.0  # the delays grow at low elevation: the height moves (metres)
    assert abs(e_on[-20:, 2].mean()) == pytest.approx(0.4 * bias[2], rel=0.15)  # (the receiver moves: noise)
    assert np.mean(e_off[:, 2] ** 2 > v_off[:, 2]) > 0.95  # before: outside 1 σ (a Gaussian: 32 %)
    assert (v_on >= 0.16 * d_on * (1 - 1e-12)).all()
    assert (e_on[:, 2] ** 2 <= 4.0 * v_on[:, 2]).all()  # after: within 2 σ (the filter settles within 0.6 m)
