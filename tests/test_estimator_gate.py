"""Innovation gate, glitch reset, validity time-out, receiver-reported R and the bound on learned R."""

import math

import numpy as np
import pytest

from companion.domain.geodesy import LocalNedFrame
from companion.domain.samples import AttitudeSample, GnssFix, ImuSample
from companion.estimator import METHODS, Navigator, engine, model
from companion.estimator.config import EstimatorConfig
from companion.estimator.engine import FusionEngine
from tests.estimator_streams import OPEN_SKY

CFG = EstimatorConfig()
HOME = LocalNedFrame(47.0, 8.0, 400.0)


def _still(e: FusionEngine, t0_us: int, t1_us: int) -> None:
    """Zero acceleration every 5 ms in (t0, t1]."""
    for t in range(t0_us + 5000, t1_us + 1, 5000):
        e.push_acc(t, 0.0, 0.0, 0.0)


def _engine(method: str = "naive", cfg: EstimatorConfig = CFG) -> FusionEngine:
    e = FusionEngine(cfg, method, context=OPEN_SKY)
    e.push_acc(0, 0.0, 0.0, 0.0)
    e.push_fix(0, (0.0, 0.0, 0.0))
    return e


def test_test_ratio_is_horizontal_nis_over_gate_squared_and_gate_is_exact():
    """Known answer: the ratio from the prior covariance and the floored R; just inside fuses, just
    outside not."""
    e = _engine()
    _still(e, 0, 50_000)
    P = model.predict_cov(e.fusions[0].P, 0.05, CFG.sigma_bias_m(CFG.beta_fixed), CFG)
    # the gate's S: H P⁻ Hᵀ + R with R floored at gnss_gate_r_floor_m (0.5 m > the nominal 0.08 m)
    s = np.diag(model.hmh(P)) + max(CFG.sigma_gnss_horizontal_m, CFG.gnss_gate_r_floor_m) ** 2
    edge = CFG.gnss_gate_sigma * math.sqrt(s[0])  # a north innovation exactly at the gate
    e.push_fix(50_000, (0.999 * edge, 0.0, 0.0))
    f = e.fusions[-1]
    assert f.test_ratio == pytest.approx(0.999**2, rel=1e-9) and not f.glitch
    assert e.counts["gnss_fused"] == 2 and e.counts["gnss_rejected_innovation"] == 0
    e2 = _engine()
    _still(e2, 0, 50_000)
    e2.push_fix(50_000, (1.001 * edge, 0.0, 0.0))
    g = e2.fusions[-1]
    assert g.test_ratio == pytest.approx(1.001**2, rel=1e-9) and g.glitch
    assert e2.counts["gnss_fused"] == 1 and e2.counts["gnss_rejected_innovation"] == 1
    assert g.x == tuple(e2.fusions[0].x)  # the prior: standing still, nothing fused


# paper-literal (comparison only) is left out: its belief climbs on the rejected fixes, and the
# grown covariance lets it accept the step just before the time-out (the gate works as designed).
def _clean_then(e: FusionEngine, t: int, seconds: float, z) -> int:
    """Fixes ``z`` at 20 Hz for ``seconds`` after ``t`` (zero acceleration); returns the end time."""
    t_end = t + int(seconds * 1e6)
    while t < t_end:
        _still(e, t, t + 50_000)
        t += 50_000
        e.push_fix(t, z)
    return t


# paper-literal (comparison only) is left out: its belief climbs on the rejected fixes, and the
# grown covariance lets it accept the step just before the time-out (the gate works as designed).
@pytest.mark.parametrize("method", [m for m in METHODS if m != "paper-literal"])
def test_a_step_opens_an_offset_and_leaves_the_estimate_alone_until_it_steps_back(method):
    """A 20 m step for 3 s in a consistent stream: the first stepped fix opens the offset (not
    fused), the others are fused relative to it (flagged, estimate untouched, position valid);
    the fix that steps back closes it. No reset."""
    e = _engine(method)
    t = _clean_then(e, 0, 3.0, (0.0, 0.0, 0.0))
    t_glitch = t
    while t < t_glitch + 3_000_000:
        t = _clean_then(e, t, 0.05, (20.0, 0.0, 0.0))
        f = e.fusions[-1]
        assert f.glitch and f.offset == pytest.approx((20.0, 0.0, 0.0), abs=1e-6)
        assert f.t_offset_us == t_glitch + 50_000
        snap = e.snapshot()
        assert abs(snap.x[0]) < 1e-6 and snap.pos_valid
    c = e.counts
    assert c["gnss_offsets"] == 1 and c["gnss_rejected_innovation"] == 1 and c["gnss_resets"] == 0
    t = _clean_then(e, t, 0.05, (0.0, 0.0, 0.0))
    f = e.fusions[-1]
    assert not f.glitch and f.offset is None and c["gnss_fused"] == 60 + 59 + 1 + 1


@pytest.mark.parametrize("method", ["naive", "second-order"])
def test_a_step_held_past_the_offset_limit_ends_in_one_reset(method):
    cfg = EstimatorConfig(gnss_offset_max_s=4.0)
    e = _engine(method, cfg)
    t = _clean_then(e, 0, 3.0, (0.0, 0.0, 0.0))
    t_glitch = t
    t_reset = None
    while t < t_glitch + 6_000_000:
        t = _clean_then(e, t, 0.05, (20.0, 0.0, 0.0))
        if t_reset is None and e.counts["gnss_resets"]:
            t_reset = t
    assert e.counts["gnss_resets"] == 1 and e.counts["gnss_offsets"] == 1
    assert t_reset - (t_glitch + 50_000) == cfg.gnss_offset_max_s * 1e6  # the offset opened at the first
    snap = e.snapshot()
    assert snap.x[0] == pytest.approx(20.0, abs=0.05) and not snap.glitch and snap.pos_valid


@pytest.mark.parametrize("method", ["naive", "second-order"])
def test_gnss_returning_after_an_outage_opens_no_offset(method):
    """2 s without fixes, then fixes 20 m away (a dead-reckoning drift, as far as the filter can
    tell): rejected without an offset (the stream was not consistent a moment ago), then one reset
    at the time-out: the returning GNSS wins."""
    e = _engine(method)
    t = _clean_then(e, 0, 3.0, (0.0, 0.0, 0.0))
    t_last = t
    _still(e, t, t + 2_000_000)
    t += 2_000_000
    while t < t_last + 6_000_000:
        t = _clean_then(e, t, 0.05, (20.0, 0.0, 0.0))
    c = e.counts
    assert c["gnss_offsets"] == 0 and c["gnss_resets"] == 1
    assert e.snapshot().x[0] == pytest.approx(20.0, abs=0.05)


def test_reset_matches_the_fix_and_its_r_and_reopens_velocity_and_imu_errors():
    x = tuple(float(v) for v in range(15))
    rng = np.random.default_rng(0)
    G = rng.standard_normal((15, 15))
    P = G @ G.T + 0.1 * np.eye(15)
    d = P.diagonal()
    xr, M = model.reset_to_fix(x, P, (1.0, 2.0, 3.0), (0.5, 0.5, 2.0), 0.04, vel_var_min_m2_s2=25.0,
                               imu_var_m2_s4=(d[9] + 1.0, 0.0))
    # without a receiver velocity: velocity and IMU error states keep their means
    assert xr == (1.0, 2.0, 3.0, 3.0, 4.0, 5.0, 0.0, 0.0, 0.0, 9.0, 10.0, 11.0, 12.0, 13.0, 14.0)
    np.testing.assert_allclose(model.hmh(M), np.diag([0.5, 0.5, 2.0]), atol=1e-15)
    assert M[3:6, 3:6].diagonal().tolist() == [max(d[i], 25.0) for i in range(3, 6)]
    assert M[9, 9] == d[9] + 1.0 and M[12:15, 12:15].diagonal().tolist() == d[12:15].tolist()
    # everything but the position-bias pair decorrelated
    off = M - np.diag(M.diagonal())
    assert np.count_nonzero(off) == 6 and np.all(np.linalg.eigvalsh(M) > 0)
    # with the receiver's velocity: north and east from it with its variance, the missing down kept
    xv, Mv = model.reset_to_fix(x, P, (1.0, 2.0, 3.0), (0.5, 0.5, 2.0), 0.04, (7.0, -8.0, math.nan),
                                (0.09, 0.09, math.nan), 25.0)
    assert xv[3:6] == (7.0, -8.0, 5.0) and Mv[3:6, 3:6].diagonal().tolist() == [0.09, 0.09, max(d[5], 25.0)]


def test_position_invalid_after_the_time_out_and_covariance_grows():
    e = _engine()
    _still(e, 0, 5_000_000)
    s = e.snapshot()
    assert s.pos_valid
    _still(e, 5_000_000, 5_010_000)
    s2 = e.snapshot()
    assert not s2.pos_valid and s2.var[0] > s.var[0]
    e.push_fix(5_010_000, (0.0, 0.0, 0.0))
    assert e.snapshot().pos_valid


def _fix(t_us, p_ned_m, h_acc_m=math.nan, v_acc_m=math.nan):
    lat, lon, alt = HOME.to_geodetic(np.asarray(p_ned_m, dtype=float))
    return GnssFix(t_us, lat, lon, alt, 3, 12, h_acc_m, v_acc_m)


def test_receiver_accuracy_sets_r_floored_at_the_config_else_learned():
    nav = Navigator(CFG, "naive", HOME)
    assert nav.fix_r_nominal_m2(1.5, 3.0) == (2.25, 2.25, 9.0)
    inf = math.inf  # not reported: the engine learns it (per component)
    assert nav.fix_r_nominal_m2(0.01, math.nan) == (CFG.sigma_gnss_horizontal_m**2,) * 2 + (inf,)
    assert nav.fix_r_nominal_m2(inf, -1.0) == (inf, inf, inf) == engine.LEARN
    nav.push(AttitudeSample(0, np.array([1.0, 0.0, 0.0, 0.0])))
    nav.push(ImuSample(0, np.array([0.0, 0.0, -CFG.gravity_m_s2]), np.zeros(3)))
    nav.push(_fix(0, (0.0, 0.0, 0.0), 2.0, 4.0))
    est = nav.estimate()
    np.testing.assert_allclose(est.cov_diag[0:3], [4.0, 4.0, 16.0], rtol=1e-9)  # P₀ = the fix's R


def test_learned_r_is_bounded():
    """adaptive on innovations of ~30 m std (gate widened so they reach it): R ≤ 100 R_nom."""
    cfg = EstimatorConfig(gnss_gate_sigma=1e6)
    e = _engine("adaptive", cfg)
    rng = np.random.default_rng(1)
    t = 0
    for _ in range(40):
        _still(e, t, t + 50_000)
        t += 50_000
        e.push_fix(t, tuple(rng.normal(0.0, 30.0, 3)))
    r_max = cfg.r_learned_max_factor * cfg.sigma_gnss_horizontal_m**2
    # the last fusion's R: recover it from the update of pp (pp⁺ = pp⁻ R'/(s)) via K
    terms_r = e.method.measurement_cov(e.fusions[-2].state, _terms_of(e))
    assert max(terms_r) > r_max  # what adaptive would learn unbounded
    f_prev, f = e.fusions[-2], e.fusions[-1]
    assert f.nis == pytest.approx(_nis_with_bounded_r(e, f_prev, f, r_max), rel=1e-9)


def _terms_of(e):
    from companion.estimator.belief import InnovationTerms
    f = e.fusions[-1]
    y = tuple(float(a - b) for a, b in zip(f.z_ned_m, np.array(e.fusions[-2].x[0:3]), strict=True))
    return InnovationTerms(y, (0.0, 0.0, 0.0), 0.0, e._r_nominal, (0.0, 0.0, 0.0))


def _nis_with_bounded_r(e, prev, f, r_max):
    T = (f.t_us - prev.t_us) * 1e-6
    x, P = e._predict(prev, f.t_us, f.ints)
    np.testing.assert_allclose(P, model.predict_cov(prev.P, T, prev.sigma_bias_m, CFG), rtol=1e-12)  # no turn
    y = np.array(f.z_ned_m) - np.array(x[0:3]) - np.array(x[6:9])
    return float(y @ np.linalg.solve(model.hmh(P) + r_max * np.eye(3), y))


@pytest.mark.parametrize("speed_m_s", [0.0, 2.0])
def test_frozen_fix_is_rejected_after_the_stated_time_when_moving(speed_m_s):
    nav = Navigator(CFG, "naive", HOME)
    nav.push(AttitudeSample(0, np.array([1.0, 0.0, 0.0, 0.0])))
    nav.push(ImuSample(0, np.array([0.0, 0.0, -CFG.gravity_m_s2]), np.zeros(3)))
    for k in range(1, 41):  # 2 s at speed_m_s north, fixes at 5 Hz
        t = k * 50_000
        nav.push(ImuSample(t, np.array([0.0, 0.0, -CFG.gravity_m_s2]), np.zeros(3)))
        if k % 4 == 0:
            nav.push(_fix(t, (speed_m_s * t * 1e-6, 0.0, 0.0)))
    p_frozen = (speed_m_s * 2.0, 0.0, 0.0)
    for k in range(41, 101):  # then 3 s of the same position
        t = k * 50_000
        nav.push(ImuSample(t, np.array([0.0, 0.0, -CFG.gravity_m_s2]), np.zeros(3)))
        if k % 4 == 0:
            nav.push(_fix(t, p_frozen))
    c = nav.counters()
    # repeats of the 2.0 s position at 2.2 ... 5.0 s: those > 2 s after it (4.2 ... 5.0 s: 5) are
    # frozen if the vehicle moved when that position first came
    assert c["gnss_rejected_frozen"] == (5 if speed_m_s else 0)


def _hold_obs(r_of_t, accel=lambda t: (0.0, 2.0 * math.sin(1.5 * t)), seconds: float = 2.0, hz: float = 5.0):
    """A held step's residuals as ``FusionEngine._hold_residual`` records them: (t, r_N, r_E, D_N, D_E),
    D the IMU's displacement since the opening (the double integral of ``accel``, 1 ms steps), r the
    fixes' drift against dead reckoning, ``r_of_t(t, D)``."""
    obs, v, d, k = [], np.zeros(2), np.zeros(2), 0
    step, every = 0.001, round(1.0 / hz / 0.001)
    while k * step <= seconds + 1e-9:
        if k % every == 0:
            t = k * step
            r = r_of_t(t, d.copy())
            obs.append((t, float(r[0]), float(r[1]), float(d[0]), float(d[1])))
        a = np.array(accel(k * step))
        d += v * step + 0.5 * a * step * step
        v += a * step
        k += 1
    return tuple(obs)


def _turned(deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c - 1.0, -s], [s, c - 1.0]])


def test_a_ramp_of_the_fixes_is_told_from_a_wrong_heading():
    """Known answers of the two-model test (a receiver of 0.3 m, the velocity at the opening known to
    0.25 m/s; noiseless drifts, the vehicle accelerating east, 2 sin(1.5 t) m/s²): fixes drifting at
    3 m/s against an IMU that is right are a ramp, whether the vehicle manoeuvres or hovers; a drift
    that is the IMU's displacement turned by 30°, 90° or 180° (plus a velocity error within its σ) is
    explained exactly by that heading and is no ramp; a constant step is neither; a ramp with a 180°
    heading on top looks like a ramp for 2 s and is found to be the IMU's by 3 s (the hold then
    returns to the fixes)."""
    e = _engine()
    ramp = np.array([-2.1, -2.1])  # 3 m/s, the diagonal

    def told(obs):
        return e._ramp_or_heading(obs, 0.09, 0.0625)

    assert told(_hold_obs(lambda t, d: ramp * t)) == (True, False)
    assert told(_hold_obs(lambda t, d: ramp * t, accel=lambda t: (0.0, 0.0))) == (True, False)
    for deg in (30.0, 90.0, 180.0):
        m = _turned(deg)
        obs = _hold_obs(lambda t, d, m=m: m @ d + np.array([0.2, -0.2]) * t)
        chi_ramp, chi_head, _, _ = e._hold_fit(obs, 0.09, 0.0625)
        assert chi_head < 1.0 < chi_ramp and not told(obs)[0], deg
    assert told(_hold_obs(lambda t, d: np.array([0.1, -0.1]))) == (False, False)
    both = _turned(180.0)
    assert told(_hold_obs(lambda t, d: ramp * t + both @ d, seconds=2.0)) == (True, False)
    assert told(_hold_obs(lambda t, d: ramp * t + both @ d, seconds=3.0)) == (False, True)
    # too few fixes to tell (4 are needed: the ramp has 4 parameters)
    assert told(_hold_obs(lambda t, d: ramp * t, seconds=0.4)) == (False, False)
    # a ramp of 0.1 m/s is within what the velocity's σ explains: not told
    assert told(_hold_obs(lambda t, d: ramp / 30.0 * t)) == (False, False)
