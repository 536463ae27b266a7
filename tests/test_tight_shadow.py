"""Shadow matching as a position measurement (companion.tight.shadow): known answers in a single street
between two long buildings, the flat grid prior, out-of-sequence exactness, and off by default."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from companion.mission.city3d import City
from companion.tight import TightConfig, belief, shadow
from tests.test_tight import _feed, _synthetic_epochs

# a street along north, 16 m wide (east −8 … 8), between two buildings 30 m high and 1 km long
STREET = City(np.array([[-500.0, -60.0, 500.0, -8.0], [-500.0, 8.0, 500.0, 60.0]]), np.array([30.0, 30.0]))
HEIGHT_M = 2.0  # the receiver's height (NED p_D = −2)
# satellites: east and west of the street high up (seen or hidden depending on the side), one near the
# zenith and two along the street (seen from everywhere in it)
AZ_DEG = np.array([90.0, 90.0, 90.0, 270.0, 270.0, 270.0, 0.0, 0.0, 180.0])
EL_DEG = np.array([70.0, 72.0, 75.0, 70.0, 72.0, 75.0, 88.0, 30.0, 40.0])
# P(line of sight) = σ(θ_prior) itself (not recalibrated): the known answers below in the prior's logits
CFG = TightConfig(shadow_matching=True, shadow_spacing_m=1.0, shadow_logit_scale=1.0, shadow_logit_offset=0.0)


def _signals(p_ned_m: np.ndarray) -> np.ndarray:
    """The prior logits of the signals received at ``p_ned_m``: 45 dB-Hz in line of sight, 25 hidden."""
    hidden = STREET.line_of_sight_blocked(p_ned_m, np.radians(AZ_DEG), np.radians(EL_DEG))[0]
    return belief.theta_prior(np.where(hidden, 25.0, 45.0), EL_DEG, CFG)


def _fix(truth_e_m: float, cfg: TightConfig = CFG, P: np.ndarray | None = None) -> shadow.ShadowFix | None:
    pred = np.array([0.0, 0.0, -HEIGHT_M])  # predicted in the middle of the street
    P = np.diag([25.0, 25.0, 25.0]) if P is None else P
    return shadow.shadow_fix(STREET.line_of_sight_blocked, pred, P, np.radians(AZ_DEG), np.radians(EL_DEG),
                             _signals(np.array([10.0, truth_e_m, -HEIGHT_M])), cfg)


def test_the_east_satellites_are_seen_from_the_west_side_only():
    """The geometry the known answers rest on: the 70-75° east satellites clear the east roof
    (30 m) from east < 8 − 28 / tan 70° = −2.19 m, the west ones clear the west roof from east > 2.19 m."""
    az, el = np.radians(AZ_DEG), np.radians(EL_DEG)
    west = STREET.line_of_sight_blocked(np.array([0.0, -5.0, -HEIGHT_M]), az, el)[0]
    east = STREET.line_of_sight_blocked(np.array([0.0, 5.0, -HEIGHT_M]), az, el)[0]
    assert west.tolist() == [False, False, False, True, True, True, False, False, False]
    assert east.tolist() == [True, True, True, False, False, False, False, False, False]
    edge = 8.0 - 28.0 / math.tan(math.radians(70.0))
    assert not STREET.line_of_sight_blocked(np.array([0.0, edge - 0.01, -HEIGHT_M]), az[:1], el[:1])[0, 0]
    assert STREET.line_of_sight_blocked(np.array([0.0, edge + 0.01, -HEIGHT_M]), az[:1], el[:1])[0, 0]


@pytest.mark.parametrize("side", [-1.0, 1.0])
def test_the_posterior_lands_on_the_true_side_narrow_across_wide_along(side):
    """Truth 5 m from the middle: the candidates whose shadows match the signals are those of the
    truth's side between the wall (8 m) and 2.19 m (the 70° satellite's edge): on the 1 m grid
    ±{3 … 7} m, a flat posterior over them (mean ±5 m, variance 2 + 1/12 m² across), and along the street
    every candidate sees the same sky: no information, no row."""
    fix = _fix(5.0 * side)
    assert fix is not None
    # the known answer: equal weights on east = ±3 … ±7 (the building's inside hides every satellite);
    # ±2 m sees the 72° and 75° satellites but not the 70° one: weight e^−3.75 (that signal's logit), ~2 %
    assert fix.mean[1] == pytest.approx(5.0 * side, abs=0.05)
    assert fix.cov[1, 1] == pytest.approx(2.0 + 1.0 / 12.0, rel=0.1)
    assert fix.mean[1] * side > 2.19 and abs(fix.mean[1] - 5.0 * side) <= CFG.shadow_spacing_m
    assert fix.cov[0, 0] > 25.0 * fix.cov[1, 1]  # along the street: as wide as the grid
    assert fix.H.shape == (1, 2) and abs(fix.H[0, 1]) == pytest.approx(1.0)  # one row: across
    # the grid (3 σ of √(25 + 5²) m, 21 m) divided out: v_u = 1 / (1/v − 1/v₀), v₀ = 21 · 22 / 3 + 1/12
    v0 = 21 * 22 / 3.0 + 1.0 / 12.0
    v = float(fix.cov[1, 1])
    vu = 1.0 / (1.0 / v - 1.0 / v0)
    assert fix.z[0] * fix.H[0, 1] == pytest.approx(vu * fix.mean[1] / v, rel=1e-9)
    assert fix.R[0] == pytest.approx(CFG.shadow_variance_scale * vu, rel=1e-9)


def test_the_grid_prior_is_flat_not_the_filters_gaussian():
    """The same candidates (the grid clamped to its maximum half-width) give the same posterior whatever
    the predicted covariance: the filter's Gaussian does not weigh the candidates."""
    cfg = dataclasses.replace(CFG, shadow_half_width_min_m=12.0, shadow_half_width_max_m=12.0)
    a = _fix(-5.0, cfg, np.diag([400.0, 400.0, 25.0]))
    b = _fix(-5.0, cfg, np.diag([900.0, 900.0, 25.0]))
    assert a is not None and b is not None
    np.testing.assert_allclose(b.mean, a.mean, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b.cov, a.cov, rtol=0, atol=1e-12)
    pts, C0 = shadow.grid(np.zeros(2), np.diag([400.0, 400.0]), cfg)
    assert len(pts) == 25 * 25  # ±12 m at 1 m
    np.testing.assert_allclose(C0, np.eye(2) * (12 * 13 / 3.0 + 1.0 / 12.0), atol=1e-9)
    # an uninformative sky (every satellite seen everywhere): the posterior is the grid's, nothing fused
    w = belief.shadow_log_likelihood(np.zeros((len(pts), 3), bool), np.full(3, 0.9), 1.0)
    mean, cov = shadow.posterior(pts, w, cfg.shadow_spacing_m)
    np.testing.assert_allclose(mean, 0.0, atol=1e-9)
    np.testing.assert_allclose(cov, C0, atol=1e-9)


def test_the_recalibrated_line_of_sight_probability():
    cfg = TightConfig(shadow_logit_scale=0.5, shadow_logit_offset=-1.0)
    np.testing.assert_allclose(shadow.p_los(np.array([2.0, 0.0, -4.0]), cfg),
                               1.0 / (1.0 + np.exp(-np.array([0.0, -1.0, -3.0]))), rtol=1e-12)
    # the default's recalibration still finds the true side (the evidence weaker than σ(θ)'s)
    fix = _fix(-5.0, dataclasses.replace(CFG, shadow_logit_scale=0.9, shadow_logit_offset=-2.4))
    assert fix is not None and -8.0 < fix.mean[1] < -2.0


def test_the_gate_refuses_a_fix_far_from_a_confident_prediction():
    fix = _fix(-5.0)
    assert fix is not None
    assert shadow.passes_gate(fix, np.array([0.0, -4.0]), np.diag([4.0, 4.0]), 3.0)
    assert not shadow.passes_gate(fix, np.array([0.0, 6.0]), np.diag([0.04, 0.04]), 3.0)


def _street_epochs():
    """The synthetic receiver (tests.test_tight: moving north-east from the frame's origin) in a street
    along its track, the buildings 40 m high 6 m either side, its signals with C/N0 set by the street."""
    cfg = TightConfig.for_ground_vehicle(shadow_logit_scale=1.0, shadow_logit_offset=0.0)  # σ(θ) as is
    epochs, truth = _synthetic_epochs(np.random.default_rng(5), cfg, 30)
    # the track (5, −3) m/s: a street along it, modelled as a rotated frame's boxes is not a City; instead
    # buildings either side of the track's start, long enough for its 6 s
    city = City(np.array([[-200.0, -60.0, 200.0, -12.0], [-200.0, 6.0, 200.0, 60.0]]), np.array([40.0, 40.0]))
    out = []
    for e, x in zip(epochs, truth, strict=True):
        hidden = city.line_of_sight_blocked(x[0:3], e.azimuth_rad, np.radians(e.elevation_deg))[0]
        out.append(e._replace(theta_prior=belief.theta_prior(np.where(hidden, 25.0, 45.0), e.elevation_deg,
                                                             cfg)))
    return cfg, out, city


@pytest.mark.parametrize("stage", ["before", "after"])
def test_out_of_sequence_epochs_with_shadow_matching_equal_in_order(stage):
    """The fix is a function of the predicted state and the epoch: a late epoch re-fused gives the same."""
    base, epochs, city = _street_epochs()
    cfg = dataclasses.replace(base, shadow_matching=True, shadow_stage=stage, shadow_gate_sigma=5.0)
    t_us = [1_000_000 + 200_000 * k for k in range(len(epochs))]
    los = city.line_of_sight_blocked
    a = _feed(cfg, "second-order", epochs, t_us, list(range(len(epochs))), line_of_sight=los)
    assert a.counts.get("shadow_fused", 0) > 0  # the fix is there to re-fuse
    order = list(range(len(epochs)))
    for k in range(2, len(order) - 3, 5):
        order[k], order[k + 3] = order[k + 3], order[k]
    b = _feed(cfg, "second-order", epochs, t_us, order, line_of_sight=los)
    assert b.counts["gnss_out_of_order"] > 0
    assert len(a.entries) == len(b.entries)
    for ea, eb in zip(a.entries, b.entries, strict=True):
        np.testing.assert_allclose(eb.x, ea.x, rtol=0, atol=1e-9)
        np.testing.assert_allclose(eb.P, ea.P, rtol=0, atol=1e-9)


def test_off_by_default_leaves_the_estimate_bit_identical():
    """shadow_matching is off by default; off, its parameters change nothing; on without a map, nothing
    either; on with the map, the estimate moves (the comparison could fail)."""
    base, epochs, city = _street_epochs()
    assert not TightConfig().shadow_matching
    t_us = [1_000_000 + 200_000 * k for k in range(len(epochs))]
    order = list(range(len(epochs)))
    los = city.line_of_sight_blocked
    ref = _feed(base, "second-order", epochs, t_us, order, line_of_sight=los)
    odd = dataclasses.replace(base, shadow_spacing_m=0.5, shadow_tempering=0.3, shadow_stage="after")
    no_map = dataclasses.replace(base, shadow_matching=True)
    same = _feed(odd, "second-order", epochs, t_us, order, line_of_sight=los)
    for ea, eb in zip(ref.entries, same.entries, strict=True):
        assert np.array_equal(ea.x, eb.x) and np.array_equal(ea.P, eb.P)
    plain = _feed(base, "second-order", epochs, t_us, order)
    for ea, eb in zip(plain.entries, _feed(no_map, "second-order", epochs, t_us, order).entries, strict=True):
        assert np.array_equal(ea.x, eb.x) and np.array_equal(ea.P, eb.P)
    on = _feed(dataclasses.replace(base, shadow_matching=True, shadow_gate_sigma=5.0), "second-order", epochs,
               t_us, order, line_of_sight=los)
    assert on.counts.get("shadow_fused", 0) > 0
    assert not np.array_equal(on.entries[-1].x, ref.entries[-1].x)


def test_tight_sim_flies_the_shadow_matching_rows_on_request():
    """``--rows ...,second-order-map-sm``: the map row with shadow matching beside the map rows, on the
    same flight (its navigator's fixes counted), and the along/across-street errors of every tight row."""
    from gcs_tools.evaluate.tight_sim import fly_rows

    navs: dict[str, object] = {}
    across: dict[str, list[tuple[float, float]]] = {}
    e = fly_rows("default", 3, 0, rows=("second-order", "second-order-map-sm"), max_duration_s=20.0,
                 across=across, on_raw=lambda row, _raw, nav: navs.setdefault(row, nav))
    assert {"tight-second-order", "tight-second-order-map", "tight-second-order-map-sm"} <= set(e)
    assert "tight-second-order-imperfect-map-sm" not in e
    assert len(e["tight-second-order-map-sm"]) == len(e["tight-second-order-map"]) > 100
    counts = navs["second-order-map-sm"].engine.counts  # type: ignore[attr-defined]
    assert sum(counts.get(k, 0) for k in ("shadow_fused", "shadow_none", "shadow_rejected_gate")) > 0
    assert not any(k.startswith("shadow") for k in navs["second-order-map"].engine.counts)  # type: ignore[attr-defined]
    assert set(across) >= {"tight-second-order-map-sm"} and all(len(v) > 0 for v in across.values())


def test_a_grid_too_fine_for_its_width_is_refused_in_one_line():
    """0.1 m spacing over ±24 m would be 231,361 line-of-sight candidates an epoch: refused, not run."""
    with pytest.raises(ValueError, match="231361 candidates an epoch, at most 10000"):
        TightConfig(shadow_spacing_m=0.1).validate()
    TightConfig(shadow_spacing_m=0.5).validate()  # 97² = 9,409: accepted


@pytest.mark.parametrize(("section", "why"), [
    ({"shadow_spacing_m": 0.01}, "candidates an epoch, at most 10000"),
    ({"shadow_stage": "during"}, "expected one of ['before', 'after']"),
    ({"shadow_matching": "yes please"}, "expected true or false"),
    ({"accuracy_delay_fraction": -1}, "accuracy_delay_fraction: must be a finite number >= 0"),
])
def test_bad_new_tight_settings_in_a_config_file_are_one_line_errors(section, why):
    """The companion's --config ``tight:`` section with the new settings out of range: refused in one line."""
    from pathlib import Path

    from companion.errors import ConfigError
    from gcs_tools import companion_config

    with pytest.raises(ConfigError) as refused:
        companion_config.tight_config({"tight": section}, Path("companion.yaml"))
    assert why in str(refused.value) and "\n" not in str(refused.value)
