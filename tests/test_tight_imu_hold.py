"""Held IMU time in the tightly coupled filter (history.py, "Held time"; the loose filter's
tests/test_estimator_imu_hold.py): lost samples bridged by holding the last one add the held sample's
white noise (per axis: the tight filter's horizontal and vertical densities) and the acceleration's
change to position and velocity; a stream without a lost sample is filtered bit for bit as before, a
late epoch re-fused through held time gives the in-order result, and the prior velocity NEES on a lossy
synthetic flight is inside its χ² interval with the noise and not without."""

import numpy as np
import pytest
from scipy.stats import chi2

from companion.estimator import model as loose
from companion.estimator.consistency import Fit
from companion.estimator.history import ImuHistory, mean_between
from companion.tight import TightConfig, _tight
from companion.tight.engine import Entry, EpochInfo, TightEngine
from companion.tight.model import N_CLK, N_STATE
from gcs_tools.evaluate.tight_hold import without_hold_noise
from tests.test_estimator_imu_hold import P_US, SIGMA_J, SIGMA_Q, _flight, _lossy
from tests.test_tight import FRAME, _synthetic_epochs

Q_NE, Q_D, Q_J = 0.3**2, 0.5**2, 1.1**2


def _predict(P, a, b, hold=(Q_NE, Q_D, Q_J, 1.0)):
    """The tight filter's F P Fᵀ + Q over the block between integrals a and b (no clocks live)."""
    _, nA, nB = mean_between((0.0,) * 15, a, b, 1.0)
    return _tight.predict_cov(P, b[0] - a[0], nA, nB, np.zeros(N_CLK), Q_NE, Q_D, 1e-4, 2e-4, 0.1, 1e-3, 0.5,
                              0.0, 0.0, False, a, b, *hold)


@pytest.mark.parametrize("missing", [8, 22])  # 45 ms held; 115 ms: a gap, held for imu_hold_max_s (100 ms)
def test_a_hold_adds_the_loose_filters_noise_per_axis(missing):
    """The held-time noise of a block is the loose filter's (the same code: held.h), with the white
    density of each axis: horizontal σ_acc², vertical σ_acc_vertical²; nothing else changes."""
    times = [*range(0, 100_000, P_US), *range(95_000 + (missing + 1) * P_US, 400_000, P_US)]
    h = ImuHistory(0.1)
    rng = np.random.default_rng(0)
    for t in times:
        h.append(t, *rng.standard_normal(3).tolist())
    A = rng.standard_normal((N_STATE, N_STATE))
    P = A @ A.T
    a, b = h.integrals(50_000), h.integrals(300_000)
    d = _predict(P, a, b) - _predict(P, a, b, (0.0, 0.0, 0.0, 0.0))
    assert np.count_nonzero(d[np.ix_(range(6), range(6))]) == 12  # each axis's pp, pv, vp, vv
    assert np.count_nonzero(d) == 12
    P15 = np.zeros((15, 15))  # the loose held noise on p, v alone, for each axis's white density
    for i, q in ((0, Q_NE), (1, Q_NE), (2, Q_D)):
        held = loose.BlockPropagator(0.0, 0.0, 0.0, q, Q_J, 1.0).predict_from(
            (0.0,) * 15, P15, a, b, b[0] - a[0], 1.0, 0.0)[1]
        for r, c in ((i, i), (i, 3 + i), (3 + i, 3 + i)):
            assert d[r, c] == pytest.approx(held[r, c], rel=1e-9)
            assert d[c, r] == d[r, c]
    assert d[5, 5] > d[3, 3] > 0.0
    # the C function alone: (pp, pv, vv) per axis of the white densities, the random walk, the coast
    qw = (Q_NE, Q_NE, Q_D)
    per_axis = [v for i in range(3) for v in (d[i, i], d[i, 3 + i], d[3 + i, 3 + i])]
    assert _tight.held_noise(a, b, qw, Q_J, 1.0) == pytest.approx(per_axis, rel=1e-9)
    assert _tight.held_noise(a, h.integrals(90_000), qw, Q_J, 1.0) is None  # before the hold
    assert _tight.held_noise(a, b, (0.0, 0.0, 0.0), 0.0, 0.0) is None


def _imu_stream(rng, t_end_us, keep_fn=None):
    """200 Hz NED accelerations (0.1 m/s² noise) to ``t_end_us``; ``keep_fn(n)``: the kept samples' mask."""
    t = np.arange(0, t_end_us + P_US, P_US)
    acc = rng.normal(0.0, 0.1, (len(t), 3))
    keep = np.ones(len(t), dtype=bool) if keep_fn is None else keep_fn(len(t))
    return t[keep], acc[keep]


def _feed(cfg, method, epochs, t_us, order, imu, hold=True) -> TightEngine:
    """The IMU samples pushed up to each epoch's time before it (epochs in ``order``; a late one after
    later ones)."""
    eng = TightEngine(cfg, method, frame=FRAME)
    if not hold:
        without_hold_noise(eng)
    t_imu, acc = imu
    i = 0
    for n, k in enumerate(order):
        target = max(t_us[j] for j in order[: n + 1])
        while i < len(t_imu) and t_imu[i] <= target + 50_000:  # the IMU runs a little ahead
            eng.push_acc(int(t_imu[i]), *acc[i].tolist())
            i += 1
        eng.push_epoch(t_us[k], epochs[k])
    while i < len(t_imu):
        eng.push_acc(int(t_imu[i]), *acc[i].tolist())
        i += 1
    return eng


def _equal_entries(a: TightEngine, b: TightEngine) -> None:
    assert len(a.entries) == len(b.entries)
    for ea, eb in zip(a.entries, b.entries, strict=True):
        assert ea.t_us == eb.t_us
        assert ea.x.tobytes() == eb.x.tobytes() and ea.P.tobytes() == eb.P.tobytes()


def test_without_a_lost_sample_the_filter_is_the_filter_before():
    """A stream without a lost sample: every entry, the state now and the output equal, bit for bit, the
    filter without the held-time noise; with lost samples they differ (the noise is there)."""
    cfg = TightConfig()
    rng = np.random.default_rng(4)
    epochs, _ = _synthetic_epochs(rng, cfg, 30)
    t_us = [1_000_000 + 200_000 * k for k in range(len(epochs))]
    order = list(range(len(epochs)))
    imu = _imu_stream(np.random.default_rng(5), t_us[-1] + 100_000)
    new, old = _feed(cfg, "second-order", epochs, t_us, order, imu), \
        _feed(cfg, "second-order", epochs, t_us, order, imu, hold=False)
    assert all(r[37:45] == (0.0,) * 8 for r in new.imu.rows)
    _equal_entries(new, old)
    sn, so = new.state_now(), old.state_now()
    assert sn is not None and so is not None
    assert sn[1].tobytes() == so[1].tobytes() and sn[2].tobytes() == so[2].tobytes()
    on, oo = new.output_now(), old.output_now()
    assert on is not None and oo is not None and on[1].tobytes() == oo[1].tobytes()
    lossy = _imu_stream(np.random.default_rng(5), t_us[-1] + 100_000,
                        lambda n: _lossy(np.random.default_rng(6), n))
    a, b = _feed(cfg, "second-order", epochs, t_us, order, lossy), \
        _feed(cfg, "second-order", epochs, t_us, order, lossy, hold=False)
    assert any(r[37] > 0.0 for r in a.imu.rows)
    assert a.entries[-1].P[5, 5] > b.entries[-1].P[5, 5]


@pytest.mark.parametrize("method", ["second-order", "student-t"])
def test_out_of_sequence_epochs_through_held_time_equal_in_order(method):
    """IMU datagrams lost (10 %, 8 samples each) and epochs (some valid inside a hold) arriving after
    later ones: the held-time noise is in the history, so re-fusion after a late epoch reproduces the
    in-order filter exactly."""
    cfg = TightConfig()
    rng = np.random.default_rng(12)
    n = 60
    epochs, _ = _synthetic_epochs(rng, cfg, n, dt_s=0.1)
    t_us = [1_000_000 + 100_000 * k + 2_500 for k in range(n)]  # between two IMU samples
    def keep(m):  # 30 % of 8-sample datagrams lost, and a 200 ms outage (a gap: held, then coasting)
        k = _lossy(np.random.default_rng(14), m, p_drop=0.3)
        k[1000:1040] = False
        return k

    imu = _imu_stream(np.random.default_rng(13), t_us[-1] + 100_000, keep)
    t_imu = imu[0]
    inside = [k for k, t in enumerate(t_us) if np.searchsorted(t_imu, t) < len(t_imu)
              and t_imu[np.searchsorted(t_imu, t)] - t_imu[np.searchsorted(t_imu, t) - 1] > 1.5 * P_US]
    assert len(inside) >= 5  # epochs valid while the IMU was held
    ref = _feed(cfg, method, epochs, t_us, list(range(n)), imu)
    order = list(range(n))
    for k in range(2, n - 4, 4):  # several epochs arrive after later ones (up to 0.4 s late)
        order[k], order[k + 3] = order[k + 3], order[k]
    late = _feed(cfg, method, epochs, t_us, order, imu)
    assert late.counts["gnss_out_of_order"] > 10 and late.counts["gnss_refused"] > 10
    assert ref.counts["gnss_out_of_order"] == 0
    assert any(r[37] > 0.0 for r in ref.imu.rows) and ref.imu.counts[1] == 1  # held time, one gap
    assert any(r[45] > 0.0 for r in ref.imu.rows)  # the coast's dropped acceleration
    _equal_entries(late, ref)
    assert late.output_now()[1].tobytes() == ref.output_now()[1].tobytes()


# ---------------------------------------------------------------- consistency on a synthetic flight
def _prior_nees(hold: bool, runs: int, fix_every: int = 40, r_m: float = 0.3) -> np.ndarray:
    """Prior NEES at every position fix after the first 2 s, per run: (velocity horizontal (2 dof),
    velocity vertical (1), position (3)), the prediction by the tight engine's own (``_predict``) on its
    IMU history, the fixes' update in numpy (the clocks stay unknown and unused: no satellites)."""
    cfg = TightConfig(sigma_acc_m_s2=SIGMA_Q, sigma_acc_vertical_m_s2=SIGMA_Q,
                      sigma_acc_bias_rw_m_s2_sqrt_s=0.0, sigma_acc_ned_rw_m_s2_sqrt_s=0.0,
                      imu_hold_acc_rw_m_s2_sqrt_s=SIGMA_J)
    H = np.zeros((3, N_STATE))
    H[:, 0:3] = np.eye(3)
    out = []
    for seed in range(runs):
        rng = np.random.default_rng(100 + seed)
        t_us, meas, p, v, keep = _flight(rng)
        eng = TightEngine(cfg, "naive", frame=FRAME)
        if not hold:
            without_hold_noise(eng)
        kept = np.flatnonzero(keep)
        P = np.zeros((N_STATE, N_STATE))
        P[0:6, 0:6] = np.diag([1.0] * 3 + [0.25] * 3)
        x = np.zeros(N_STATE)
        x[0:6] = np.concatenate([p[0], v[0]]) + rng.standard_normal(6) * np.sqrt(np.diag(P)[0:6])
        e, i, nees = None, 0, []
        for k in range(0, len(t_us), fix_every):
            t = int(t_us[k])
            while i < len(kept) and t_us[kept[i]] <= t:
                eng.push_acc(int(t_us[kept[i]]), *meas[kept[i]].tolist())
                i += 1
            ints = eng.imu.integrals(t)
            if e is not None:
                x, P = eng._predict(e, t, ints)
                dv, dp = x[3:6] - v[k], x[0:3] - p[k]
                if t >= 2_000_000:
                    nees.append((dv[0:2] @ np.linalg.solve(P[3:5, 3:5], dv[0:2]), dv[2] ** 2 / P[5, 5],
                                 dp @ np.linalg.solve(P[0:3, 0:3], dp)))
            y = p[k] + rng.standard_normal(3) * r_m - x[0:3]
            PHt = P @ H.T
            K = PHt @ np.linalg.inv(H @ PHt + np.eye(3) * r_m**2)
            x, P = x + K @ y, P - K @ PHt.T
            P = 0.5 * (P + P.T)
            e = Entry(t, None, x, P, ints, (False,) * N_CLK, None, t, EpochInfo(), (0, 0, 0, 0, 0), Fit())
        out.append(nees)
    return np.array(out)  # (runs, fixes, 3)


def test_prior_nees_is_consistent_through_held_time_and_was_not_without():
    """60 Monte-Carlo flights of 20 s (truth from a finer integration, not from the filter's model; the
    loose filter's test flight), 5 Hz position fixes, 10 % of 8-sample IMU datagrams lost: the tight
    filter's prior velocity NEES averaged over the runs, at each fix, is inside its two-sided 99 % χ²
    interval (χ²(60 k) / 60) for nearly all fixes with the held-time noise and well above it without; the
    position NEES per dof is near 1 with it and above without."""
    runs = 60
    fixed, before = _prior_nees(True, runs), _prior_nees(False, runs)
    for j, k in ((0, 2), (1, 1)):  # velocity horizontal, vertical
        lo, hi = chi2.ppf([0.005, 0.995], runs * k) / runs
        mean_fixed, mean_before = fixed[:, :, j].mean(axis=0), before[:, :, j].mean(axis=0)
        assert np.mean((mean_fixed >= lo) & (mean_fixed <= hi)) >= 0.95
        assert np.mean((mean_before >= lo) & (mean_before <= hi)) <= 0.5
        assert 0.9 < fixed[:, :, j].mean() / k < 1.1 and before[:, :, j].mean() / k > 1.5
    pos_fixed, pos_before = fixed[:, :, 2].mean() / 3, before[:, :, 2].mean() / 3
    assert 0.9 < pos_fixed < 1.1 and pos_before > pos_fixed + 0.1


@pytest.mark.parametrize("field", ["imu_hold_acc_rw_m_s2_sqrt_s", "imu_hold_periods"])
@pytest.mark.parametrize("value", [-0.1, float("nan"), float("inf"), "fast"])
def test_a_bad_hold_setting_is_a_one_line_error(field, value):
    from companion.mission.schema import ConfigError, build

    with pytest.raises(ConfigError, match=rf"^tight[:.] ?{field}") as err:
        build(TightConfig, {field: value}, "tight")
    assert "\n" not in str(err.value)
    assert getattr(build(TightConfig, {field: 0}, "tight"), field) == 0


def test_the_hold_limit_follows_the_imu_period_when_told():
    """imu_hold_periods reaches the tight filter's IMU history (the loose filter's semantics)."""
    assert TightEngine(TightConfig(), frame=FRAME).imu.hold_periods == 0.0
    assert TightEngine(TightConfig(imu_hold_periods=2.5), frame=FRAME).imu.hold_periods == 2.5
