"""Ablation plugins: fixed-beta, map-beta (map-scheduled β), windowed-ml (windowed-likelihood β)."""

import dataclasses

import numpy as np
import pytest

from companion.estimator import METHODS
from companion.estimator.belief import InnovationTerms, s_of_beta
from companion.estimator.config import EstimatorConfig
from companion.estimator.engine import FusionEngine
from companion.estimator.map_beta import scheduled_beta
from companion.estimator.methods import MethodContext
from companion.estimator.plugin_config import PluginConfig
from companion.estimator.windowed_ml import window_nll
from companion.mission import ConfigError, load_mission
from companion.wiring import mission_plugin_config, navigator_for
from tests.estimator_streams import (
    assert_out_of_order_equals_in_order,
    drive,
    late_and_in_order,
    multipath_stream,
)

CFG = EstimatorConfig()


@pytest.fixture(scope="module")
def stream():
    return multipath_stream(np.random.default_rng(3), CFG, [(4.0, 0.0), (4.0, 1.2)])


def test_registered():
    assert {"fixed-beta", "map-beta", "windowed-ml"} <= set(METHODS)


def test_fixed_beta_at_full_trust_is_naive_exactly(stream):
    """β = 1: R(1) = R_nom and σ_b(1) — the naive filter, bit for bit."""
    a = drive(stream, FusionEngine(CFG, "fixed-beta"), stream.fix_t_us.copy()).snapshot()
    b = drive(stream, FusionEngine(CFG, "naive"), stream.fix_t_us.copy()).snapshot()
    assert a.x == b.x and a.var == b.var
    half = dataclasses.replace(CFG, beta_fixed=0.5)
    c = drive(stream, FusionEngine(half, "fixed-beta"), stream.fix_t_us.copy())
    assert c.snapshot().beta == 0.5 and c.snapshot().x != a.x


def test_map_schedule_known_values():
    p = PluginConfig(map_beta_open=0.9, map_beta_canyon=0.2, map_d_near_m=15.0, map_ramp_m=10.0)
    assert scheduled_beta(p, 30.0) == pytest.approx(0.9)
    assert scheduled_beta(p, 10.0) == pytest.approx(0.55)
    assert scheduled_beta(p, 2.0) == pytest.approx(0.2)


def _mission_stream_engine(method: str, plugin_section: dict | None = None) -> tuple[FusionEngine, object]:
    m = load_mission("test")
    if plugin_section:
        m = dataclasses.replace(m, sections={**m.sections, "belief_plugins": plugin_section})
    nav = navigator_for(m, method, config=CFG)
    return nav.engine, m


def test_map_beta_follows_the_clearance_of_the_previous_posterior(stream):
    engine, m = _mission_stream_engine("map-beta", {"map_d_near_m": 1000.0, "map_ramp_m": 2000.0})
    drive(stream, engine, stream.fix_t_us.copy())
    cfg = mission_plugin_config(m)
    fusions = engine.fusions
    assert len(fusions) > 20
    # (entry 0 is the history's re-based anchor, not the posterior the next fix saw)
    for prev, cur in zip(fusions[1:-1], fusions[2:], strict=True):
        d = float(m.world.clearance_m(prev.x[0], prev.x[1]))
        assert cur.beta == pytest.approx(scheduled_beta(cfg, d), abs=1e-12)
    assert len({round(f.beta, 9) for f in fusions}) > 5  # the schedule really moves β


def test_map_beta_without_a_map_is_open_sky(stream):
    """Open sky everywhere only when asked for (a map without buildings); no map at all is an error."""
    open_sky = MethodContext(clearance_m=lambda north_m, east_m: float("inf"))
    e = drive(stream, FusionEngine(CFG, "map-beta", context=open_sky), stream.fix_t_us.copy())
    assert {f.beta for f in e.fusions} == {PluginConfig().map_beta_open}
    for method in ("map-beta", "map-hmm"):
        with pytest.raises(ConfigError, match=f"'{method}' needs the mission's map"):
            FusionEngine(CFG, method)
        with pytest.raises(ConfigError, match="needs the mission's map"):
            navigator_for(None, method)


@pytest.mark.parametrize("method", ["map-beta", "windowed-ml"])
def test_out_of_order_equals_in_order(stream, method):
    far = {"map_d_near_m": 1000.0, "map_ramp_m": 2000.0}
    late, ref = late_and_in_order(stream, lambda: _mission_stream_engine(method, far)[0])
    assert_out_of_order_equals_in_order(late, ref)


def test_windowed_likelihood_is_minimal_at_the_consistent_trust():
    """Gaussian NLL per axis is minimal where S(β) = y²: build a window whose innovations are exactly
    consistent with β₀ = 0.3 and the grid minimiser is β₀."""
    cfg = dataclasses.replace(CFG, loss="gaussian")
    window = []
    for k in range(10):
        t = InnovationTerms((0.0, 0.0, 0.0), (0.01 + 0.001 * k,) * 3, 0.03, (0.0064,) * 3, (0.01,) * 3)
        S, _ = s_of_beta(0.3, t, cfg)
        window.append(t._replace(y=tuple(float(np.sqrt(s)) for s in S)))
    grid = np.linspace(0.0, 1.0, 41)  # 0.3 is a grid point
    nll = window_nll(grid, tuple(window), cfg)
    assert grid[int(np.argmin(nll))] == pytest.approx(0.3)
    # and the loss agrees with the scalar belief loss at one β (its consistency part)
    from companion.estimator.belief import loss_grad

    no_smooth = dataclasses.replace(cfg, lambda_smooth_1_m=0.0)
    direct = sum(loss_grad(0.7, t, no_smooth)[0] for t in window)
    assert window_nll(np.array([0.7]), tuple(window), cfg)[0] == pytest.approx(direct, rel=1e-12)
    # with the bias-level term too (a receiver scale and a bias estimate per fix)
    level = dataclasses.replace(no_smooth, lambda_bias_level=2.0)
    window = [t._replace(bias_scale=1.5, bias_m2=(0.1 * k, 0.2, 0.3)) for k, t in enumerate(window)]
    direct = sum(loss_grad(0.7, t, level)[0] for t in window)
    assert window_nll(np.array([0.7]), tuple(window), level)[0] == pytest.approx(direct, rel=1e-12)


def test_windowed_ml_lowers_trust_under_multipath(stream):
    """Clean GNSS for 4 s, then a 1.2 m Gauss-Markov bias: the window's β drops."""
    e = FusionEngine(CFG, "windowed-ml")
    t_s, beta = [], []
    for i, t in zip(stream.fix_index.tolist(), stream.fix_t_us.tolist(), strict=True):
        for k in range(max(0, i - 9), i + 1):
            if not e.imu.t_us or stream.t_us[k] > e.imu.t_us[-1]:
                e.push_acc(int(stream.t_us[k]), *stream.a_ned_m_s2[k].tolist())
        e.push_fix(int(t), stream.z_ned_m[len(t_s)])
        t_s.append(t * 1e-6)
        beta.append(e.snapshot().beta)
    t_s, beta = np.array(t_s), np.array(beta)
    assert beta[(t_s > 2.0) & (t_s < 4.0)].mean() > beta[t_s > 6.0].mean() + 0.2


def test_plugin_section_is_checked():
    m = load_mission("test")
    bad = dataclasses.replace(m, sections={**m.sections, "belief_plugins": {"window_gain": 2.0}})
    with pytest.raises(ConfigError, match="belief_plugins: window_gain"):
        mission_plugin_config(bad)
