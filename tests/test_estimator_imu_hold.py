"""Held IMU time (history.py, "Held time"): lost samples bridged by holding the last one add the held
sample's white noise and the acceleration's change to the covariance; a stream without a lost sample
is predicted exactly as before, and a late fix re-propagated through held time gives the in-order
result."""

import numpy as np
import pytest
from scipy.stats import chi2

from companion.estimator import _core, model
from companion.estimator.config import EstimatorConfig
from companion.estimator.engine import FusionEngine
from companion.estimator.history import ImuHistory
from tests.estimator_streams import OPEN_SKY, drive, multipath_stream

N = model.N_STATE
P_US = 5_000  # 200 Hz


def _history(times_us, rng=None, hold_max_s=0.05):
    h = ImuHistory(hold_max_s)
    rng = rng or np.random.default_rng(0)
    for t in times_us:
        h.append(int(t), *rng.standard_normal(3).tolist())
    return h


def _cov(prop, h, t_a, t_b, P=None):
    """P after the block [t_a, t_b] (alpha 1, no GNSS-bias noise), from P (default zero)."""
    P = np.zeros((N, N)) if P is None else P
    x = (0.0,) * N
    return prop.predict_from(x, P, h.integrals(t_a), h.integrals(t_b), (t_b - t_a) * 1e-6, 1.0, 0.0)[1]


@pytest.mark.parametrize("missing", [8, 12])  # 45 ms held; 65 ms: a gap, held for imu_hold_max_s (50 ms)
def test_a_hold_adds_the_stated_velocity_position_noise(missing):
    """Over an interval of L s holding a sample (period p) for L_h s (a gap: the limit, then coasting
    C = L − L_h), each axis gains ΔP_vv = σ_q² L_h (L_h − p) / p, spread evenly over the hold, + σ_j² L³ / 3,
    spread evenly over the interval: ΔP_pv = ∫ n (t_b − s) ds, ΔP_pp = ∫ n (t_b − s)² ds; a gap's coast
    drops the held acceleration ã, adding ã_i² C² on axis i, spread evenly over the coast; a block split
    inside composes to the same covariance."""
    q, qj, p = 0.3**2, 1.1**2, P_US * 1e-6
    times = [*range(0, 100_000, P_US), *range(95_000 + (missing + 1) * P_US, 400_000, P_US)]
    h = _history(times)
    t_k = 95_000  # the held sample
    L = (missing + 1) * p
    C = max(L - 0.05, 0.0)  # the coast
    a_held = np.array(h.rows[h.t_us.index(t_k)][1:4])
    assert (C > 0) == (missing == 12) and (len(h) == len(times) + (C > 0))
    prop = model.BlockPropagator(q, 0.0, 0.0, q, qj, 1.0)
    t_a, t_b = 50_000, 300_000
    T, tb, s0, s1 = (t_b - t_a) * 1e-6, t_b * 1e-6, t_k * 1e-6, t_k * 1e-6 + L
    Lh = L - C  # held
    held_vv = q * Lh * (Lh - p) / p + qj * L**3 / 3.0
    nw, nj = q * (Lh - p) / p, qj * L**2 / 3.0  # white over the hold, the acceleration's change over L
    held_pv = nw * ((tb - s0) ** 2 - (tb - s0 - Lh) ** 2) / 2.0 + nj * ((tb - s0) ** 2 - (tb - s1) ** 2) / 2.0
    held_pp = nw * ((tb - s0) ** 3 - (tb - s0 - Lh) ** 3) / 3.0 + nj * ((tb - s0) ** 3 - (tb - s1) ** 3) / 3.0
    c = a_held**2 * C  # the coast's density per axis, over [s1 − C, s1]
    coast_vv, coast_pv = c * C, c * ((tb - s1 + C) ** 2 - (tb - s1) ** 2) / 2.0
    coast_pp = c * ((tb - s1 + C) ** 3 - (tb - s1) ** 3) / 3.0
    P = _cov(prop, h, t_a, t_b)
    for i in range(3):
        assert P[3 + i, 3 + i] == pytest.approx(q * T + held_vv + coast_vv[i], rel=1e-12)
        assert P[i, 3 + i] == pytest.approx(q * T * T / 2.0 + held_pv + coast_pv[i], rel=1e-9)
        assert P[i, i] == pytest.approx(q * T**3 / 3.0 + held_pp + coast_pp[i], rel=1e-9)
    # the coast's term off (the propagator without its scale): the held time alone
    P0 = _cov(model.BlockPropagator(q, 0.0, 0.0, q, qj), h, t_a, t_b)
    assert P0[3, 3] == pytest.approx(q * T + held_vv, rel=1e-12)
    # without the held-time densities: the model's σ_q² T alone (the behaviour before)
    assert _cov(model.BlockPropagator(q, 0.0, 0.0), h, t_a, t_b)[3, 3] == pytest.approx(q * T, rel=1e-12)
    # split inside the hold, and inside the coast: the same covariance in two blocks
    for t_m in (t_k + 20_000, t_k + 57_000):
        two = _cov(prop, h, t_m, t_b, _cov(prop, h, t_a, t_m))
        np.testing.assert_allclose(two[0:6, 0:6], P[0:6, 0:6], rtol=1e-9, atol=1e-15)
    # the output path adds the same variances
    out = prop.output_from((0.0,) * N, np.zeros((N, N)), h.integrals(t_a), h.integrals(t_b), T, 1.0, 0.0)[1]
    np.testing.assert_allclose(out[9:15], np.diag(P)[0:6], rtol=1e-12)


def test_no_lost_sample_changes_nothing():
    """Intervals up to 1.5 periods (jitter, not a lost sample) hold no time: the history's held-time
    columns stay zero and every prediction equals, bit for bit, the propagator without them."""
    rng = np.random.default_rng(3)
    times = np.cumsum(rng.integers(4_500, 6_500, size=600))  # 4.5-6.5 ms: never 1.5 periods
    h = _history(times, rng)
    assert all(r[37:45] == (0.0,) * 8 for r in h.rows)
    q = 0.3**2
    new, old = model.BlockPropagator(q, 0.01, 0.02, q, 1.1**2), model.BlockPropagator(q, 0.01, 0.02)
    A = rng.standard_normal((N, N))
    P = A @ A.T
    x = tuple(rng.standard_normal(N).tolist())
    for t_a, t_b in rng.integers(times[0], times[-1], size=(30, 2)).tolist():
        t_a, t_b = min(t_a, t_b), max(t_a, t_b)
        a, b, T = h.integrals(t_a), h.integrals(t_b), (t_b - t_a) * 1e-6
        xn, Pn, *_ = new.predict_from(x, P, a, b, T, 0.9, 0.01)
        xo, Po, *_ = old.predict_from(x, P, a, b, T, 0.9, 0.01)
        assert xn == xo and Pn.tobytes() == Po.tobytes()
        assert new.output_from(x, P, a, h, T, 0.9, 0.01)[1].tobytes() == \
            old.output_from(x, P, a, h, T, 0.9, 0.01)[1].tobytes()


def test_engine_without_a_lost_sample_is_the_engine_before():
    """The whole filter on a gap-free stream: identical to the filter whose propagators have no
    held-time noise (the behaviour before it existed), every method-independent output bit for bit."""
    cfg = EstimatorConfig()
    s = multipath_stream(np.random.default_rng(7), cfg, [(6.0, 0.0), (6.0, 1.2)])
    new = FusionEngine(cfg, "second-order", context=OPEN_SKY)
    old = FusionEngine(cfg, "second-order", context=OPEN_SKY)
    old._prop = model.BlockPropagator(old._q_acc, old._q_rw, old._q_ned)
    f = cfg.imu_gnss_disagree_acc_factor**2
    old._prop_disagree = model.BlockPropagator(old._q_acc * f, old._q_rw, old._q_ned)
    drive(s, new, s.fix_t_us.copy())
    drive(s, old, s.fix_t_us.copy())
    a, b = new.snapshot(), old.snapshot()
    assert a.x == b.x and np.asarray(a.var).tobytes() == np.asarray(b.var).tobytes() and a.beta == b.beta
    assert new.covariance_now().tobytes() == old.covariance_now().tobytes()


def _lossy(rng, n, block=8, p_drop=0.1):
    """Keep mask of n samples: blocks of ``block`` samples (a datagram) lost with probability p_drop,
    never two in a row (a loss stays a hold, shorter than imu_hold_max_s)."""
    keep = np.ones(n, dtype=bool)
    last = -2
    for b in range(1, n // block - 1):
        if b - last > 1 and rng.random() < p_drop:
            keep[b * block:(b + 1) * block] = False
            last = b
    return keep


def _slow(rng, n, every=20, p_drop=0.2):
    """Keep mask of n 200 Hz samples: every ``every``-th (10 Hz), a kept one lost with probability p_drop
    (one lost: a hold of 2 periods; two in a row: a gap, held 2.5 periods, then coasting)."""
    keep = np.zeros(n, dtype=bool)
    keep[::every] = True
    keep[every * 4::every] &= rng.random(len(keep[every * 4::every])) >= p_drop
    return keep


def _outages(rng, n, p_drop=0.1):
    """Keep mask of n 200 Hz samples: 8-sample datagrams lost as ``_lossy``, and outages of 60-400 ms
    (a gap: held imu_hold_max_s, then coasting) about every 2 s."""
    keep = _lossy(rng, n, p_drop=p_drop)
    for k in range(300, n - 200, 400):
        start = k + int(rng.integers(0, 100))
        keep[start:start + int(rng.integers(12, 80))] = False
    return keep


@pytest.mark.parametrize("mode", ["datagrams", "10 Hz", "outages"])
def test_out_of_order_fusion_through_held_time_equals_in_order(mode):
    """IMU datagrams lost (10 %, 8 samples each), a 10 Hz IMU (the hold limit following its period) with
    single and double losses, or 200 Hz with outages coasted beyond the limit; fixes (some valid inside a
    hold or a coast) arriving up to 1.2 s late: the held-time and coast noise and the hold decision are in
    the history, so re-propagation after a late fix reproduces the in-order filter exactly."""
    cfg = EstimatorConfig(imu_hold_periods=2.5 if mode == "10 Hz" else 0.0)
    s = multipath_stream(np.random.default_rng(9), cfg, [(8.0, 0.0), (8.0, 1.2)])
    loss = {"datagrams": _lossy, "10 Hz": _slow, "outages": _outages}[mode]
    keep = loss(np.random.default_rng(10), len(s.t_us))
    t_fix = s.fix_t_us
    inside = ~keep[s.fix_index]
    assert inside.sum() > 10  # fixes valid while the IMU was held
    rng = np.random.default_rng(11)
    delay = rng.uniform(0.0, 1.2e6, size=len(t_fix)).astype(np.int64)
    delay[0] = 0

    def run(arrival):
        e = FusionEngine(cfg, "second-order", context=OPEN_SKY)
        order, j = np.argsort(arrival, kind="stable"), 0
        for k in np.flatnonzero(keep).tolist():
            t = int(s.t_us[k])
            e.push_acc(t, *s.a_ned_m_s2[k].tolist())
            while j < len(order) and arrival[order[j]] <= t:
                e.push_fix(int(t_fix[order[j]]), s.z_ned_m[order[j]])
                j += 1
        return e

    late = run(np.minimum(t_fix + delay, s.t_us[-1]))
    ref = run(t_fix.copy())
    assert late.counts["gnss_out_of_order"] > 50 and ref.counts["gnss_out_of_order"] == 0
    rows = ref.imu.rows
    assert any(r[37] > 0.0 for r in rows)  # held time in the history kept
    gaps = ref.counts["imu_gaps"]
    if mode == "datagrams":
        assert gaps == 0
    else:  # gaps held then coasted (a 10 Hz stream: only the first interval and two samples lost in a row)
        assert 2 < gaps < (20 if mode == "10 Hz" else 50), gaps
    a, b = late.snapshot(), ref.snapshot()
    assert a.t_us == b.t_us
    np.testing.assert_allclose(a.x, b.x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.var, b.var, rtol=0, atol=1e-12)
    np.testing.assert_allclose(late.covariance_now(), ref.covariance_now(), rtol=0, atol=1e-12)
    for f, g in zip(late.fusions[1:], ref.fusions[-len(late.fusions) + 1:], strict=True):
        np.testing.assert_allclose(f.P, g.P, rtol=0, atol=1e-12)


def _circle_at(t_s):
    """A horizontal circle (10 m radius, 0.5 rad/s: 5 m/s, 2.5 m/s²) with a constant climb acceleration."""
    w, r, az = 0.5, 10.0, -0.2
    c, s = np.cos(w * t_s), np.sin(w * t_s)
    p = np.stack([r * c, r * s, 0.5 * az * t_s**2], axis=-1)
    v = np.stack([-r * w * s, r * w * c, az * t_s], axis=-1)
    return p, v


@pytest.mark.parametrize("periods", [2.5, 0.0])
def test_a_10_hz_imu_is_integrated_sample_to_sample(periods):
    """A 10 Hz IMU (90-110 ms between samples) reporting the mean acceleration over each interval, as a
    delta-velocity IMU does (Δv / Δt), on a known circle: started from one exact fix with its velocity
    (after the first interval, which has no period yet),
    the filter dead-reckons 10 s to within 1 mm/s and 5 cm of the truth with the hold limit following the
    period (every interval held, none a gap). With the fixed 50 ms limit (``imu_hold_periods`` 0, the
    behaviour before) every interval is a gap that coasts its second half, and the estimate is metres off."""
    cfg = EstimatorConfig(imu_hold_periods=periods)
    rng = np.random.default_rng(4)
    t_us = np.concatenate([[1_000_000], 1_000_000 + np.cumsum(rng.integers(90_000, 110_001, size=100))])
    t_s = (t_us - t_us[0]) * 1e-6
    p, v = _circle_at(t_s)
    e = FusionEngine(cfg, "second-order", context=OPEN_SKY)
    for k in range(len(t_us) - 1):
        e.push_acc(int(t_us[k]), *((v[k + 1] - v[k]) / (t_s[k + 1] - t_s[k])).tolist())
        if k == 1:  # after the first interval (no period yet: a gap)
            e.push_fix(int(t_us[1]), p[1], (1e-6,) * 3, v[1], (1e-8,) * 3)
    e.push_acc(int(t_us[-1]), 0.0, 0.0, 0.0)
    snap = e.snapshot()
    assert snap.t_us == t_us[-1] and e.counts["gnss_fused"] == 1
    dp, dv = np.abs(np.array(snap.x[0:3]) - p[-1]), np.abs(np.array(snap.x[3:6]) - v[-1])
    if periods:
        assert e.counts["imu_gaps"] == 1  # the first interval: no period yet
        assert dv.max() < 1e-3 and dp.max() < 0.05
    else:
        assert e.counts["imu_gaps"] == len(t_us) - 1
        assert dp.max() > 3.0


# ---------------------------------------------------------------- consistency on a synthetic flight
SIGMA_Q, SIGMA_J = 0.1, 5.0  # white density (m/s²/√Hz) and acceleration random walk (m/s²/√s)
FINE = 10  # truth sub-steps per IMU period


def _flight(rng, duration_s=20.0, loss=_lossy):
    """Truth from fine steps (0.5 ms): an acceleration random walk of density SIGMA_J² integrated; the
    IMU samples it every 5 ms with white noise SIGMA_Q² / p; lost as ``loss`` says (default: 10 % of
    8-sample datagrams)."""
    n = int(duration_s / (P_US * 1e-6))
    dtf = P_US * 1e-6 / FINE
    a = np.cumsum(rng.standard_normal((n * FINE, 3)) * SIGMA_J * np.sqrt(dtf), axis=0)
    v = np.vstack([np.zeros(3), np.cumsum(a * dtf, axis=0)])
    p = np.vstack([np.zeros(3), np.cumsum(v[:-1] * dtf + 0.5 * a * dtf * dtf, axis=0)])
    k = np.arange(n) * FINE
    meas = a[k] + rng.standard_normal((n, 3)) * SIGMA_Q / np.sqrt(P_US * 1e-6)
    return np.arange(n) * P_US, meas, p[k], v[k], loss(rng, n)


def _velocity_nees(q_hold_white, q_hold_rw, runs=30, fix_every=40, r_m=0.3, q_coast=0.0, loss=_lossy):
    """Prior velocity NEES (horizontal 2 dof, vertical 1 dof) at every fix after the first 2 s, per run,
    and whether the block before the fix coasted (third column, 1.0: yes)."""
    prop = model.BlockPropagator(SIGMA_Q**2, 0.0, 0.0, q_hold_white, q_hold_rw, q_coast)
    out = []
    for seed in range(runs):
        rng = np.random.default_rng(100 + seed)
        t_us, meas, p, v, keep = _flight(rng, loss=loss)
        h = ImuHistory(0.05)
        P = np.diag([1.0] * 3 + [0.25] * 3 + [0.0] * 9)
        x0 = np.zeros(N)
        x0[0:6] = np.concatenate([p[0], v[0]]) + rng.standard_normal(6) * np.sqrt(np.diag(P)[0:6])
        x, t_prev, a_prev = tuple(x0.tolist()), None, None
        nees = []
        for k in np.flatnonzero(keep).tolist():
            h.append(int(t_us[k]), *meas[k].tolist())
        for k in range(0, len(t_us), fix_every):
            b = h.integrals(int(t_us[k]))
            if t_prev is not None:
                x, P, *_ = prop.predict_from(x, P, a_prev, b, (t_us[k] - t_prev) * 1e-6, 1.0, 0.0)
                e = np.array(x[3:6]) - v[k]
                if t_us[k] >= 2_000_000:
                    # the coast's moments moved: 1 (the IMU back before the fix), 2 (the fix in the outage)
                    coasted = 0.0 if b[31] == a_prev[31] else 1.0 if keep[k] else 2.0
                    nees.append((e[0:2] @ np.linalg.solve(P[3:5, 3:5], e[0:2]), e[2] ** 2 / P[5, 5],
                                 coasted))
            z = p[k] + rng.standard_normal(3) * r_m
            y = tuple((z - np.array(x[0:3])).tolist())
            x, P, _ = _core.update(x, P, y, (r_m**2,) * 3)
            t_prev, a_prev = t_us[k], b
        out.append(nees)
    return np.array(out)  # (runs, fixes, 3)


def test_velocity_nees_is_consistent_through_held_time_and_was_not_without():
    """60 Monte-Carlo flights of 20 s (truth from a finer integration, not from the filter's model), 5 Hz
    position fixes: the prior velocity NEES averaged over the runs, at each fix, inside its two-sided
    99 % χ² interval (χ²(60 k) / 60, k = 2 horizontal, 1 vertical) for nearly all fixes with the held-time
    noise; without it the held samples' errors are not covered and the NEES is well above the interval."""
    runs = 60
    fixed = _velocity_nees(SIGMA_Q**2, SIGMA_J**2, runs)
    before = _velocity_nees(0.0, 0.0, runs)
    for j, k in ((0, 2), (1, 1)):  # horizontal, vertical
        lo, hi = chi2.ppf([0.005, 0.995], runs * k) / runs
        mean_fixed, mean_before = fixed[:, :, j].mean(axis=0), before[:, :, j].mean(axis=0)
        inside_fixed = np.mean((mean_fixed >= lo) & (mean_fixed <= hi))
        inside_before = np.mean((mean_before >= lo) & (mean_before <= hi))
        assert inside_fixed >= 0.95
        assert inside_before <= 0.5
        assert 0.9 < fixed[:, :, j].mean() / k < 1.1 and before[:, :, j].mean() / k > 1.5


def test_velocity_nees_is_consistent_through_outages_coasted():
    """The same flights with outages of 60-400 ms about every 2 s (besides lost datagrams): each is held
    for imu_hold_max_s, then coasted. With the coast's noise (the acceleration's change over the whole
    interval and the acceleration the coast drops) the prior velocity NEES per dof at the fixes after an
    outage (the IMU back before the fix), pooled over the runs, is inside its two-sided 99 % χ² interval,
    and the NEES averaged over the runs at each fix inside its interval for nearly all fixes; without the
    dropped acceleration's term the fixes after an outage are far outside. A fix inside an outage is
    covered conservatively (NEES per dof below 1): the noise is spread evenly over the whole interval."""
    runs = 60
    fixed = _velocity_nees(SIGMA_Q**2, SIGMA_J**2, runs, q_coast=1.0, loss=_outages)
    before = _velocity_nees(SIGMA_Q**2, SIGMA_J**2, runs, q_coast=0.0, loss=_outages)
    after, inside = fixed[:, :, 2] == 1.0, fixed[:, :, 2] == 2.0
    assert after.sum() > 300 and inside.sum() > 300 and (before[:, :, 2] == fixed[:, :, 2]).all()
    n = int(after.sum())
    for j, k in ((0, 2), (1, 1)):  # horizontal, vertical
        lo, hi = chi2.ppf([0.005, 0.995], n * k) / (n * k)
        assert lo <= fixed[:, :, j][after].mean() / k <= hi
        assert before[:, :, j][after].mean() / k > 10.0
        assert 0.5 < fixed[:, :, j][inside].mean() / k < 1.0
        lo1, hi1 = chi2.ppf([0.005, 0.995], runs * k) / runs
        mean_fixed = fixed[:, :, j].mean(axis=0)
        assert np.mean((mean_fixed >= lo1) & (mean_fixed <= hi1)) >= 0.95
        assert 0.85 < fixed[:, :, j].mean() / k < 1.1


@pytest.mark.parametrize("value", [-0.1, float("nan"), float("inf"), "fast"])
def test_a_bad_acceleration_change_density_is_a_one_line_error(value):
    from companion.mission.schema import ConfigError, build

    with pytest.raises(ConfigError, match=r"^estimator[:.] ?imu_hold_acc_rw_m_s2_sqrt_s") as err:
        build(EstimatorConfig, {"imu_hold_acc_rw_m_s2_sqrt_s": value}, "estimator")
    assert "\n" not in str(err.value)
    off = build(EstimatorConfig, {"imu_hold_acc_rw_m_s2_sqrt_s": 0}, "estimator")
    assert off.imu_hold_acc_rw_m_s2_sqrt_s == 0
