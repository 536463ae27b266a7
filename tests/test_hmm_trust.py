"""``hmm-trust``: the GNSS belief as the posterior of an HMM over trust levels (known answers)."""

import dataclasses
import math

import numpy as np
import pytest

from companion.estimator import METHODS
from companion.estimator.belief import InnovationTerms
from companion.estimator.config import EstimatorConfig
from companion.estimator.engine import FusionEngine
from companion.estimator.hmm_trust import (
    HmmTrust,
    interval_s,
    levels_of,
    posterior,
    predict,
    relaxation_factor,
    stationary,
)
from companion.estimator.methods import MethodContext
from companion.estimator.plugin_config import PluginConfig
from companion.mission import ConfigError, load_mission
from companion.wiring import mission_plugin_config, navigator_for
from tests.estimator_streams import (
    assert_out_of_order_equals_in_order,
    late_and_in_order,
    multipath_stream,
)

CFG = EstimatorConfig()
T_S = 0.05
Q_UNIT = 1.0 - math.exp(-2.0 * T_S / CFG.bias_tau_s)


def _terms(y, s0=(0.01, 0.01, 0.02), r=(0.0064, 0.0064, 0.0064)) -> InnovationTerms:
    return InnovationTerms(tuple(y), s0, Q_UNIT, r, (0.01, 0.01, 0.01))


def _plugin(**kw) -> PluginConfig:
    return dataclasses.replace(PluginConfig(), **kw)


def _method(plugin: PluginConfig) -> HmmTrust:
    return HmmTrust(CFG, MethodContext(plugin=plugin))


def _pdf(y: float, s: float) -> float:
    return math.exp(-0.5 * y * y / s) / math.sqrt(2 * math.pi * s)


def test_registered_and_interval_recovered():
    assert "hmm-trust" in METHODS
    assert interval_s(_terms((0, 0, 0)), CFG) == pytest.approx(T_S, rel=1e-12)


def test_two_level_posterior_by_hand():
    """Forward recursion of a 2-level HMM, written out by hand with scalar formulas."""
    plugin = _plugin(hmm_levels=2, hmm_beta_clean=1.0, hmm_beta_degraded=0.0, hmm_dwell_s=2.0)
    m = _method(plugin)
    ys = [(0.05, -0.02, 0.1), (1.0, 0.5, 0.0), (0.3, 0.2, -0.4), (0.0, 0.0, 0.0)]
    # level variances per axis: s0 + q σ_b² + k R_nom
    sb_clean, sb_deg = CFG.sigma_bias_floor_m, CFG.sigma_bias_max_m + CFG.sigma_bias_floor_m
    k_deg = CFG.r_inflation_max
    s0, r = (0.01, 0.01, 0.02), 0.0064
    S_clean = [s + Q_UNIT * sb_clean**2 + r for s in s0]
    S_deg = [s + Q_UNIT * sb_deg**2 + k_deg * r for s in s0]
    stay = math.exp(-T_S / 2.0)
    p_clean = 0.5  # stationary law of two levels with the same dwell time
    state = m.initial_state()
    assert state[0] == pytest.approx((0.5, 0.5)) and len(state) == 1  # one chain over all axes
    trajectory = []
    for y in ys:
        prior = p_clean * stay + (1.0 - p_clean) * (1.0 - stay)
        lc = np.prod([_pdf(v, s) for v, s in zip(y, S_clean, strict=True)])
        ld = np.prod([_pdf(v, s) for v, s in zip(y, S_deg, strict=True)])
        p_clean = prior * lc / (prior * lc + (1.0 - prior) * ld)
        R = m.measurement_cov(state, _terms(y))
        k = p_clean * 1.0 + (1.0 - p_clean) * k_deg
        assert pytest.approx((k * r, k * r, k * r), rel=1e-10) == R
        state = m.update(state, _terms(y))
        assert state[0][0] == pytest.approx(p_clean, rel=1e-10)
        assert m.beta(state) == pytest.approx(p_clean, rel=1e-10)  # β = P(clean) here
        trajectory.append(p_clean)
    # the sequence really moved the belief both ways: up on a small innovation, down on 1 m, up on 0
    assert trajectory[0] > 0.5 and trajectory[1] < 1e-6 and trajectory[3] > 10 * trajectory[2]


def test_chain_relaxes_to_its_stationary_law_at_the_second_eigenvalue():
    plugin = _plugin(hmm_levels=3, hmm_dwell_s=1.5, hmm_outlier_dwell_s=1.5)
    levels = levels_of(CFG, plugin)
    lam = relaxation_factor(levels, T_S)
    pi = (0.0, 1.0, 0.0)
    for n in range(1, 60):
        pi = predict(pi, levels, T_S)
        assert sum(pi) == pytest.approx(1.0, abs=1e-14)
        assert pi[0] == pytest.approx(1 / 3 - 1 / 3 * lam**n, abs=1e-12)
    # unequal dwell times: the stationary law is a fixed point; for short intervals π_j ∝ D_j
    levels = levels_of(CFG, _plugin(hmm_dwell_s=2.0, hmm_outlier_dwell_s=0.25))
    pi = stationary(levels, 0.37)
    assert predict(pi, levels, 0.37) == pytest.approx(pi, abs=1e-14)
    assert stationary(levels) == pytest.approx((2 / 4.25, 2 / 4.25, 0.25 / 4.25))
    assert stationary(levels, 1e-6) == pytest.approx(stationary(levels), abs=1e-6)


def test_recovery_is_bounded_after_any_run_of_bad_fixes():
    """1000 absurd fixes, then clean ones (y = 0): P(clean) never falls below the transition floor,
    and it climbs at least as fast as the worst-case recursion p ← g(max(e·p, floor))."""
    plugin = PluginConfig()
    m = _method(plugin)
    levels = m.levels
    stay = [math.exp(-T_S / lv.dwell_s) for lv in levels]
    floor = min((1.0 - s) / (len(levels) - 1) for s in stay)
    state = m.initial_state()
    for _ in range(1000):
        state = m.update(state, _terms((30.0, -30.0, 30.0)))
        assert predict(state[0], levels, T_S)[0] >= floor * (1 - 1e-12)
    assert m.beta(state) < 1e-6
    clean = _terms((0.0, 0.0, 0.0))
    ll = [sum(-0.5 * math.log(s0 + Q_UNIT * lv.sigma_bias_m**2 + lv.r_factor * r)
              for s0, r in zip(clean.s0, clean.r_nominal, strict=True)) for lv in levels]
    lr_min = min(math.exp(ll[0] - v) for v in ll[1:])  # worst likelihood ratio clean : other at y = 0
    assert lr_min > 1.0
    p_bound, n_bound = 0.0, None
    for n in range(1, 200):
        state = m.update(state, clean)
        q = max(stay[0] * p_bound, floor)
        p_bound = lr_min * q / (lr_min * q + 1.0 - q)
        assert state[0][0] >= p_bound - 1e-12
        if n_bound is None and p_bound > 0.9:
            n_bound = n
    assert n_bound is not None and n_bound <= 20  # back above 0.9 within 1 s of clean fixes at 20 Hz
    assert m.beta(state) > 0.9


def test_an_outlier_fix_is_downweighted_at_once():
    """A lone 3 m jump: the outlier level takes the posterior on that very fix, R is inflated by
    about the outlier factor, and the estimate moves much less than a fixed-β filter's."""
    stream = multipath_stream(np.random.default_rng(7), CFG, [(6.0, 0.0)])
    jump_at = 80
    moved = {}
    for name in ("hmm-trust", "fixed-beta"):
        e = FusionEngine(dataclasses.replace(CFG, beta_fixed=0.5, gnss_gate_sigma=1e3), name)
        j = 0
        for k, t in enumerate(stream.t_us.tolist()):
            e.push_acc(t, *stream.a_ned_m_s2[k].tolist())
            while j < len(stream.fix_t_us) and stream.fix_t_us[j] <= t:
                z = stream.z_ned_m[j] + (np.array([3.0, 0.0, 0.0]) if j == jump_at else 0.0)
                before = e.snapshot().x[0] if e.fusions else 0.0
                e.push_fix(int(stream.fix_t_us[j]), z)
                if j == jump_at:
                    moved[name] = e.snapshot().x[0] - before
                    if name == "hmm-trust":
                        post = e.fusions[-1].state[0]
                        assert post[2] > 0.99  # outlier level
                j += 1
    assert abs(moved["hmm-trust"]) < 0.2 * abs(moved["fixed-beta"])


def test_split_chains_keep_a_vertical_step_out_of_the_horizontal_trust():
    """With hmm_split_vertical a vertical outlier inflates only the vertical R; the joint chain
    inflates all three axes and drops β."""
    y = (0.01, -0.01, 2.0)
    split, joint = _method(_plugin(hmm_split_vertical=True)), _method(PluginConfig())
    s0, j0 = split.initial_state(), joint.initial_state()
    r_split, r_joint = split.measurement_cov(s0, _terms(y)), joint.measurement_cov(j0, _terms(y))
    assert len(s0) == 2 and r_split[2] > 10 * 0.0064 and r_joint[0] > 10 * 0.0064
    assert r_split[0] == r_split[1] < 1.5 * 0.0064
    assert split.beta(split.update(s0, _terms(y))) > 0.5 > joint.beta(joint.update(j0, _terms(y)))
    # the horizontal chain alone is the joint rule on the horizontal axes
    h = posterior(s0[0], _terms(y), split.levels, CFG, (0, 1))
    assert split.update(s0, _terms(y))[0] == h


def test_belief_follows_multipath_and_recovers():
    stream = multipath_stream(np.random.default_rng(3), CFG, [(4.0, 0.0), (4.0, 1.2), (6.0, 0.0)])
    e = FusionEngine(CFG, "hmm-trust")
    t_s, beta, j = [], [], 0
    for k, t in enumerate(stream.t_us.tolist()):
        e.push_acc(t, *stream.a_ned_m_s2[k].tolist())
        while j < len(stream.fix_t_us) and stream.fix_t_us[j] <= t:
            e.push_fix(int(stream.fix_t_us[j]), stream.z_ned_m[j])
            t_s.append(t * 1e-6)
            beta.append(e.snapshot().beta)
            j += 1
    t_s, beta = np.array(t_s), np.array(beta)
    assert beta[(t_s > 2) & (t_s < 4)].mean() > 0.9
    assert beta[(t_s > 5) & (t_s < 8)].mean() < 0.3
    assert beta[(t_s > 10)].mean() > 0.9


def test_out_of_order_equals_in_order():
    stream = multipath_stream(np.random.default_rng(3), CFG, [(4.0, 0.0), (4.0, 1.2)])
    m = load_mission("test")

    late, ref = late_and_in_order(
        stream, lambda: navigator_for(m, "hmm-trust", config=CFG).engine)
    assert_out_of_order_equals_in_order(late, ref)


@pytest.mark.parametrize("section, message", [
    ({"hmm_levels": 4}, "hmm_levels: must be 2 or 3"),
    ({"hmm_beta_clean": 0.3, "hmm_beta_degraded": 0.5}, "hmm_beta_degraded, hmm_beta_clean"),
    ({"hmm_dwell_s": 0.0}, "hmm_dwell_s: must be a finite number of seconds > 0"),
    ({"hmm_outlier_r_factor": 0.5}, "hmm_outlier_r_factor: must be finite and >= 1"),
])
def test_plugin_section_is_checked(section, message):
    m = load_mission("test")
    bad = dataclasses.replace(m, sections={**m.sections, "belief_plugins": section})
    with pytest.raises(ConfigError, match=message):
        mission_plugin_config(bad)
