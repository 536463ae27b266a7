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
    with pytest.raises(ValueError):
        ClockWindow(max_back_us=0, max_forward_us=0, max_rate=float("nan"))


# --- a stream over a real link: stamps checked against their arrival times ---------------------
LINK = ClockWindow(max_back_us=1_000_000, max_forward_us=200_000, consensus_samples=5,
                   consensus_step_us=1_000_000, consensus_back_us=1_000_000, max_rate=20.0,
                   consensus_span_us=250_000)


def test_a_forged_burst_cannot_ratchet_the_base_forward():
    """Ten forged stamps, each 0.15 s after the last, arriving together: the stream gains at most
    max_forward in one instant, so the genuine stamps that follow are still in the window."""
    c = StreamClock(LINK)
    for k in range(50):  # genuine: 50 Hz at x1
        assert c.check(10_000_000 + k * 20_000, k * 20_000) is Verdict.ACCEPT
    base, now = c.base_us, 49 * 20_000 + 100
    verdicts = [c.check(base + (k + 1) * 150_000, now).value for k in range(10)]
    assert verdicts == ["accept"] + ["reject"] * 9  # +0.15 s fits the forward window once, no more
    assert c.base_us == base + 150_000
    for k in range(1, 20):  # the genuine stream goes on: in window (0.15 s back at most)
        assert c.check(base + k * 20_000, now + k * 20_000) is Verdict.ACCEPT
    assert c.resets == 0


def test_the_forward_edge_grows_with_the_arrivals_at_max_rate():
    """A sped-up sender (x10) after a 0.5 s stall of ours: 5 s of its stamps arrive at once, all
    in window; the same 5 s without the stall would not be."""
    c = StreamClock(LINK)
    assert c.check(1_000_000, 0) is Verdict.ACCEPT
    assert c.check(6_000_000, 500_000) is Verdict.ACCEPT  # 5 s in 0.5 s: x10 <= x20
    assert c.check(16_000_000, 500_100) is Verdict.REJECT  # 10 s in 0.1 ms: no


def test_a_reset_needs_its_agreeing_run_to_last():
    c = StreamClock(LINK)
    for k in range(10):
        c.check(50_000_000 + k * 20_000, k * 20_000)
    now = 10 * 20_000
    burst = [c.check(1_000_000 + k * 1_000, now).value for k in range(20)]  # 20 agreeing, at once
    assert set(burst) == {"reject"} and c.resets == 0 and c.pending == 20
    rebooted = [c.check(1_020_000 + k * 20_000, now + (k + 1) * 20_000).value for k in range(15)]
    assert rebooted[:12] == ["reject"] * 12 and rebooted[12] == "reset"  # >= 0.25 s after the run began
    assert c.resets == 1


def test_a_jittery_run_agrees_within_consensus_back():
    """Messages of one sender lag each other (a stamp 0.1 s older than the previous): a run may go
    back by consensus_back, so a real reboot with mixed message types is still found."""
    c = StreamClock(LINK)
    c.check(50_000_000, 0)
    stamps = [1_000_000, 1_100_000, 1_000_000, 1_150_000, 1_050_000, 1_200_000]
    verdicts = [c.check(t, 300_000 + k * 60_000).value for k, t in enumerate(stamps)]
    assert verdicts == ["reject"] * 5 + ["reset"]
    strict = StreamClock(W)
    strict.check(50_000_000)
    assert [strict.check(t).value for t in stamps] == ["reject"] * 6  # in order only (the default)
