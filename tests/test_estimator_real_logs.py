"""The estimator on real and autopilot logs without injected faults: the belief stays high in open
sky, the position is flagged invalid when GNSS ends and does not run away.

Logs (tests/data): quad106.tlog (real flight, PX4 FMU), sample_px4_events.ulg (PX4 SITL),
arducopter_sitl_hover.bin (ArduCopter SITL).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from companion.estimator import EstimatorConfig
from tests.real_logs import inject, load_log, load_quad106, run

DATA = Path(__file__).parent / "data"
CFG = EstimatorConfig()


@pytest.fixture(scope="module")
def open_sky():
    return load_quad106(), load_log(DATA / "sample_px4_events.ulg")


@pytest.mark.parametrize("method", ["first-order", "second-order"])
def test_belief_is_high_in_open_sky_on_real_and_px4_logs(open_sky, method):
    """Open sky: after the first 10 s, β's median > 0.85 and its last value > 0.9 on quad106 (668 s,
    measured second-order 0.90 / 1.00, first-order 0.94 / 0.99) and on the PX4 ULog (31 s)."""
    for log in open_sky:
        r = run(log, method)
        settled = r.beta[r.t_s > r.t_s[0] + 10.0]
        assert np.median(settled) > 0.85 and settled[-1] > 0.9


@pytest.fixture(scope="module")
def hover():
    return load_log(DATA / "arducopter_sitl_hover.bin")


@pytest.mark.parametrize("method", ["naive", "adaptive", "vbakf", "second-order"])
def test_when_gnss_ends_the_position_is_flagged_invalid_and_does_not_run_away(hover, method):
    """GNSS removed for the last 14 s of the ArduCopter SITL hover: pos_valid turns False
    pos_valid_timeout_s (5 s) after the last fix's validity time (to one 25 ms estimate row), the
    position variance reported only grows (held at the fixes' own variance until P passes it), and
    the estimate stays within 1 m of the full-GNSS replay for 12 s (measured ≤ 0.12 m; 1.8-2.0 m
    without the acceleration-bias state)."""
    t_end = (hover.samples[-1].t_us - hover.samples[0].t_us) * 1e-6 - 14.0
    clean = run(hover, method, every_imu=10)
    cut = run(hover.without_gnss_after(t_end), method, every_imu=10)
    after = cut.t_s > t_end + 0.5  # the last fix arrives ~0.2 s after its validity time
    last_fix = cut.fix_t_s.max()
    invalid = cut.t_s[after & ~cut.pos_valid]
    assert len(invalid) and 0.0 < invalid[0] - (last_fix + CFG.pos_valid_timeout_s) <= 0.026
    assert not cut.pos_valid[cut.t_s > invalid[0]].any()
    var_n = cut.var_p_m2[after, 0]  # reported: floored at one fix's variance while P is below it
    assert np.all(np.diff(var_n) >= 0) and np.all(np.diff(var_n[var_n > var_n[0]]) > 0)
    assert var_n[-1] > 100 * var_n[0]
    dev = np.linalg.norm(cut.p_ned_m[:, :2] - clean.p_ned_m[:, :2], axis=1)
    assert dev[after & (cut.t_s < t_end + 12.0)].max() < 1.0


@pytest.mark.parametrize("method", ["naive", "second-order"])
def test_steps_in_the_px4_ulog_are_held_then_accepted_and_returned(open_sky, method):
    """PX4 SITL ULog (its receiver reports eph ≈ 1 m at 12 s, no velocity): a 20 m step from 12 s lasting
    2 s is held (the stepped fixes fused relative to the offset): within 0.5 m of the clean replay, no
    reset; lasting 10 s it is accepted after gnss_offset_max_s (one reset, the estimate on the stepped
    fixes) and its end is a return (no second reset), back within 0.5 m 1 s after; β ends above 0.9.
    (A 5 m step there is within 5σ of the reported accuracy and is fused, as EKF2 would.)"""
    log = open_sky[1]
    clean = run(log, method)
    diag = np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0)
    for duration_s, resets in ((2.0, 0), (10.0, 1)):
        r = run(inject(log, 12.0, duration_s, lambda t, p: p + 20.0 * diag), method)
        dev = np.linalg.norm(r.p_ned_m[:, :2] - clean.p_ned_m[:, :2], axis=1)
        held = r.t_s < 12.0 + 5.0
        assert dev[held].max() < 0.5
        if duration_s > 5.0:  # accepted: on the stepped fixes until the step ends
            on_step = (r.t_s > 12.0 + 6.0) & (r.t_s < 12.0 + duration_s)
            assert np.all(np.abs(dev[on_step] - 20.0) < 1.0)
        assert r.counters["gnss_resets"] == resets and r.counters["gnss_offsets"] == 1
        assert r.counters["gnss_offset_returns"] == resets
        after = r.t_s >= 12.0 + duration_s + 1.0
        assert dev[after].max() < 0.5 and r.beta[-1] > 0.9
