"""The tightly coupled filter: Jacobians against finite differences, the per-satellite belief (gradient,
R(β) monotone and bounded, direction), out-of-sequence epochs == in order to 1e-9, NEES/NIS in χ²
bounds on its own model, the satellite-state cache's error, the navigator on raw epochs."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import chi2

from companion.domain.samples import GnssFix
from companion.errors import ConfigError
from companion.estimator.consistency import fix_floor, snapshot_axis, snapshot_parts
from companion.gnss import make_epoch
from companion.gnss.systems import System
from companion.tight import Odometry, RawGnss, TightConfig, TightNavigator, belief, model
from companion.tight.engine import TightEngine, prepare_epoch
from companion.tight.model import I_CLK, I_DRIFT, I_HEADING, N_STATE, Frame
from companion.tight.satcache import SatelliteCache
from tests.gnss_helpers import RX_ECEF, T0, hold_at_rest, observe, store

FRAME = Frame.at_ecef(RX_ECEF)
STORE = store()


def _sats(t: float = T0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(system, prn, position, velocity) of the synthetic satellites above 10° at RX_ECEF."""
    kep, glo = STORE.kepler, STORE.glonass
    sysv = np.array([e.system for e in kep] + [int(System.GLONASS)] * len(glo))
    prn = np.array([e.prn for e in kep] + [g.prn for g in glo])
    s = STORE.states(sysv, prn, np.full(len(sysv), t))
    d = s.pos_ecef_m - RX_ECEF
    el = model.elevation_rad(d / np.linalg.norm(d, axis=1)[:, None], FRAME)
    vis = s.valid & (el > math.radians(10))
    return sysv[vis], prn[vis], s.pos_ecef_m[vis], s.vel_ecef_m_s[vis]


def _state(rng: np.random.Generator) -> np.ndarray:
    x = np.zeros(N_STATE)
    x[0:3] = rng.normal(0, 50, 3)
    x[3:6] = rng.normal(0, 10, 3)
    x[I_CLK:I_DRIFT] = rng.normal(0, 1e4, I_DRIFT - I_CLK)
    x[I_DRIFT] = rng.normal(0, 50)
    x[I_HEADING] = rng.uniform(-3, 3)
    x[-1] = rng.normal(0, 0.01)  # the yaw-rate bias
    return x


def _numeric_jacobian(f, x: np.ndarray, steps: np.ndarray) -> np.ndarray:
    cols = []
    for i in range(len(x)):
        e = np.zeros(len(x))
        e[i] = steps[i]
        cols.append((f(x + e) - f(x - e)) / (2 * steps[i]))
    return np.column_stack(cols)


def test_measurement_jacobians_match_finite_differences():
    rng = np.random.default_rng(1)
    sysv, _, pos, vel = _sats()
    slot = model.SLOT_OF[sysv]
    steps = np.full(N_STATE, 1e-3)
    steps[0:3] = 1.0  # metres: the range is smooth over 20,000 km
    steps[I_CLK:I_HEADING] = 1.0  # linear: a step above the range's rounding
    for _ in range(3):
        x = _state(rng)
        _, H, _ = model.pseudorange(x, FRAME, pos, slot)
        num = _numeric_jacobian(lambda z: model.pseudorange(z, FRAME, pos, slot)[0], x, steps)
        np.testing.assert_allclose(H, num, atol=1e-7)
        _, Hr = model.range_rate(x, FRAME, pos, vel)
        num = _numeric_jacobian(lambda z: model.range_rate(z, FRAME, pos, vel)[0], x, steps)
        np.testing.assert_allclose(Hr, num, atol=1e-9)
        assert np.abs(Hr[:, 0:3]).max() > 1e-5  # the position terms are there and right
        _, Ho = model.odometry_velocity(x, 7.0, 0.3)
        num = _numeric_jacobian(lambda z: -model.odometry_velocity(z, 7.0, 0.3)[0], x, np.full(N_STATE, 1e-6))
        np.testing.assert_allclose(Ho, num, atol=1e-7)
        _, hl = model.lateral_velocity(x, 0.3)
        num = _numeric_jacobian(lambda z: -model.lateral_velocity(z, 0.3)[0], x, np.full(N_STATE, 1e-6))
        np.testing.assert_allclose(hl, num, atol=1e-7)
        assert np.abs(hl[0, I_HEADING]) > 0.1  # the heading term is there
        _, hs = model.speed(x)
        num = _numeric_jacobian(lambda z: np.array([model.speed(z)[0]]), x, np.full(N_STATE, 1e-6))
        np.testing.assert_allclose(hs[None, :], num, atol=1e-7)


def test_prepared_sigma_models_are_the_single_point_solutions():
    from companion.gnss.spp import SppConfig, sigma_model_m

    cfg = TightConfig()
    ep, _ = observe(STORE, T0, RX_ECEF)
    from companion.gnss import attach_broadcast

    ep, _ = attach_broadcast(ep, STORE)
    rng = np.random.default_rng(10)
    ep = ep.replace(cn0_dbhz=rng.uniform(20, 50, ep.n))
    m = prepare_epoch(ep, FRAME, cfg)
    assert m is not None and m.epoch.n == ep.n
    el = np.radians(m.elevation_deg)
    base = SppConfig(weighting="cn0-elevation")
    np.testing.assert_allclose(m.r_model_m2, sigma_model_m(ep, el, base) ** 2, rtol=1e-9)
    los = SppConfig(weighting="cn0", sigma_cn0_m=cfg.sigma_los_cn0_m)
    np.testing.assert_allclose(m.r_los_m2, sigma_model_m(ep, el, los) ** 2, rtol=1e-9)


def test_prediction_is_the_loose_filters_on_p_v_a_d():
    """The tight transition and process noise equal the loose filter's (its GNSS bias dropped)."""
    from companion.estimator import model as loose

    rng = np.random.default_rng(8)
    T = 0.2
    A = T * np.linalg.qr(rng.normal(size=(3, 3)))[0]
    B = 0.5 * T * A
    live = np.array([1.0, 0.0, 1.0, 0.0, 0.0, 1.0])
    F = model.transition(T, -A.ravel(), -B.ravel(), live)
    nav = model.NAV_OF_LOOSE
    F_loose = loose.transition_block(T, A, B, 1.0)[np.ix_(nav, nav)]
    np.testing.assert_allclose(F[:12, :12], F_loose, atol=1e-15)
    Q = model.process_noise(T, -A.ravel(), live, 0.09, 0.09, 9e-6, 1e-4, 0.1, 1e-3, 0.5)
    Q15 = np.zeros((15, 15))
    loose.add_process_noise(Q15, T, A / T, 0.09, 0.0, 9e-6, 1e-4)
    np.testing.assert_allclose(Q[:12, :12], Q15[np.ix_(nav, nav)], atol=1e-15)
    assert np.all(np.linalg.eigvalsh(Q) > -1e-15) and Q[I_CLK + 1, I_CLK + 1] == 0.0


def test_range_rate_model_matches_the_generators_doppler():
    """The synthetic receiver's Doppler (central differences of exact light-time ranges) against the
    model at the true state: 0.07 mm/s measured (the first-order Earth rotation; with RTKLIB's sign of
    the Sagnac rate it was ~5 mm/s)."""
    v = np.array([3.0, -2.0, 1.0])
    ep, _ = observe(STORE, T0, RX_ECEF, v_rx_ecef=v, atmosphere=False)
    from companion.gnss import attach_broadcast

    ep, _ = attach_broadcast(ep, STORE)
    x = np.zeros(N_STATE)
    x[3:6] = FRAME.c_ecef_ned.T @ v
    from companion.gnss.constants import C_M_S

    pred, _ = model.range_rate(x, FRAME, ep.sat_pos_ecef_m, ep.sat_vel_ecef_m_s)
    got = ep.pseudorange_rate_m_s + C_M_S * ep.sat_clock_drift_s_s
    assert np.abs(got - pred).max() < 1e-3, np.abs(got - pred).max()


def test_range_rate_sagnac_term_is_the_derivative_of_the_ranges_sagnac_term():
    """Known answer: apart from the light-time factor f = 1 − l·v_s/c on the geometric rate, the
    predicted range rate (model.py; the C core and the single-point solver are held to it by their own
    tests) is the time derivative of the
    Sagnac-corrected range (``sagnac_range_m``) with satellite and receiver moving; RTKLIB's ``resdop``
    has this term's sign flipped (a few mm/s per satellite)."""
    from companion.gnss.constants import C_M_S
    from companion.gnss.geometry import sagnac_range_m

    rng = np.random.default_rng(7)
    rs = rng.normal(0.0, 1.0, (8, 3))
    rs = 26.6e6 * rs / np.linalg.norm(rs, axis=1)[:, None] + RX_ECEF
    us = rng.normal(0.0, 2500.0, (8, 3))
    x = np.zeros(N_STATE)
    x[3:6] = [12.0, -9.0, 2.0]  # v_ned_m_s
    x[I_DRIFT] = 3.0
    ve = FRAME.c_ecef_ned @ x[3:6]
    r = FRAME.ecef(x[0:3])
    h = 1e-3
    fd = (sagnac_range_m(rs + h * us, r + h * ve)[0] - sagnac_range_m(rs - h * us, r - h * ve)[0]) / (2 * h)
    los = (rs - r) / np.linalg.norm(rs - r, axis=1)[:, None]
    g = np.einsum("ij,ij->i", los, us - ve)
    f = 1.0 - np.einsum("ij,ij->i", los, us) / C_M_S
    pred, H = model.range_rate(x, FRAME, rs, us)
    np.testing.assert_allclose(pred - x[I_DRIFT] - g * (f - 1.0), fd, atol=1e-6)
    # the Jacobian by finite differences (position and velocity)
    for k in range(6):
        dx = np.zeros(N_STATE)
        dx[k] = 1e-3 if k < 3 else 1e-4
        up, down = model.range_rate(x + dx, FRAME, rs, us)[0], model.range_rate(x - dx, FRAME, rs, us)[0]
        num = (up - down) / (2 * dx[k])
        np.testing.assert_allclose(H[:, k], num, atol=1e-7)


def test_belief_gradient_monotone_bounded_r():
    cfg = TightConfig()
    rng = np.random.default_rng(2)
    n = 200
    theta = rng.uniform(cfg.theta_min, cfg.theta_max, n)
    y = rng.normal(0, 30, n)
    s0 = rng.uniform(1, 50, n)
    r_nom = rng.uniform(1, 100, n)
    prior = rng.uniform(-2, 2, n)
    _, g = belief.loss_grad_theta(theta, y, s0, r_nom, prior, cfg)
    h = 1e-6
    num = (belief.loss_grad_theta(theta + h, y, s0, r_nom, prior, cfg)[0]
           - belief.loss_grad_theta(theta - h, y, s0, r_nom, prior, cfg)[0]) / (2 * h)
    np.testing.assert_allclose(g, num, rtol=1e-5, atol=1e-8)
    np.testing.assert_allclose(belief.grad_theta(theta, y, s0, r_nom, prior, cfg), g, rtol=1e-12, atol=1e-15)
    beta = np.linspace(0, 1, 101)
    r = belief.r_of_beta(beta, 4.0, cfg)
    assert np.all(np.diff(r) < 0) and r[-1] == pytest.approx(4.0)
    assert r[0] == pytest.approx(4.0 * cfg.r_inflation_max)
    # the data term's minimum is at consistency: S = y² (here s0 + R(β*) = y²)
    cfg0 = TightConfig(prior_weight=0.0)
    th = np.linspace(-6, 6, 20001)
    loss, _ = belief.loss_grad_theta(th, np.full_like(th, 20.0), np.full_like(th, 4.0), np.full_like(th, 9.0),
                                     np.zeros_like(th), cfg0)
    b = belief.sigmoid(th[np.argmin(loss)])
    assert 4.0 + belief.r_of_beta(b, 9.0, cfg0) == pytest.approx(400.0, rel=1e-2)


def _synthetic_epochs(rng: np.random.Generator, cfg: TightConfig, n: int, dt_s: float = 0.2,
                      bias: dict[int, tuple[float, int]] | None = None):
    """Corrected pseudoranges (σ_uniform noise) of a receiver moving by the filter's own process model
    (white acceleration, clock random walks), and its true states."""
    sysv, prn, pos, _ = _sats()
    slot = model.SLOT_OF[sysv]
    x = np.zeros(N_STATE)
    x[3:6] = (5.0, -3.0, 0.0)
    x[I_CLK + model.SLOT_OF[sysv]] = 1000.0
    x[I_DRIFT] = -50.0
    live = np.zeros(model.N_CLK)
    live[np.unique(slot)] = 1.0
    F = model.transition(dt_s, -dt_s * np.eye(3).ravel(), -0.5 * dt_s * dt_s * np.eye(3).ravel(), live)
    Q = model.process_noise(dt_s, -dt_s * np.eye(3).ravel(), live, cfg.sigma_acc_m_s2**2,
                            cfg.sigma_acc_vertical_m_s2**2, 0.0, 0.0, cfg.q_clock_m2_s, cfg.q_isb_m2_s,
                            cfg.q_drift_m2_s3)
    Q[I_HEADING:, I_HEADING:] = 0.0
    Lq = np.linalg.cholesky(Q + 1e-15 * np.eye(N_STATE))
    epochs, truth = [], []
    sig = cfg.sigma_uniform_m
    for k in range(n):
        if k:
            x = F @ x + Lq @ rng.standard_normal(N_STATE)
        pred, _, _ = model.pseudorange(x, FRAME, pos, slot)
        z = pred + rng.normal(0, sig, len(pred))
        for i, (b, k0) in (bias or {}).items():  # satellite i reflected (+b m) from epoch k0 on
            if k >= k0:
                z[i] += b
        ep = make_epoch(T0 + k * dt_s, sysv, prn, z, sat_pos_ecef_m=pos, cn0_dbhz=np.full(len(z), 45.0),
                        corrected=True)
        epochs.append(prepare_epoch(ep, FRAME, cfg))
        truth.append(x.copy())
    return epochs, truth


def test_out_of_sequence_epochs_equal_in_order():
    cfg = TightConfig.for_ground_vehicle(accuracy_floor_m=2.5)  # its DOPs re-fused too
    rng = np.random.default_rng(3)
    epochs, _ = _synthetic_epochs(rng, cfg, 40, bias={0: (30.0, 10)})
    t_us = [1_000_000 + 200_000 * k for k in range(len(epochs))]
    for method in ("second-order", "student-t", "fde"):
        a = _feed(cfg, method, epochs, t_us, list(range(len(epochs))))
        order = list(range(len(epochs)))
        for k in range(2, len(order) - 3, 5):  # several epochs arrive after later ones (up to 0.8 s late)
            order[k], order[k + 3] = order[k + 3], order[k]
        b = _feed(cfg, method, epochs, t_us, order)
        assert b.counts["gnss_out_of_order"] > 0 and b.counts["gnss_refused"] > 0
        assert len(a.entries) == len(b.entries)
        for ea, eb in zip(a.entries, b.entries, strict=True):
            assert ea.t_us == eb.t_us
            np.testing.assert_allclose(eb.x, ea.x, rtol=0, atol=1e-9)
            np.testing.assert_allclose(eb.P, ea.P, rtol=0, atol=1e-9)
            assert eb.fit.inflation() == pytest.approx(ea.fit.inflation(), rel=1e-9)
            for sa, sb, i in ((ea.scatter_h, eb.scatter_h, 0), (ea.scatter_v, eb.scatter_v, 1)):
                # the reported accuracy's snapshot floor (correlation, one snapshot's variance) re-fused too
                fa, fb = fix_floor(sa, ea.fix_var_m2[i]), fix_floor(sb, eb.fix_var_m2[i])
                assert fb == pytest.approx(fa, rel=1e-9) and sb.t_us == sa.t_us
            np.testing.assert_allclose(eb.delay_m2, ea.delay_m2, rtol=1e-9, atol=1e-12)  # the delay bias too
            qa, qb = ea.info.q_pos_ned, eb.info.q_pos_ned
            assert (qa is None) == (qb is None)
            if qa is not None:
                np.testing.assert_allclose(qb, qa, rtol=1e-12)
        assert a.entries[-1].info.q_pos_ned is not None
        assert fix_floor(a.entries[-1].scatter_h, a.entries[-1].fix_var_m2[0])[1] > 0.0  # a floor to compare
        assert max(a.entries[-1].delay_m2) > 0.0  # weights that differ by satellite: a delay bias
        assert a.counts["sat_used"] == b.counts["sat_used"]


def _feed(cfg: TightConfig, method: str, epochs, t_us, order, line_of_sight=None, eng=None,
          on_imu=None) -> TightEngine:
    """IMU (zero acceleration, 50 Hz) to the end first in chunks; epochs pushed in ``order``, each as
    soon as the IMU passed its validity (a late one after later ones); ``line_of_sight``: a map; ``eng``:
    this engine; ``on_imu(eng, t_us)``: called after each IMU sample."""
    eng = eng or TightEngine(cfg, method, frame=FRAME, line_of_sight=line_of_sight)
    eng.push_acc(0, 0.0, 0.0, 0.0)
    pushed = 0
    for i in order:
        target = max(t_us[j] for j in order[: order.index(i) + 1])
        while pushed < target:
            pushed += 20_000
            eng.push_acc(pushed, 0.0, 0.0, 0.0)
            if on_imu is not None:
                on_imu(eng, pushed)
        eng.push_epoch(t_us[i], epochs[i])
    return eng


def test_nees_and_nis_within_chi2_bounds_on_the_filters_own_model():
    cfg = TightConfig.for_ground_vehicle(sigma_clock0_m=1e3)
    rng = np.random.default_rng(7)
    runs, n = 40, 60
    nees, nis, m_tot = [], [], 0
    for _ in range(runs):
        epochs, truth = _synthetic_epochs(rng, cfg, n)
        t_us = [1_000_000 + 200_000 * k for k in range(n)]
        eng = _feed(cfg, "naive", epochs, t_us, list(range(n)))
        e = eng.entries[-1]
        d = (e.x - truth[-1])[0:6]
        nees.append(float(d @ np.linalg.solve(e.P[0:6, 0:6], d)))
        for ent in eng.entries[20:]:
            if ent.info.n_used:
                nis.append(ent.info.nis)
                m_tot += ent.info.n_used
    lo, hi = chi2.ppf([0.005, 0.995], 6 * runs) / runs
    assert lo < np.mean(nees) < hi, np.mean(nees)
    lo, hi = chi2.ppf([0.005, 0.995], m_tot) / m_tot
    assert lo < np.sum(nis) / m_tot < hi, np.sum(nis) / m_tot


def test_belief_falls_for_a_reflected_satellite_and_rises_for_clean_ones():
    cfg = TightConfig.for_ground_vehicle()
    rng = np.random.default_rng(5)
    first = _synthetic_epochs(rng, cfg, 1)[0][0]
    low = int(np.argmin(first.elevation_deg))  # NLOS: a low satellite, 4 times its σ model late after 10 s
    epochs, truth = _synthetic_epochs(rng, cfg, 100, bias={low: (4.0 * math.sqrt(first.r_model_m2[low]), 50)})
    t_us = [1_000_000 + 200_000 * k for k in range(100)]
    eng = _feed(cfg, "second-order", epochs, t_us, list(range(100)))
    info = eng.entries[-1].info
    beta = dict(zip(info.key.tolist(), info.beta.tolist(), strict=True))
    bad = int(epochs[0].key[low])
    clean = [b for k, b in beta.items() if k != bad]
    assert beta[bad] < 0.5 and min(clean) > beta[bad] + 0.25 and np.median(clean) > 0.9, (beta[bad], clean)
    # and the position is not dragged by the reflection
    err = np.linalg.norm(eng.entries[-1].x[0:2] - truth[-1][0:2])
    assert err < 3.0


def test_a_receiver_clock_jump_resets_the_clock_not_the_position():
    cfg = TightConfig.for_ground_vehicle()
    rng = np.random.default_rng(9)
    epochs, truth = _synthetic_epochs(rng, cfg, 40)
    jump = 1e-3 * 299_792_458.0  # a 1 ms receiver clock step
    epochs = epochs[:20] + [e._replace(z_m=e.z_m + jump) for e in epochs[20:]]
    eng = _feed(cfg, "second-order", epochs, [1_000_000 + 200_000 * k for k in range(40)], list(range(40)))
    n_systems = len(set(epochs[0].slot.tolist()))  # every system's clock stepped, once
    assert n_systems > 1 and eng.counts["clock_resets"] == n_systems and eng.counts["gnss_resets"] == 0
    assert np.linalg.norm(eng.entries[-1].x[0:3] - truth[-1][0:3]) < 5.0


def test_the_start_takes_the_vertical_velocitys_own_prior():
    """A car's vertical velocity starts within 0.2 m/s, a quadrotor's (and the horizontal) within 5 m/s;
    without Doppler the start's velocity is zero with those variances. A car (its truth climbing at
    0.1 m/s²/√Hz) keeps its vertical velocity through the first epochs' noise with the car's prior, not
    with the quadrotor's (20 seeds), and the tighter prior is honest: its errors within its σ."""
    car = TightConfig.for_ground_vehicle()
    assert (car.sigma_velocity0_m_s, car.sigma_velocity0_vertical_m_s) == (5.0, 0.2)
    assert TightConfig().sigma_velocity0_vertical_m_s == 5.0
    wide = TightConfig.for_ground_vehicle(sigma_velocity0_vertical_m_s=5.0)
    t_us = [1_000_000 + 200_000 * k for k in range(10)]
    err: dict[str, list[float]] = {"car": [], "wide": []}
    z2: list[float] = []
    for seed in range(20):
        epochs, truth = _synthetic_epochs(np.random.default_rng(100 + seed), car, 10)
        for name, cfg in (("car", car), ("wide", wide)):
            eng = _feed(cfg, "naive", epochs, t_us, list(range(10)))
            first, last = eng.entries[0], eng.entries[-1]
            want = [25.0, 25.0, cfg.sigma_velocity0_vertical_m_s**2]
            np.testing.assert_allclose(np.diag(first.P)[3:6], want)
            np.testing.assert_array_equal(first.x[3:6], 0.0)
            e = float(last.x[5] - truth[-1][5])
            err[name].append(abs(e))
            if name == "car":
                z2.append(e * e / float(last.P[5, 5]))
    assert np.mean(err["car"]) < 0.5 * np.mean(err["wide"]), err
    assert np.mean(z2) < chi2.ppf(0.999, 20) / 20, np.mean(z2)  # 20 one-dof NEES: within its χ² bound
    with pytest.raises(ValueError, match="sigma_velocity0_vertical_m_s"):
        TightConfig(sigma_velocity0_vertical_m_s=0.0).validate()


def test_satellite_cache_error_is_below_a_millimetre():
    cache = SatelliteCache(STORE, period_s=1.0)
    sysv, prn, _, _ = _sats()
    rng = np.random.default_rng(6)
    worst_p, worst_c = 0.0, 0.0
    for t in T0 + rng.uniform(0, 30, 20):
        a, b = cache.states(sysv, prn, np.full(len(sysv), t)), STORE.states(sysv, prn, np.full(len(sysv), t))
        worst_p = max(worst_p, float(np.abs(a.pos_ecef_m - b.pos_ecef_m).max()))
        worst_c = max(worst_c, float(np.abs(a.clock_s - b.clock_s).max()) * 3e8)
    assert worst_p < 1e-3 and worst_c < 1e-3, (worst_p, worst_c)


def test_navigator_on_raw_epochs_with_ephemerides_and_bad_input():
    nav = TightNavigator(TightConfig(), "second-order", ephemerides=STORE)
    n_ep = hold_at_rest(nav, STORE, 200)  # 4 s at 50 Hz, an epoch per 0.2 s (raw: clocks, atmosphere)
    nav.push(RawGnss(5_000_000, make_epoch(T0 + 4.0, [0], [1], [math.nan])))  # nothing usable
    nav.push(GnssFix(5_000_000, 52.5, 13.4, 60.0, 3, 10, 1.0, 1.0, 1.0))
    nav.push(Odometry(5_000_000, math.inf, 0.0))  # damaged (NaN alone: a gyro without a wheel speed)
    nav.push(Odometry(5_000_000, math.nan, math.nan))
    c = nav.counters()
    assert c["gnss_fused"] == n_ep - 1 and c["gnss_rejected_empty"] == 1 and c["gnss_fix_ignored"] == 1
    assert c["odometry_rejected"] == 2
    est = nav.estimate()
    assert est is not None and est.pos_valid
    t_now, x_now, P_now, _ = nav.engine.state_now()  # the C output path == the full prediction
    assert t_now == est.t_us
    np.testing.assert_allclose(np.r_[est.p_ned_m, est.v_ned_m_s], x_now[0:6], atol=1e-9)
    # the position variances reported: P's times the filter's measured consistency (≥ 1), floored by its
    # own snapshots' white and slow parts (consistency.snapshot_parts) and the one-signed delays' bias
    # (accuracy_delay_fraction² × the last snapshot's delay_m2); the velocities' as P's
    k = nav.accuracy_inflation()
    last = nav.engine.entries[-1]
    assert k == last.fit.inflation() >= 1.0
    floors = [snapshot_parts(last.scatter_h, last.fix_var_m2[0], last.kept[0])] * 2 + [
        snapshot_parts(last.scatter_v, last.fix_var_m2[1], last.kept[1])]
    f2 = TightConfig().accuracy_delay_fraction ** 2
    assert f2 > 0.0 and max(last.delay_m2) > 0.0  # the σ model's weights differ: a delay bias to report
    want = [snapshot_axis(float(P_now[i, i]), k, floors[i], f2 * last.delay_m2[i]) for i in range(3)]
    np.testing.assert_allclose(est.cov_diag[0:3], want, rtol=1e-9)
    assert (est.cov_diag[0:3] >= np.diag(P_now)[0:3] * k * (1 - 1e-12)).all()
    np.testing.assert_allclose(est.cov_diag[3:6], np.diag(P_now)[3:6], rtol=1e-9)
    p = nav.engine.frame.ecef(np.asarray(est.p_ned_m))
    assert np.linalg.norm(p - RX_ECEF) < 2.0
    with pytest.raises(ConfigError, match="second-order"):
        TightNavigator(TightConfig(), "adaptive")


def test_block_bootstrap_indices_are_contiguous_blocks():
    from gcs_tools.evaluate.tight import block_indices

    idx = block_indices(1000, 100, np.random.default_rng(0), 50)
    assert idx.shape == (50, 1000) and idx.min() >= 0 and idx.max() < 1000
    d = np.diff(idx[:, :100], axis=1)
    assert np.all(d == 1)  # the first block is 100 consecutive epochs


def test_smartloc_tight_rows_on_the_real_drive():
    """The smartLoc Berlin drive (real receiver, deep canyon): the per-satellite belief with the car's
    odometry against the single-point solution, fixed weights and C/N0 weighting (the goal: median
    ≤ 0.7×, p95 ≤ 0.5× the single-point solution's), and its β against the residuals at the truth."""
    import os
    from pathlib import Path

    from gcs_tools.evaluate.tight import run

    shared = Path(__file__).resolve().parents[1].parent / "shared"
    inp = shared / "data" / "urban" / "smartloc" / "Berlin_Potsdamer_Platz_Input.txt"
    if not inp.is_file():
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(f"the smartLoc data set is required in CI: {inp} is missing")
        pytest.skip(f"smartLoc data set not found at {inp} (shared directory beside the repository)")
    r = run(inp, None, n_resamples=200, rows=("naive", "second-order"), loose=False, no_odometry=False)
    rows, goals = r["rows"], r["goals"]["tight-second-order"]
    assert goals["median_ratio_to_spp"] <= 0.7 and goals["p95_ratio_to_spp"] <= 0.5, goals
    assert rows["tight-second-order"]["max_m"] < 40.0  # never diverging
    assert r["resets"]["tight-second-order"] == 0
    vs_naive = next(c for c in r["paired"] if c["reference"] == "tight-naive")
    assert vs_naive["median_diff_ci_m"][1] < 0 and vs_naive["p95_diff_ci_m"][1] < 0
    beta = {(b["residual_from_m"], b["residual_to_m"]): b["beta_median"] for b in r["belief_vs_residual"]}
    # (β scales the C/N0 + elevation σ model: a low reflected satellite needs less of a fall)
    assert beta[(-5.0, 5.0)] > 0.9 and beta[(40.0, math.inf)] < beta[(-5.0, 5.0)] - 0.15


def test_atmosphere_every_5_s_is_within_centimetres():
    from companion.gnss import transmission_states
    from companion.gnss.atmosphere import iono_frequency_scale, klobuchar_m, saastamoinen_m
    from companion.gnss.timescale import week_tow
    from companion.tight.satcache import AtmosphereCache

    cache = SatelliteCache(STORE, 5.0)
    atmo = AtmosphereCache(cache, FRAME.lat_rad, FRAME.lon_rad, FRAME.h_m, FRAME.r0_ecef_m, FRAME.c_ecef_ned,
                           STORE.klobuchar)
    worst_low, worst_high = 0.0, 0.0
    for t in T0 + np.arange(0.0, 10.0, 0.2):
        ep, _ = observe(STORE, t, RX_ECEF, mask_deg=5.0)
        st, t_tx = transmission_states(STORE, ep)
        got = atmo.delays_m(ep.system, ep.prn, t_tx)
        d = st.pos_ecef_m - RX_ECEF
        ned = d @ FRAME.c_ecef_ned / np.linalg.norm(d, axis=1)[:, None]
        el = np.arcsin(-ned[:, 2])
        az = np.arctan2(ned[:, 1], ned[:, 0]) % (2 * np.pi)
        want = saastamoinen_m(FRAME.lat_rad, FRAME.h_m, el) + klobuchar_m(
            *STORE.klobuchar, FRAME.lat_rad, FRAME.lon_rad, az, el, week_tow(ep.t_gps_s)[1]
        ) * iono_frequency_scale(ep.system)
        err = np.abs(got - want)
        high = el > math.radians(15)
        worst_high = max(worst_high, float(err[high].max()))
        worst_low = max(worst_low, float(err.max()))
    assert worst_high < 0.01 and worst_low < 0.05, (worst_high, worst_low)


def test_odometry_heading_starts_once_moving_and_follows_a_turn():
    """A car at rest for 8 s, then 8 m/s north-east, turning 90° right at 3°/s from 20 s: GNSS (5 m
    noise) + wheel speed and yaw rate with a 0.05°/s bias. The heading offset starts only once the
    car moves, and the track stays within metres."""
    eng, errs, psi, rest = _turning_car(speed_known=True)
    assert rest and max(rest) == 0.0  # no heading while at rest
    x = eng.entries[-1].x
    heading = math.atan2(x[4], x[3])
    assert abs((heading - psi + math.pi) % (2 * math.pi) - math.pi) < 0.1
    assert np.median(errs) < 2.5 and max(errs) < 8.0, (np.median(errs), max(errs))


def _turning_car(speed_known: bool, late: bool = False
                 ) -> tuple[TightEngine, list[float], float, list[float]]:
    """The car of the test above (at rest 8 s, then 8 m/s, a 90° right turn from 20 s), GNSS with 5 m
    noise and a yaw rate with a 0.05°/s bias, the wheel speed given or not (NaN: a gyro alone); ``late``:
    every fifth epoch arrives 0.4 s late (after the next two epochs and their odometry). Returns the
    engine, the horizontal errors after 12 s, the final heading and the heading's variance at rest."""
    cfg = TightConfig.for_ground_vehicle()
    rng = np.random.default_rng(11)
    sysv, prn, pos, _ = _sats()
    slot = model.SLOT_OF[sysv]
    eng = TightEngine(cfg, "cn0-elevation", frame=FRAME)
    dt, p, psi = 0.02, np.zeros(3), math.radians(45.0)
    eng.push_acc(0, 0.0, 0.0, 0.0)
    yaw_int, errs, held, rest = 0.0, [], [], []
    for k in range(1, 2000):  # 40 s at 50 Hz
        t = k * dt
        rate = math.radians(3.0) if 20.0 <= t < 50.0 and psi < math.radians(135.0) else 0.0
        speed = 0.0 if t < 8.0 else 8.0
        psi += rate * dt
        p = p + speed * dt * np.array([math.cos(psi), math.sin(psi), 0.0])
        t_us = 1_000_000 + int(round(t * 1e6))
        eng.push_acc(t_us, 0.0, 0.0, 0.0)
        yaw_int += (rate + math.radians(0.05)) * dt
        if k % 10 == 0:
            x = np.zeros(N_STATE)
            x[0:3] = p
            x[I_CLK + slot] = 1000.0
            pred, _, _ = model.pseudorange(x, FRAME, pos, slot)
            ep = make_epoch(T0 + t, sysv, prn, pred + rng.normal(0, cfg.sigma_uniform_m, len(pred)),
                            sat_pos_ecef_m=pos, cn0_dbhz=np.full(len(pred), 45.0), corrected=True)
            m = prepare_epoch(ep, FRAME, cfg)
            if late and k % 50 == 0:
                held.append((t_us, m))
            else:
                eng.push_epoch(t_us, m)
            # the odometry 10 ms after the epoch (a late epoch is re-fused before it, as in order)
            eng.push_acc(t_us + 10_000, 0.0, 0.0, 0.0)
            eng.push_speed(t_us + 10_000, speed if speed_known else math.nan, yaw_int)
            if late and held and t_us - held[0][0] >= 400_000:
                eng.push_epoch(*held.pop(0))
            if t < 8.0:
                rest.append(float(eng.entries[-1].P[I_HEADING, I_HEADING]))
            if t > 12.0:
                errs.append(float(np.hypot(*(eng.entries[-1].x[0:2] - p[0:2]))))
    return eng, errs, psi, rest


def test_a_gyro_alone_keeps_the_heading_and_the_car_on_its_track():
    """Without a wheel speed (NaN) the yaw rate still gives the heading, started from the filter's own
    velocity once it moves, and the car does not slide sideways: the track stays within metres, the
    heading follows the turn, and late epochs re-fused among the gyro's samples equal them in order."""
    eng, errs, psi, rest = _turning_car(speed_known=False)
    assert rest and max(rest) == 0.0  # no heading while at rest
    x = eng.entries[-1].x
    assert eng.entries[-1].P[I_HEADING, I_HEADING] > 0.0  # the heading started without a speed
    heading = math.atan2(x[4], x[3])
    assert abs((heading - psi + math.pi) % (2 * math.pi) - math.pi) < 0.1
    assert np.median(errs) < 2.5 and max(errs) < 8.0, (np.median(errs), max(errs))
    assert eng.counts.get("speed_fused", 0) > 100  # the lateral constraint was fused, not skipped
    late, _, _, _ = _turning_car(speed_known=False, late=True)
    assert late.counts["gnss_out_of_order"] > 0
    assert len(late.entries) == len(eng.entries)
    for ea, eb in zip(eng.entries, late.entries, strict=True):
        assert ea.t_us == eb.t_us
        np.testing.assert_allclose(eb.x, ea.x, rtol=0, atol=1e-9)
        np.testing.assert_allclose(eb.P, ea.P, rtol=0, atol=1e-9)


def test_c_belief_step_equals_the_numpy_forms():
    from companion.tight import _tight, weighting

    cfg = TightConfig()
    rng = np.random.default_rng(13)
    n = 50
    theta, hf, hs = rng.uniform(-4, 4, n), rng.uniform(0.1, 3, n), rng.uniform(0.1, 3, n)
    y, s0 = rng.normal(0, 30, n), rng.uniform(1, 50, n)
    r_nom, prior = rng.uniform(1, 100, n), rng.uniform(-2, 2, n)
    scales = []
    for first, scaled in ((False, False), (True, False), (False, True), (True, True)):
        got = _tight.belief_step(theta, hf, hs, y, s0, r_nom, prior, cfg.eta, cfg.lambda_reg, cfg.alpha_fast,
                                 cfg.alpha_slow, cfg.omega_fast, cfg.student_dof, cfg.r_inflation_max,
                                 cfg.prior_weight, cfg.theta_min, cfg.theta_max, cfg.gate_sigma**2, first,
                                 scaled, cfg.belief_early_factor)
        ye = belief.consistency_innovation(y, cfg)  # early innovations scaled (the gate sees y)
        sc = belief.epoch_scale(theta, ye, s0, r_nom, cfg) if scaled else 1.0
        scales.append(sc)
        g = belief.grad_theta(theta, ye, sc * s0, sc * r_nom, prior, cfg)
        th, f, s = (theta - cfg.eta * g, hf, hs) if first else belief.second_order_step(theta, hf, hs, g, cfg)
        th = np.clip(th, cfg.theta_min, cfg.theta_max)
        b = belief.sigmoid(th)
        r = belief.r_of_beta(b, r_nom, cfg)
        used = weighting.gate(weighting.SatTerms(np.zeros(n), y, s0, r_nom, prior), r, cfg)
        for a, w in zip(got, (th, f, s, b, r), strict=False):
            np.testing.assert_allclose(a, w, rtol=1e-12, atol=1e-14)
        assert np.array_equal(got[5] > 0, used)
    assert scales[2] > 1.5  # the scaled branch is exercised (an even count: the median of the middle two)
    assert 0.0 < cfg.belief_early_factor < 1.0 and (y < 0).sum() > 10  # the asymmetry is exercised


def test_belief_early_innovations_count_less():
    """A satellite late by 30 m loses more trust than one early by 30 m (NLOS only delays); with
    ``belief_early_factor`` = 1 they lose the same."""
    from companion.tight import _tight

    for early, sym in ((0.5, False), (1.0, True)):
        cfg = TightConfig(belief_early_factor=early)
        y = np.array([30.0, -30.0, 0.5, -0.5])
        th, hf, hs = np.full(4, 2.0), np.ones(4), np.ones(4)
        for _ in range(10):  # ten epochs of the same innovations
            th, hf, hs = _tight.belief_step(
                th, hf, hs, y, np.ones(4), np.full(4, 9.0), np.full(4, 2.0), cfg.eta, cfg.lambda_reg,
                cfg.alpha_fast, cfg.alpha_slow, cfg.omega_fast, cfg.student_dof, cfg.r_inflation_max,
                cfg.prior_weight, cfg.theta_min, cfg.theta_max, cfg.gate_sigma**2, False, False,
                cfg.belief_early_factor)[0:3]
        assert th[0] < 0.0 and th[1] < 0.0 and th[2] > 2.0 and th[3] > 2.0
        assert (th[0] == pytest.approx(th[1], abs=1e-12)) if sym else th[0] < th[1] - 0.5, th
    with pytest.raises(ValueError, match="belief_early_factor"):
        TightConfig(belief_early_factor=1.5).validate()


def test_belief_nominal_variance_is_the_sigma_model_scaled():
    """The belief's R at trust β is (belief_sigma_scale × the σ model's σ)² · k^(1 − β); the rows without a
    belief keep the σ model as it is."""
    from companion.tight import weighting

    rng = np.random.default_rng(5)
    n = 8
    t = weighting.SatTerms(np.arange(n), rng.normal(0, 3, n), np.full(n, 4.0), rng.uniform(4, 400, n),
                           np.full(n, 1.0))

    def solve(r, used):
        return np.zeros(n), np.eye(int(used.sum()))

    for scale in (0.5, 1.0):
        cfg = TightConfig(belief_sigma_scale=scale)
        w = weighting.make("second-order", cfg).weigh({}, t, solve)
        r_model = scale**2 * t.r_nominal
        np.testing.assert_allclose(w.r, r_model * cfg.r_inflation_max ** (1.0 - w.beta), rtol=1e-12)
        assert np.array_equal(weighting.make("cn0-elevation", cfg).weigh(None, t, solve).r, t.r_nominal)
    with pytest.raises(ValueError, match="belief_sigma_scale"):
        TightConfig(belief_sigma_scale=0.0).validate()


def c_core_inputs(rng: np.random.Generator, n: int) -> tuple[np.ndarray, float, np.ndarray, np.ndarray,
                                                               np.ndarray, tuple[float, ...]]:
    """(P (n, n), T, −A, −B (3, 3), live clocks, process noise densities) for the C core's tests."""
    A = rng.normal(size=(n, n))
    P = A @ A.T + np.eye(n)
    T = 0.2
    nA = -(T * np.linalg.qr(rng.normal(size=(3, 3)))[0])
    nB = 0.5 * T * nA
    live = np.array([1.0, 0.0, 1.0, 0.0, 0.0, 1.0])
    return P, T, nA, nB, live, (0.09, 0.01, 9e-6, 1e-4, 0.1, 1e-3, 0.5, 2.5e-5, 1e-8)


def test_c_core_equals_the_numpy_forms():
    """``_tight.c`` (the filter's hot path) against model.py's numpy forms: F P Fᵀ + Q, the
    pseudorange innovations with H, H P and (H P Hᵀ)_ii, and the stacked update with range rates."""
    from companion.tight import _tight

    rng = np.random.default_rng(12)
    P, T, nA, nB, live, q = c_core_inputs(rng, N_STATE)
    F = model.transition(T, nA.ravel(), nB.ravel(), live)
    want = F @ P @ F.T + model.process_noise(T, nA.ravel(), live, *q)
    got = _tight.predict_cov(P, T, nA.ravel(), nB.ravel(), live, *q, True)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
    # without process noise, F P Fᵀ exactly as the products summed over F's non-zero entries in column
    # order (what the C core does, and its dense loops with a zero skip did before)
    def sparse_product(A: np.ndarray, B: np.ndarray, transpose_b: bool) -> np.ndarray:
        out = np.zeros((N_STATE, N_STATE))
        for i in range(N_STATE):
            for k in range(N_STATE):
                s = 0.0
                for j in range(N_STATE):
                    if transpose_b:
                        if B[k, j] != 0.0:
                            s += A[i, j] * B[k, j]
                    elif A[i, j] != 0.0:
                        s += A[i, j] * B[j, k]
                out[i, k] = s
        return out

    exact = _tight.predict_cov(P, T, nA.ravel(), nB.ravel(), live, *(0.0,) * len(q), False)
    FP = sparse_product(F, P, False)
    assert np.array_equal(exact, sparse_product(FP, F, True))
    sysv, _, pos, vel = _sats()
    slot = model.SLOT_OF[sysv]
    x = _state(rng)
    z = model.pseudorange(x, FRAME, pos, slot)[0] + rng.normal(0, 5, len(slot))
    r0, C = FRAME.r0_ecef_m, FRAME.c_ecef_ned
    y, H, HP, s0, mins = _tight.innovations(x, P, r0, C, pos, slot.astype(float), z)
    for j in range(model.N_CLK):
        sel = slot == j
        assert mins[j] == (np.abs(y[sel]).min() if sel.any() else np.inf)
    pred, H_ref, _ = model.pseudorange(x, FRAME, pos, slot)
    np.testing.assert_allclose(y, z - pred, atol=1e-6)
    np.testing.assert_allclose(H, H_ref, atol=1e-12)
    np.testing.assert_allclose(HP, H_ref @ P, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(s0, np.einsum("ij,ij->i", H_ref @ P, H_ref), rtol=1e-12)
    used = rng.uniform(size=len(y)) > 0.2
    r = rng.uniform(4, 100, len(y))
    z_rate = model.range_rate(x, FRAME, pos, vel)[0] + rng.normal(0, 0.3, len(y))
    z_rate[::4] = np.nan  # some without Doppler
    r_rate = rng.uniform(0.05, 1.0, len(y))
    x_c, P_c, nis_c, n_rate = _tight.update(x, P, H, HP, y, r, used.astype(float), FRAME.r0_ecef_m,
                                            FRAME.c_ecef_ned, pos, vel, z_rate, r_rate, 25.0)
    u = np.flatnonzero(used)
    k = np.flatnonzero(used & np.isfinite(z_rate))
    pr, Hr = model.range_rate(x, FRAME, pos[k], vel[k])
    yr = z_rate[k] - pr
    g = yr**2 <= 25.0 * (np.einsum("ij,jk,ik->i", Hr, P, Hr) + r_rate[k])
    Hs = np.vstack((H_ref[u], Hr[g]))
    ys = np.concatenate((y[u], yr[g]))
    S = Hs @ P @ Hs.T + np.diag(np.concatenate((r[u], r_rate[k][g])))
    K = P @ Hs.T @ np.linalg.inv(S)
    np.testing.assert_allclose(x_c, x + K @ ys, rtol=1e-9, atol=1e-7)
    np.testing.assert_allclose(P_c, P - K @ Hs @ P, rtol=1e-9, atol=1e-9)
    assert n_rate == int(g.sum()) > 0 and nis_c == pytest.approx(float(ys @ np.linalg.solve(S, ys)), rel=1e-9)


def test_tight_rows_on_the_calibrated_simulator_open_loop():
    """A short canyon flight (the receiver calibrated to smartLoc): the tight rows estimate open loop
    from the same IMU and raw epochs; every row is scored, and tight coupling beats the receiver's
    own fixes (30 s of profile 3, seed 0)."""
    from gcs_tools.evaluate.tight_sim import fly_rows

    e = fly_rows("default", 3, 0, rows=("cn0-elevation", "second-order"), max_duration_s=30.0)
    outside = " (truth outside buildings)"
    assert set(e) == {"spp", "loose", "tight-cn0-elevation", "tight-second-order", "tight-second-order-map",
                      "tight-second-order-imperfect-map", "tight-second-order-map-free",
                      "tight-second-order-map" + outside, "tight-second-order-map-free" + outside}
    assert len(e["spp"]) > 300 and all(np.isfinite(v).all() for v in e.values())
    # the free-space row differs from the map row it constrains only where that one was inside a building
    assert len(e["tight-second-order-map" + outside]) == len(e["tight-second-order-map-free" + outside])
    assert np.median(e["tight-second-order"]) < 0.7 * np.median(e["spp"])


def test_tight_sim_without_cn0_changes_the_tight_rows_not_the_receiver():
    """``cn0_missing``: the tight rows get every epoch without C/N0 (NaN), the receiver and the flight
    are the same (fixes identical), so the C/N0-weighted row's errors differ."""
    from gcs_tools.evaluate.tight_sim import fly_rows

    seen: list[float] = []
    a = fly_rows("default", 3, 0, rows=("cn0-elevation",), max_duration_s=8.0, maps=False)
    b = fly_rows("default", 3, 0, rows=("cn0-elevation",), max_duration_s=8.0, maps=False, cn0_missing=True,
                 on_raw=lambda row, raw, nav: seen.append(float(raw.epoch.cn0_dbhz[0])))
    np.testing.assert_array_equal(a["spp"], b["spp"])
    assert len(a["spp"]) > 50 and seen and all(np.isfinite(seen))  # the receiver still reports C/N0
    assert not np.allclose(a["tight-cn0-elevation"], b["tight-cn0-elevation"])


def test_tight_sim_rate_hz_keeps_the_first_epoch_of_every_second():
    """``rate_hz``: the tight rows get one raw epoch per second (the receiver's 5 Hz otherwise)."""
    from gcs_tools.evaluate.tight_sim import fly_rows

    seen: dict[float | None, list[int]] = {}
    for rate in (None, 1.0):
        got = seen.setdefault(rate, [])
        fly_rows("default", 3, 0, rows=("cn0-elevation",), max_duration_s=4.0, maps=False, rate_hz=rate,
                 on_raw=lambda _row, raw, _nav, got=got: got.append(raw.t_us))
    assert len(seen[None]) >= 15
    assert len({t // 1_000_000 for t in seen[1.0]}) == len(seen[1.0]) >= 3
    assert set(seen[1.0]) <= set(seen[None])
