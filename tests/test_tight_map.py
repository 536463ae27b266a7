"""The map's line of sight as the per-satellite belief's prior, and the belief's leave-one-out
innovation: ray/box known answers, the prior's effect at start, out-of-sequence exactness with a map,
and one reflected satellite among clean ones."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.mission import load_mission
from companion.mission.city3d import City
from companion.tight import TightConfig, belief
from companion.tight.engine import TightEngine
from companion.wiring import mission_city, tight_navigator_for
from tests.test_tight import FRAME, _feed, _synthetic_epochs

BOX = City(np.array([[10.0, -5.0, 20.0, 5.0]]), np.array([30.0]))  # 10 m × 10 m, 30 m high, 10 m north


def test_line_of_sight_behind_a_box_above_it_and_grazing_a_corner():
    p = np.array([0.0, 0.0, -20.0])  # 20 m above the ground, 10 m south of the box
    az = np.radians([0.0, 0.0, 180.0, 90.0])
    el = np.radians([30.0, 60.0, 30.0, 30.0])
    # north at 30°: the ray enters at 10 m, 20 + 10 tan 30° = 25.8 m < 30 → hidden; at 60° 37.3 m → seen
    assert BOX.line_of_sight_blocked(p, az, el)[0].tolist() == [True, False, False, False]
    assert not BOX.line_of_sight_blocked(np.array([0.0, 0.0, -31.0]), az, el).any()  # above the roof
    # the roof's height exactly: the ray at 45° reaches 30 m at 10 m (entry): seen (a roof must be above)
    assert not BOX.line_of_sight_blocked(p, [0.0], [math.radians(45.0)])[0, 0]
    assert BOX.line_of_sight_blocked(p, [0.0], [math.radians(44.9)])[0, 0]
    # grazing: along the west wall (a wall is the box's: hidden), 1 mm west of it (seen); past the
    # south-east corner (10, 5) from (0, -5): 0.01° north of the diagonal the ray enters the south face,
    # 0.01° east of it the ray passes outside the corner
    low = np.radians([10.0, 10.0])
    along = BOX.line_of_sight_blocked(np.array([[0.0, -5.0, -5.0], [0.0, -5.001, -5.0]]), [0.0], low[:1])
    assert along[:, 0].tolist() == [True, False]
    q = np.array([0.0, -5.0, -5.0])
    assert BOX.line_of_sight_blocked(q, np.radians([44.99, 45.01]), low)[0].tolist() == [True, False]
    # many positions at once, (K, n), the same verdicts as one at a time
    pts = np.array([p, [0.0, 0.0, -31.0], [0.0, -5.0, -5.0]])
    many = BOX.line_of_sight_blocked(pts, az, el)
    assert many.shape == (3, 4)
    for k in range(3):
        np.testing.assert_array_equal(many[k], BOX.line_of_sight_blocked(pts[k], az, el)[0])


def test_blocked_probability_follows_the_position_uncertainty_and_the_signals():
    p = np.array([0.0, 0.0, -20.0])
    az, el = np.radians([0.0, 180.0]), np.radians([30.0, 30.0])
    sure = belief.blocked_probability(BOX.line_of_sight_blocked, p, np.eye(3) * 1e-4, az, el)
    np.testing.assert_allclose(sure, [1.0, 0.0])
    # 4 m (1σ) east: the candidates 0 and ±4 m east see the box (half-width 5 m), ±8 m do not;
    # Gaussian weights exp(−j²/2) at j = 0, ±1, ±2 σ
    w1, w2 = math.exp(-0.5), math.exp(-2.0)
    wide = belief.blocked_probability(BOX.line_of_sight_blocked, p, np.diag([1e-4, 16.0, 1e-4]), az, el)
    np.testing.assert_allclose(wide, [(1 + 2 * w1) / (1 + 2 * w1 + 2 * w2), 0.0])
    # the floor widens both axes: 8 m south the ray toward the north clears the roof (20 + 18 tan 30° > 30)
    floor = belief.blocked_probability(BOX.line_of_sight_blocked, p, np.zeros((3, 3)), az, el,
                                       sigma_floor_m=4.0)
    total = 1 + 2 * w1 + 2 * w2
    np.testing.assert_allclose(floor, [(total - w2) * (1 + 2 * w1) / total**2, 0.0])
    # shadow matching: a strong signal from the north (p_los 0.9) favours the candidates that see it
    p_los = np.array([0.9, 0.5])
    sm = belief.blocked_probability(BOX.line_of_sight_blocked, p, np.diag([1e-4, 16.0, 1e-4]), az, el, p_los)
    hid, seen = (1 + 2 * w1) * 0.1, 2 * w2 * 0.9
    np.testing.assert_allclose(sm, [hid / (hid + seen), 0.0])
    cfg = TightConfig(prior_map_nlos=-3.0, prior_map_los=1.0)
    np.testing.assert_allclose(belief.map_theta(np.array([1.0, 0.0, 0.75]), cfg), [-3.0, 1.0, -2.0])


def _hide(index_az_el):
    """A map hiding the satellites whose (azimuth, elevation) are in ``index_az_el``, from everywhere."""
    hidden = np.array(index_az_el)

    def los(p_ned_m, az, el):
        p = np.atleast_2d(p_ned_m)
        same = np.isclose(az[:, None], hidden[None, :, 0]) & np.isclose(el[:, None], hidden[None, :, 1])
        one = same.any(axis=1)
        return np.broadcast_to(one, (len(p), len(az)))

    return los


def test_a_satellite_the_map_hides_starts_with_a_lower_belief():
    cfg = TightConfig.for_ground_vehicle()  # the map's prior: +prior_map_los where it shows the satellite
    assert cfg.prior_map_los > cfg.prior_map_nlos
    epochs, _ = _synthetic_epochs(np.random.default_rng(11), cfg, 3)
    e0 = epochs[0]
    i = int(np.argmin(e0.elevation_deg))  # the lowest satellite: its prior is far from the clamp
    t_us = [1_000_000 + 200_000 * k for k in range(3)]
    nothing = _hide([(9.0, 9.0)])  # a map that hides no satellite
    seen = _feed(cfg, "second-order", epochs, t_us, [0, 1, 2], line_of_sight=nothing)
    hidden = _feed(cfg, "second-order", epochs, t_us, [0, 1, 2],
                   line_of_sight=_hide([(e0.azimuth_rad[i], math.radians(e0.elevation_deg[i]))]))
    a, b = seen.entries[1].info, hidden.entries[1].info  # the first fused epoch
    assert b.beta[i] < a.beta[i] - 0.1
    others = np.arange(len(a.beta)) != i
    np.testing.assert_allclose(b.beta[others], a.beta[others], atol=0.02)  # the others barely move


def test_out_of_sequence_epochs_with_a_map_equal_in_order():
    """The map is read at the predicted state at fusion: a late epoch re-fused gives the same result."""
    cfg = TightConfig.for_ground_vehicle(belief_innovation="leave-one-out", belief_student_iterations=2)
    rng = np.random.default_rng(3)
    epochs, _ = _synthetic_epochs(rng, cfg, 30, bias={0: (30.0, 10)})
    e0 = epochs[0]
    los = _hide([(e0.azimuth_rad[j], math.radians(e0.elevation_deg[j])) for j in (0, 2)])
    t_us = [1_000_000 + 200_000 * k for k in range(len(epochs))]
    a = _feed(cfg, "second-order", epochs, t_us, list(range(len(epochs))), line_of_sight=los)
    order = list(range(len(epochs)))
    for k in range(2, len(order) - 3, 5):
        order[k], order[k + 3] = order[k + 3], order[k]
    b = _feed(cfg, "second-order", epochs, t_us, order, line_of_sight=los)
    assert b.counts["gnss_out_of_order"] > 0
    for ea, eb in zip(a.entries, b.entries, strict=True):
        np.testing.assert_allclose(eb.x, ea.x, rtol=0, atol=1e-9)
        np.testing.assert_allclose(eb.P, ea.P, rtol=0, atol=1e-9)


@pytest.mark.parametrize("innovation", ["prefit", "leave-one-out", "snapshot"])
def test_one_reflected_satellite_loses_its_belief_within_a_second(innovation):
    cfg = TightConfig.for_ground_vehicle(belief_innovation=innovation)
    rng = np.random.default_rng(5)
    first = _synthetic_epochs(rng, cfg, 1)[0][0]
    low = int(np.argmin(first.elevation_deg))
    onset = 50  # from here the low satellite is reflected: 4 times its nominal σ late (inside the 5σ gate)
    late_m = 4.0 * math.sqrt(first.r_model_m2[low])
    epochs, truth = _synthetic_epochs(rng, cfg, 70, bias={low: (late_m, onset)})
    t_us = [1_000_000 + 200_000 * k for k in range(70)]
    eng = TightEngine(cfg, "second-order", frame=FRAME)
    bad = int(epochs[0].key[low])
    beta_bad, infos = [], []
    for k, (t, ep) in enumerate(zip(t_us, epochs, strict=True)):
        for j in range(10):  # IMU (zero acceleration, 50 Hz) up to the epoch
            eng.push_acc(t - 200_000 + 20_000 * (j + 1), 0.0, 0.0, 0.0)
        eng.push_epoch(t, ep)
        if k:
            infos.append(eng.entries[-1].info)
            beta_bad.append(dict(zip(infos[-1].key.tolist(), infos[-1].beta.tolist(), strict=True))[bad])
    assert min(beta_bad[: onset - 1]) > 0.6  # trusted while clean
    assert beta_bad[onset - 1 + 5] < 0.45  # 5 epochs (1 s) after the reflection starts
    last = infos[-1]
    clean = np.delete(last.beta, list(last.key).index(bad))
    assert np.median(clean) > 0.85 and clean.min() > 0.6
    assert np.linalg.norm(eng.entries[-1].x[0:2] - truth[-1][0:2]) < 3.0


def test_the_missions_map_reaches_the_tight_navigator():
    m = load_mission("test", "canyon")
    city = mission_city(m)
    assert len(city.height_m) == len(m.world.rects_m) > 0
    nav = tight_navigator_for(m, "second-order")
    assert nav.engine.line_of_sight is not None and nav.engine.frame is not None
    assert tight_navigator_for(m, "second-order", city=None).engine.line_of_sight is None
    imperfect = city.perturbed(np.random.default_rng(0), 2.5, 1.5)
    d_h = imperfect.height_m - city.height_m
    assert np.all(d_h != 0.0) and np.all(np.abs(d_h) < 15.0)
    np.testing.assert_allclose(imperfect.hi - imperfect.lo, city.hi - city.lo)  # moved, same footprint


def test_a_frame_other_than_the_missions_gets_the_map_moved_into_it():
    """The companion beside an autopilot runs in its --home frame (the SITL's home: a profile's start),
    not the mission's: the same places must see the same buildings. The line of sight at a point of
    that frame equals the mission map's at the same point in the mission frame, exactly (a
    translation); the loose map methods' clearance alike; the mission's own frame is not moved."""
    from companion.domain.geodesy import LocalNedFrame
    from companion.wiring import navigator_for

    m = load_mission("test", "canyon")
    o = np.array([47.0, 5.0, -1.5])  # that frame's origin in the mission's (1.5 m above its ground)
    frame = LocalNedFrame(*m.frame.to_geodetic(o))
    np.testing.assert_allclose(m.frame.to_ned_m(frame.home_lat_deg, frame.home_lon_deg, frame.home_alt_m), o,
                               atol=1e-6)
    theirs, ours = tight_navigator_for(m, "second-order").engine, tight_navigator_for(m, "second-order",
                                                                                      frame=frame).engine
    assert theirs.line_of_sight is not None and ours.line_of_sight is not None
    rng = np.random.default_rng(3)
    p_ours = np.column_stack((rng.uniform(-60, 60, 200), rng.uniform(-60, 60, 200),
                              rng.uniform(-25, -1, 200)))
    az, el = rng.uniform(0, 2 * np.pi, 12), np.radians(rng.uniform(5, 85, 12))
    hidden = ours.line_of_sight(p_ours, az, el)
    assert hidden.any() and not hidden.all()
    np.testing.assert_array_equal(hidden, theirs.line_of_sight(p_ours + o, az, el))
    moved = navigator_for(m, "map-beta", frame=frame).engine.method._clearance
    for n, e, _ in p_ours[:20]:
        assert moved(n, e) == pytest.approx(m.world.clearance_m(n + o[0], e + o[1]), abs=1e-9)
    assert navigator_for(m, "map-beta").engine.method._clearance == m.world.clearance_m


def test_a_whole_epoch_off_is_blamed_on_the_state_not_on_every_satellite():
    """Joint consistency: every pseudorange 30 m late at once (the receiver clock stepped: the prediction
    is off, not each satellite). Judged against the epoch's median, the beliefs hold; judged one by one
    against the prediction, every satellite loses trust."""
    cfg = TightConfig.for_ground_vehicle()
    assert cfg.belief_epoch_scale
    rng = np.random.default_rng(8)
    n_sat = len(_synthetic_epochs(rng, cfg, 1)[0][0].key)
    epochs, _ = _synthetic_epochs(rng, cfg, 32, bias={i: (30.0, 30) for i in range(n_sat)})
    t_us = [1_000_000 + 200_000 * k for k in range(32)]
    drop = {}
    for scaled in (True, False):
        eng = _feed(TightConfig.for_ground_vehicle(belief_epoch_scale=scaled), "second-order", epochs, t_us,
                    list(range(31)))
        before, at = eng.entries[-2].info.beta, eng.entries[-1].info.beta  # epochs 29 and 30 (the step)
        assert np.median(before) > 0.9
        drop[scaled] = float(np.median(before - at))
    assert drop[False] > 0.05 and drop[True] < 0.3 * drop[False], drop
