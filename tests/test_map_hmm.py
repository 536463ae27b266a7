"""``map-hmm``: the map's clearance as the prior of a two-level trust HMM (known answers)."""

import dataclasses
import math

import numpy as np
import pytest

from companion.estimator import METHODS
from companion.estimator.belief import InnovationTerms
from companion.estimator.config import EstimatorConfig
from companion.estimator.engine import FusionEngine
from companion.estimator.map_beta import canyon_weight, scheduled_beta
from companion.estimator.map_hmm import MapHmm, map_levels, map_posterior
from companion.estimator.methods import MethodContext
from companion.estimator.plugin_config import PluginConfig
from companion.mission import ConfigError, load_mission
from companion.wiring import mission_plugin_config, navigator_for
from tests.estimator_streams import (
    assert_out_of_order_equals_in_order,
    drive,
    late_and_in_order,
    multipath_stream,
)

CFG = EstimatorConfig()
T_S = 0.05
Q_UNIT = 1.0 - math.exp(-2.0 * T_S / CFG.bias_tau_s)
FAR = {"map_d_near_m": 1000.0, "map_ramp_m": 2000.0}  # the test city: w(d) moves with the position


def _terms(y, s0=(0.01, 0.01, 0.02), r=(0.0064, 0.0064, 0.0064)) -> InnovationTerms:
    return InnovationTerms(tuple(y), s0, Q_UNIT, r, (0.01, 0.01, 0.01))


def _plugin(**kw) -> PluginConfig:
    return dataclasses.replace(PluginConfig(), **kw)


class _Place:
    """A map whose clearance is whatever the test sets (the position reader is ignored)."""

    def __init__(self, clearance_m: float) -> None:
        self.clearance_m_now = clearance_m
        self.world = self

    def clearance_m(self, north_m: float, east_m: float) -> float:
        return self.clearance_m_now


def _method(plugin: PluginConfig, place: _Place) -> MapHmm:
    return MapHmm(CFG, MethodContext(plugin, place.world.clearance_m, lambda: (0.0, 0.0, 0.0)))


def _pdf(y: float, s: float) -> float:
    return math.exp(-0.5 * y * y / s) / math.sqrt(2 * math.pi * s)


def test_registered_and_weight_known_values():
    assert "map-hmm" in METHODS
    p = _plugin(map_d_near_m=15.0, map_ramp_m=10.0)
    assert [canyon_weight(p, d) for d in (30.0, 10.0, 2.0)] == pytest.approx([0.0, 0.5, 1.0])


def test_without_evidence_it_is_the_map_schedule_smoothed_over_the_dwell_time():
    """κ = 0, ε = 0: π_d relaxes to w(d) as 1 − e^(−t/D), so β → the map-beta schedule's β(d) exactly."""
    plugin = _plugin(map_beta_open=0.9, map_beta_canyon=0.2, mhmm_evidence=0.0, mhmm_dwell_s=1.0,
                     mhmm_prior_floor=0.0)
    place = _Place(10.0)  # w = 0.5 with d_near 15, ramp 10
    m = _method(plugin, place)
    state = m.initial_state()
    assert m.beta(state) == pytest.approx(0.9)  # open sky before the first fix
    for n in range(1, 101):
        state = m.update(state, _terms((5.0, -5.0, 5.0)))  # the innovation does not matter at κ = 0
        assert state[1] == pytest.approx(0.5 * (1.0 - math.exp(-n * T_S / 1.0)), rel=1e-12)
    assert m.beta(state) == pytest.approx(scheduled_beta(plugin, 10.0), abs=0.01 * 0.7)
    for _ in range(400):  # 25 dwell times in all: e^(−25) of the start remains
        state = m.update(state, _terms((0.0, 0.0, 0.0)))
    assert m.beta(state) == pytest.approx(scheduled_beta(plugin, 10.0), abs=1e-10)
    R = m.measurement_cov(state, _terms((0.0, 0.0, 0.0)))
    assert pytest.approx(tuple(CFG.r_factor(m.beta(state)) * 0.0064 for _ in range(3)), rel=1e-9) == R


def test_tempered_posterior_by_hand():
    """One step written out: map-prior prediction, then likelihoods to the power κ."""
    plugin = _plugin(map_beta_open=1.0, map_beta_canyon=0.0, mhmm_evidence=0.3, mhmm_dwell_s=2.0)
    levels = map_levels(CFG, plugin)
    s0, r = (0.01, 0.01, 0.02), 0.0064
    S_c = [s + Q_UNIT * CFG.sigma_bias_m(1.0) ** 2 + CFG.r_factor(1.0) * r for s in s0]
    S_d = [s + Q_UNIT * CFG.sigma_bias_m(0.0) ** 2 + CFG.r_factor(0.0) * r for s in s0]
    e = math.exp(-T_S / 2.0)
    pi, w = (0.7, 0.3), 0.8
    trajectory = []
    for y in [(0.05, -0.02, 0.1), (1.0, 0.5, 0.0), (0.0, 0.0, 0.0)]:
        pc, pd = e * pi[0] + (1 - e) * (1 - w), e * pi[1] + (1 - e) * w
        lc = np.prod([_pdf(v, s) for v, s in zip(y, S_c, strict=True)]) ** 0.3
        ld = np.prod([_pdf(v, s) for v, s in zip(y, S_d, strict=True)]) ** 0.3
        want = (pc * lc / (pc * lc + pd * ld), pd * ld / (pc * lc + pd * ld))
        pi = map_posterior(pi, w, _terms(y), levels, CFG, 0.3)
        assert pi == pytest.approx(want, rel=1e-10)
        trajectory.append(pi[0])
    assert trajectory[1] < 0.01 < trajectory[0] and trajectory[2] > trajectory[1]  # moved both ways


def test_evidence_can_overrule_the_map_and_recovery_is_bounded():
    """Open sky on the map (w = 0) but absurd fixes: the belief drops (the map's prior floor ε keeps
    the degraded level possible); after any run of them it returns above 0.9 within 1 s of clean
    fixes, because each prediction restores (1 − e)(1 − ε) of the clean level."""
    plugin = _plugin(map_beta_open=1.0, map_beta_canyon=0.0, mhmm_evidence=0.3, mhmm_dwell_s=1.0,
                     mhmm_prior_floor=0.05)
    m = _method(plugin, _Place(100.0))
    state = m.initial_state()
    floor = (1.0 - math.exp(-T_S / 1.0)) * 0.95
    for _ in range(1000):
        state = m.update(state, _terms((30.0, -30.0, 30.0)))
    assert m.beta(state) < 1e-3
    only_map = _method(dataclasses.replace(plugin, mhmm_prior_floor=0.0), _Place(100.0))
    s0 = only_map.initial_state()
    for _ in range(100):  # ε = 0 in open sky: the map rules the degraded level out, evidence cannot
        s0 = only_map.update(s0, _terms((30.0, -30.0, 30.0)))
    assert s0 == (1.0, 0.0)
    n = 0
    while m.beta(state) <= 0.9:
        state = m.update(state, _terms((0.0, 0.0, 0.0)))
        n += 1
        assert state[0] >= floor * (1 - 1e-12)
    assert n <= 20


def test_without_a_map_it_is_open_sky():
    stream = multipath_stream(np.random.default_rng(3), CFG, [(2.0, 0.0)])
    open_sky = MethodContext(clearance_m=lambda north_m, east_m: float("inf"))  # a map without buildings
    e = FusionEngine(CFG, "map-hmm", context=open_sky)  # PluginConfig defaults
    drive(stream, e, stream.fix_t_us.copy())
    assert e.fusions[-1].beta > 0.5  # clean prior, clean fixes


@pytest.mark.parametrize("evidence", [0.0, 0.3, 1.0])
def test_out_of_order_equals_in_order(evidence):
    stream = multipath_stream(np.random.default_rng(3), CFG, [(4.0, 0.0), (4.0, 1.2)])
    m = load_mission("test")
    m = dataclasses.replace(m, sections={**m.sections, "belief_plugins": {**FAR, "mhmm_evidence": evidence}})

    late, ref = late_and_in_order(
        stream, lambda: navigator_for(m, "map-hmm", config=CFG).engine)
    assert_out_of_order_equals_in_order(late, ref)
    assert len({round(f.beta, 6) for f in ref.fusions}) > 5  # β really moves


@pytest.mark.parametrize("section, message", [
    ({"mhmm_evidence": 1.5}, "mhmm_evidence: must be in \\[0, 1\\]"),
    ({"mhmm_evidence": float("nan")}, "mhmm_evidence: expected a finite number"),
    ({"mhmm_dwell_s": 0.0}, "mhmm_dwell_s: must be a finite number of seconds > 0"),
    ({"mhmm_prior_floor": 0.5}, "mhmm_prior_floor: must be in \\[0, 0.5\\)"),
])
def test_plugin_section_is_checked(section, message):
    m = load_mission("test")
    bad = dataclasses.replace(m, sections={**m.sections, "belief_plugins": section})
    with pytest.raises(ConfigError, match=message):
        mission_plugin_config(bad)
