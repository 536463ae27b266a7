"""GNSS glitches injected into the real quad106 log (tests/data/quad106.tlog): each glitched replay
is compared with the clean replay of the same method (horizontal deviation, m).

Stated bounds (docs/estimator.md, "Glitches on a real log"); the glitch starts at T0 = 60 s into a
140 s window of the log (log time 260 s, the vehicle manoeuvring):

* a step of 5-30 m lasting 2-60 s: the first stepped fix opens a GNSS offset, the others are
  fused relative to it (every glitched fix flagged), deviation < 0.3 m (measured ≤ 0.07 m), no
  reset, the position stays valid; the fix that steps back closes the offset: back within 0.5 m
  1 s after the glitch;
* a slow ramp (0.5 m/s for 20 s, then back): followed (no innovation test sees it); the 10 m jump
  back is a step like any other (the filter cannot tell which side is right), so the estimate
  stays on the ramp's end until the offset limit gnss_offset_max_s (60 s; 20 s here), then one
  reset: back within 0.5 m 1 s after it;
* a frozen fix (the position held 10 s): rejected as frozen after 2 s, the estimate flagged invalid
  after 5 s more, back within 0.5 m 1 s after;
* a fix received twice: the repeat is a counted duplicate, the estimate identical;
* the belief methods: β back above 0.5 within 1 s of the glitch's end and staying above it, and
  above 0.75 at the end of the window (after a reset β may dip to ~0.8 for a few tens of seconds
  while velocity and the IMU error states settle; the clean replay ends at 0.98).

naive, adaptive and second-order run every case, vbakf and first-order the short steps (the gate,
offset and reset are the engine's, shared by all methods; test time).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from companion.domain.samples import GnssFix
from companion.estimator import EstimatorConfig
from tests.real_logs import Log, inject, load_quad106, run

T0_S = 60.0
METHODS = ("naive", "adaptive", "vbakf", "first-order", "second-order")
LONG = ("naive", "adaptive", "second-order")
DIAG = np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0)


@pytest.fixture(scope="module")
def log() -> Log:
    return load_quad106().window(200.0, 340.0)


@pytest.fixture(scope="module")
def clean(log):
    return {m: run(log, m) for m in METHODS}  # the clean replay of every method, once


def _step(m: float):
    return lambda t, p: p + m * DIAG


def _frozen():
    held: dict[str, np.ndarray] = {}
    return lambda t, p: held.setdefault("p", p)


def _glitched(log, clean, method, duration_s, offset, cfg=None):
    r = run(inject(log, T0_S, duration_s, offset), method, cfg)
    ref = clean[method]
    assert np.array_equal(r.t_s, ref.t_s)
    dev = np.linalg.norm(r.p_ned_m[:, :2] - ref.p_ned_m[:, :2], axis=1)
    return r, dev


def _back_within(r, dev, end_s, tol_m=0.5) -> float:
    after = r.t_s >= end_s
    ok = dev[after] < tol_m
    return float(r.t_s[after][np.argmax(ok)] - end_s) if ok.any() else np.inf


def _belief_recovers(r, ref, end_s):
    if r.beta.max() == r.beta.min():  # belief held (naive, adaptive, vbakf)
        return
    after = r.t_s >= end_s
    back = r.t_s[after][np.argmax(r.beta[after] > 0.5)]
    assert back - end_s < 1.0 and r.beta[r.t_s >= back].min() > 0.5
    assert r.beta[-1] > 0.75 and ref.beta[-1] > 0.9


def _step_is_absorbed(r, dev, duration_s):
    inside = (r.t_s >= T0_S) & (r.t_s < T0_S + duration_s)
    assert dev[inside].max() < 0.3
    assert r.glitch[inside][1:].all() and r.pos_valid.all()
    assert r.counters["gnss_resets"] == 0 and r.counters["gnss_offsets"] == 1
    assert _back_within(r, dev, T0_S + duration_s) < 1.0


@pytest.mark.parametrize("method", METHODS)
def test_short_steps_leave_the_estimate_alone(log, clean, method):
    for size_m in (5.0, 30.0):
        r, dev = _glitched(log, clean, method, 2.0, _step(size_m))
        _step_is_absorbed(r, dev, 2.0)
        _belief_recovers(r, clean[method], T0_S + 2.0)


@pytest.mark.parametrize("method", LONG)
@pytest.mark.parametrize(("size_m", "duration_s"), [(5.0, 10.0), (15.0, 10.0), (30.0, 60.0)])
def test_long_steps_leave_the_estimate_alone(log, clean, method, size_m, duration_s):
    r, dev = _glitched(log, clean, method, duration_s, _step(size_m))
    _step_is_absorbed(r, dev, duration_s)
    _belief_recovers(r, clean[method], T0_S + duration_s)


@pytest.mark.parametrize("method", LONG)
def test_slow_ramp_is_followed_and_its_jump_back_held_until_the_offset_limit(log, clean, method):
    cfg = EstimatorConfig(gnss_offset_max_s=20.0)
    r, dev = _glitched(log, clean, method, 20.0, lambda t, p: p + 0.5 * t * DIAG, cfg)
    inside = (r.t_s >= T0_S) & (r.t_s < T0_S + 20.0)
    assert dev[inside].max() < 0.5 * 20.0 + 1.0
    assert r.counters["gnss_offsets"] == 1 and r.counters["gnss_resets"] == 1
    held = (r.t_s >= T0_S + 21.0) & (r.t_s < T0_S + 39.0)
    assert dev[held].min() > 8.0  # on the ramp's end: the jump back is a step to the filter
    assert _back_within(r, dev, T0_S + 20.0 + cfg.gnss_offset_max_s) < 1.0
    _belief_recovers(r, clean[method], T0_S + 20.0 + cfg.gnss_offset_max_s)


@pytest.mark.parametrize("method", LONG)
def test_frozen_fix_is_rejected_and_the_estimate_flagged(log, clean, method):
    r, dev = _glitched(log, clean, method, 10.0, _frozen())
    assert r.counters["gnss_rejected_frozen"] > 30
    inside = (r.t_s >= T0_S) & (r.t_s < T0_S + 10.0)
    assert not r.pos_valid[inside].all()  # > 5 s without a fused fix
    assert _back_within(r, dev, T0_S + 10.0) < 1.0
    _belief_recovers(r, clean[method], T0_S + 10.0)


def test_a_repeated_fix_is_a_counted_duplicate(log, clean):
    twice = []
    for s in log.samples:
        twice.append(s)
        if type(s) is GnssFix:
            twice.append(dataclasses.replace(s))
    r = run(Log(tuple(twice), log.frame), "second-order")
    ref = clean["second-order"]
    n_fix = len(log.fix_indices())
    assert r.counters["gnss_rejected_duplicate"] == n_fix
    # one estimate row per received fix: the repeat's row equals the row before it
    np.testing.assert_array_equal(r.p_ned_m[1::2], ref.p_ned_m)
