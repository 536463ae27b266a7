"""The clock guard: lone far-off stamps rejected, a consensus of several is a reset (known answers)."""

import numpy as np
import pytest

from companion.domain.clock_guard import MAX_STAMP_US, ClockWindow, StreamClock, Verdict, within

W = ClockWindow(max_back_us=200_000, max_forward_us=1_000_000, consensus_samples=5,
                consensus_step_us=100_000)


def _stream(clock, stamps):
    return [clock.check(t).value for t in stamps]


def test_in_window_stamps_are_accepted_and_move_the_base_forward_only():
    c = StreamClock(W)
    assert _stream(c, [1_000, 6_000, 5_000, 11_000]) == ["accept"] * 4
    assert c.base_us == 11_000  # 5_000 was accepted (within 200 ms back) but did not move the base


def test_a_lone_future_stamp_is_rejected_and_the_stream_goes_on():
    c = StreamClock(W)
    live = [k * 5_000 for k in range(100)]
    verdicts = _stream(c, live[:50] + [4_000_000_000_000] + live[50:])
    assert verdicts.count("reject") == 1 and verdicts[50] == "reject"
    assert c.base_us == live[-1] and c.resets == 0 and c.rejected == 1


def test_a_lone_past_stamp_and_absurd_stamps_are_rejected():
    c = StreamClock(W)
    _stream(c, [10_000_000, 10_005_000])
    assert c.check(0) is Verdict.REJECT
    assert c.check(-1) is Verdict.REJECT
    assert c.check(MAX_STAMP_US + 1) is Verdict.REJECT
    assert c.check(10_010_000) is Verdict.ACCEPT


def test_a_real_jump_is_a_reset_after_exactly_consensus_samples():
    c = StreamClock(W)
    _stream(c, [100_000_000 + k * 5_000 for k in range(10)])
    rebooted = [k * 5_000 for k in range(1, 8)]
    assert _stream(c, rebooted) == ["reject"] * 4 + ["reset"] + ["accept"] * 2
    assert c.resets == 1 and c.base_us == rebooted[-1]


def test_random_stamps_interleaved_with_a_live_stream_never_reset_it():
    rng = np.random.default_rng(7)
    c = StreamClock(W)
    t = 0
    for _ in range(2_000):
        t += 5_000
        assert c.check(t) is Verdict.ACCEPT
        for _ in range(3):  # a flood: three hostile stamps per live one
            c.check(int(rng.integers(0, 2**62)))
    assert c.resets == 0 and c.base_us == t


def test_a_hostile_burst_that_agrees_with_itself_is_still_broken_by_the_live_stream():
    c = StreamClock(W)
    _stream(c, [k * 5_000 for k in range(1, 20)])
    hostile = [9_000_000_000 + k for k in range(4)]  # one short of the consensus
    assert _stream(c, hostile) == ["reject"] * 4
    assert c.check(100_000) is Verdict.ACCEPT  # live sample clears the candidates
    assert _stream(c, hostile) == ["reject"] * 4 and c.resets == 0


def test_a_poisoned_first_stamp_heals_by_consensus():
    c = StreamClock(W)
    assert c.check(4_000_000_000_000) is Verdict.ACCEPT  # nothing to compare the first one with
    verdicts = _stream(c, [k * 5_000 for k in range(1, 7)])
    assert verdicts == ["reject"] * 4 + ["reset", "accept"]


def test_within_is_inclusive_at_both_edges():
    assert within(800_000, 1_000_000, W) and within(2_000_000, 1_000_000, W)
    assert not within(799_999, 1_000_000, W) and not within(2_000_001, 1_000_000, W)


def test_bad_windows_are_refused():
    with pytest.raises(ValueError):
        ClockWindow(max_back_us=-1, max_forward_us=0)
    with pytest.raises(ValueError):
        ClockWindow(max_back_us=0, max_forward_us=0, consensus_samples=1)
