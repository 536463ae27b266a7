"""Faults injected into the real quad106 log (tests/data/quad106.tlog, 140 s from log time 200 s
while it manoeuvres; the faults from 60 s into it): GNSS position jumps, a fading jump, heading jumps
of the autopilot's attitude, a slow ramp, a frozen receiver, repeated fixes. The helpers are those
of ``beliefnav bench robustness`` (``gcs_tools.bench.robustness``): ``deviation`` is the distance of
the estimate right after each fix to the nearer of the clean track and the track the receiver says,
so following a glitch and ignoring it both count as consistent and only a fly-away scores.

Stated bounds (docs/estimator.md, "Glitches on a real log"):

* a step is held (every stepped fix flagged, the estimate dead-reckoned on the receiver's velocity)
  for gnss_offset_max_s (5 s): a 2 s step leaves the estimate within 0.5 m of the clean replay, no
  reset; a longer one is then accepted (one reset: the position moves onto the fixes), and its end
  (the fixes back on the earlier track) is a return at once, not a second reset;
* a fading jump (100 m back to 0 over 20 s) is followed without a trap (within 3 m), with or without
  the receiver's velocity; without it a 30 m reflection fading over 10 s is told from a wrong heading
  (the fixes drift against an IMU that is right) and held on the IMU: within 5 m, also when the fault
  starts 20, 40 or 80 s into the window;
* a heading jump of the attitude (90°, 180°) is counted as an IMU/GNSS disagreement and the estimate
  stays within 1.5 m of the GNSS; with a coincident 100 m jump (the fly-away of a real log) no
  estimate leaves the GNSS-consistent track by more than the filter with its gates off, with or
  without the receiver's velocity, and no reset follows another within 10 s;
* a slow ramp (0.5 m/s for 20 s, then back) is followed; the 10 m jump back is a step: held until
  the gate, grown by dead reckoning, passes it or 5 s, then followed;
* a frozen fix (the position held 10 s) is rejected as frozen after 2 s, the estimate flagged
  invalid 5 s later, back within 0.5 m 1 s after;
* a fix received twice is a counted duplicate, the estimate identical.

naive and second-order run every case, adaptive and vbakf the jump with a heading fault and the fade
without a velocity (the gate, offsets and resets are the engine's, shared by all methods; test time).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from companion.domain.samples import GnssFix
from gcs_tools.bench import robustness as rb

T0_S = rb.T0_S
BOTH = ("naive", "second-order")


@pytest.fixture(scope="module")
def log() -> rb.Log:
    return rb.load()


@pytest.fixture(scope="module")
def clean(log):
    return rb.clean_track(log)


@pytest.fixture(scope="module")
def clean_runs(log):
    return {m: rb.replay(log, m) for m in ("naive", "adaptive", "vbakf", "second-order")}


def _dev_from_clean_run(r: rb.Replay, ref: rb.Replay) -> np.ndarray:
    assert np.array_equal(r.fix_t_s, ref.fix_t_s)
    return np.linalg.norm(r.p_ned_m[:, :2] - ref.p_ned_m[:, :2], axis=1)


@pytest.mark.parametrize("method", BOTH)
@pytest.mark.parametrize("size_m", [5.0, 30.0])
def test_a_short_step_is_held_on_the_receiver_velocity(log, clean_runs, method, size_m):
    r = rb.replay(rb.inject(log, rb.Glitch("step", size_m, 2.0)), method)
    dev = _dev_from_clean_run(r, clean_runs[method])
    inside = (r.fix_t_s >= T0_S) & (r.fix_t_s < T0_S + 2.0)
    assert dev.max() < 0.5 and r.counters["gnss_resets"] == 0 and r.counters["gnss_offsets"] == 1
    assert inside.sum() >= 9


@pytest.mark.parametrize("method", BOTH)
def test_a_long_step_is_accepted_after_5_s_and_its_end_returns_without_a_second_reset(log, clean, method):
    g = rb.Glitch("step", 30.0, 20.0)
    r = rb.replay(rb.inject(log, g), method)
    c = r.counters
    assert c["gnss_resets"] == 1 and c["gnss_offset_returns"] == 1 and c["gnss_offsets"] == 1
    assert T0_S + 5.0 <= r.resets_t_s[0] < T0_S + 6.0  # accepted once it lasted gnss_offset_max_s
    assert rb.deviation(r, clean, g).max() < 1.0
    on_track = (r.t_s > r.resets_t_s[0]) & (r.fix_t_s < T0_S + 20.0)  # on the stepped track meanwhile
    tc, pc = clean
    off_clean = np.linalg.norm(r.p_ned_m[on_track, :2] - np.column_stack(
        [np.interp(r.t_s[on_track], tc, pc[:, i]) for i in range(2)]), axis=1)
    assert off_clean.min() > 25.0


@pytest.mark.parametrize("method", BOTH)
@pytest.mark.parametrize("velocity", [True, False])
def test_a_fading_jump_is_followed_without_a_trap(log, clean, method, velocity):
    g = rb.Glitch("fade", 100.0, 20.0, fade_s=20.0)
    r = rb.replay(rb.inject(log, g, velocity), method)
    assert rb.deviation(r, clean, g).max() < 3.0


@pytest.mark.parametrize("method", ["naive", "adaptive", "vbakf", "second-order"])
def test_a_fading_reflection_without_a_receiver_velocity_is_held_on_the_imu(log, clean, method):
    """A reflection of 30 m fading over 10 s, no receiver velocity: the fixes drift at 3 m/s against
    an IMU that is right, which no heading error explains; held on the IMU from the step's opening,
    then accepted: at or below the filter with its gates off (it was 15.7 m against 9-13 m) and
    within 5 m of the GNSS-consistent track."""
    case = rb.glitch_case(log, clean, rb.Glitch("fade", 30.0, 10.0, fade_s=10.0), method, False)
    assert case["ok"], case
    assert case["deviation_max_m"] < 5.0


@pytest.mark.parametrize("t0_s", [20.0, 40.0, 80.0])
def test_the_fade_and_the_fly_away_at_other_moments_of_the_flight(log, clean, monkeypatch, t0_s):
    """The same faults starting elsewhere in the manoeuvres (no receiver velocity, naive): the 30 m
    fade at or below its gate-off bar, and a 100 m jump with a 180° heading fault held 40 s never taken
    for a fade (a sub-gate wobble of the real fixes is no ramp): within 3 m, its end returned."""
    monkeypatch.setattr(rb, "T0_S", t0_s)
    fade = rb.glitch_case(log, clean, rb.Glitch("fade", 30.0, 10.0, fade_s=10.0), "naive", False)
    assert fade["ok"], fade
    fly = rb.glitch_case(log, clean, rb.Glitch("jump + heading", 100.0, 40.0, heading_deg=180.0), "naive",
                         False)
    assert fly["ok"] and fly["deviation_max_m"] < 3.0 and fly["resets"] == 1, fly


@pytest.mark.parametrize("method", BOTH)
@pytest.mark.parametrize("heading_deg", [90.0, 180.0])
def test_a_heading_jump_is_a_counted_disagreement_and_no_fly_away(log, clean, method, heading_deg):
    g = rb.Glitch("heading", heading_deg=heading_deg, heading_s=30.0)
    r = rb.replay(rb.inject(log, g), method)
    assert r.counters["imu_gnss_disagreements"] >= 1 and r.counters["gnss_resets"] == 0
    assert rb.deviation(r, clean, g).max() < 1.5


@pytest.mark.parametrize("method", ["naive", "adaptive", "vbakf", "second-order"])
@pytest.mark.parametrize("velocity", [True, False])
def test_a_jump_with_a_heading_fault_stays_on_the_gnss_track(log, clean, method, velocity):
    """The real fly-away (a 100 m GNSS jump with a coincident 180° jump of the attitude, both held):
    no farther from the GNSS-consistent track than the filter with its gates off, no reset within
    10 s of another, and within 3 m with the receiver's velocity."""
    case = rb.glitch_case(log, clean, rb.Glitch("jump + heading", 100.0, 80.0, heading_deg=180.0), method,
                          velocity)
    assert case["ok"], case  # (its resets, if any, at least 10 s apart)
    # with the receiver's velocity within 3 m; without, never held on the IMU with the wrong heading
    # (2-3 m; adaptive and vbakf 13.7 m: their learned R lets the heading drag before the fixes win)
    assert case["deviation_max_m"] < (3.0 if velocity else 15.0)


@pytest.mark.parametrize("method", BOTH)
def test_a_slow_ramp_is_followed_and_its_jump_back_accepted_after_5_s(log, clean_runs, method):
    t_first = log.t0_us

    def ramp(fix: GnssFix, p: np.ndarray) -> GnssFix:
        t = (fix.t_validity_us - t_first) * 1e-6 - T0_S
        return rb.moved(log, fix, p + 0.5 * t * rb.DIAGONAL) if 0.0 <= t < 20.0 else fix

    r = rb.replay(rb.edit_fixes(log, ramp), method)
    dev = _dev_from_clean_run(r, clean_runs[method])
    inside = (r.fix_t_s >= T0_S) & (r.fix_t_s < T0_S + 20.0)
    assert dev[inside].max() < 0.5 * 20.0 + 1.0
    # the jump back opens the offset; held on the velocity, the fixes pass the gate grown meanwhile
    # (4.6 s) or are accepted at 5 s
    assert r.counters["gnss_offsets"] == 1 and r.counters["gnss_resets"] <= 1
    held = (r.fix_t_s >= T0_S + 20.5) & (r.fix_t_s < T0_S + 24.0)
    assert dev[held].min() > 8.0  # the jump back is a step to the filter: held ...
    assert dev[r.fix_t_s > T0_S + 26.0].max() < 0.5  # ... then accepted


@pytest.mark.parametrize("method", BOTH)
def test_a_frozen_fix_is_rejected_and_the_estimate_flagged(log, clean_runs, method):
    t_first = log.t0_us
    held: dict[str, GnssFix] = {}

    def frozen(fix: GnssFix, p: np.ndarray) -> GnssFix:
        t = (fix.t_validity_us - t_first) * 1e-6 - T0_S
        if not 0.0 <= t < 10.0:
            return fix
        first = held.setdefault("fix", fix)
        return dataclasses.replace(fix, lat_deg=first.lat_deg, lon_deg=first.lon_deg, alt_m=first.alt_m)

    bad = rb.edit_fixes(log, frozen)
    r = rb.replay(bad, method)
    assert r.counters["gnss_rejected_frozen"] > 30
    inside = (r.t_s > T0_S) & (r.t_s < T0_S + 10.0)
    assert not r.pos_valid[inside].all()  # > 5 s without a fused fix
    dev = _dev_from_clean_run(r, clean_runs[method])
    assert dev[r.fix_t_s > T0_S + 11.0].max() < 0.5


def test_a_repeated_fix_is_a_counted_duplicate(log, clean_runs):
    twice = []
    for s in log.samples:
        twice.append(s)
        if type(s) is GnssFix:
            twice.append(dataclasses.replace(s))
    r = rb.replay(rb.Log(tuple(twice), log.frame), "second-order")
    ref = clean_runs["second-order"]
    assert r.counters["gnss_rejected_duplicate"] == len(ref.fix_t_s)
    np.testing.assert_array_equal(r.p_ned_m[1::2], ref.p_ned_m)  # the repeat's row equals the row before
