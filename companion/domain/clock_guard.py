"""Clocks that cannot be poisoned: one pure, tested rule for every stamped stream.

A stream's time base is the latest stamp it accepted. A new stamp is

- ``accept``: within ``[base - max_back_us, base + max_forward_us]`` (the base moves forward to it);
- ``reject``: outside that window — a lone far-off stamp (hostile, corrupt, a bit flip) is dropped,
  never adopted, so it cannot freeze the stream;
- ``reset``: the last ``consensus_samples`` out-of-window stamps agree with each other (each
  within ``[0, consensus_step_us]`` after the previous one): the clock really jumped (the sender
  rebooted or its clock was set). The stream adopts the new time base; its user starts afresh.

An in-window stamp clears the pending candidates, so hostile stamps interleaved with a live
stream never add up to a reset, and random stamps never agree with each other.

A stream received over a real link (the companion beside a real autopilot, whose frames an
attacker may forge without a key) also gives each stamp's ARRIVAL time (the receiver's clock,
µs). Two more rules then hold:

- the forward edge follows the arrivals: a stamp may lead the stream's envelope by at most
  ``max_forward_us``, and the envelope grows at most ``max_rate`` stamp-µs per arrival-µs (the
  sender's clock speed: 1 for real hardware, the speed-up for a simulator). A burst of forged
  stamps, each a little ahead of the last, cannot ratchet the base forward: in one instant the
  stream gains at most ``max_forward_us``;
- a reset needs its agreeing run to last ``consensus_span_us`` of arrival time as well: a real
  jump persists, a burst of forged frames arriving at once does not.

``consensus_back_us`` lets the agreeing candidates go back by that much (jittery values, e.g.
a clock offset, rather than stamps). :func:`within` is the stateless form for a receiver that
owns the reference time (the vehicle checks an estimate or a setpoint against its own clock).
No I/O, no wall clock: arrival times are passed in.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

MAX_STAMP_US = 2**62  # beyond this a µs stamp is corrupt whatever the stream (int64 headroom)


class Verdict(Enum):
    ACCEPT = "accept"
    REJECT = "reject"
    RESET = "reset"


@dataclass(frozen=True, slots=True)
class ClockWindow:
    """Plausible stamps around a stream's time base, and what makes a jump real."""

    max_back_us: int  # older than the base by more than this: out of window
    max_forward_us: int  # newer than the base by more than this: out of window
    consensus_samples: int = 5  # consecutive agreeing out-of-window stamps that make a reset
    consensus_step_us: int = 1_000_000  # consecutive candidates must be this close, in order
    consensus_back_us: int = 0  # ... or at most this much older than the previous one
    max_rate: float = 0.0  # stamp µs per arrival µs the envelope may grow (0: arrivals not used)
    consensus_span_us: int = 0  # arrival time an agreeing run must last before it is a reset

    def __post_init__(self) -> None:
        if min(self.max_back_us, self.max_forward_us, self.consensus_step_us, self.consensus_back_us,
               self.consensus_span_us) < 0:
            raise ValueError("clock window bounds must be >= 0")
        if not self.max_rate >= 0:
            raise ValueError("the clock's max_rate must be >= 0")
        if self.consensus_samples < 2:
            raise ValueError("a reset needs the consensus of at least 2 samples")


def within(t_us: int, reference_us: int, window: ClockWindow) -> bool:
    """Is ``t_us`` inside ``window`` around a reference time the receiver owns?"""
    return reference_us - window.max_back_us <= t_us <= reference_us + window.max_forward_us


@dataclass(slots=True)
class StreamClock:
    """The time base of one stream; :meth:`check` classifies each new stamp (see module doc)."""

    window: ClockWindow
    base_us: int | None = None
    resets: int = 0
    rejected: int = 0
    _envelope_us: float = 0.0  # with arrivals: the forward edge's reference, and when it was set
    _envelope_at_us: int | None = None
    _run_count: int = 0  # the agreeing out-of-window run: length, last stamp, first arrival
    _run_last_us: int = 0
    _run_start_at_us: int | None = None

    @property
    def pending(self) -> int:
        """Out-of-window stamps of the agreeing run so far (0: none pending)."""
        return self._run_count

    def check(self, t_us: int, arrival_us: int | None = None) -> Verdict:
        if not 0 <= t_us <= MAX_STAMP_US:
            self.rejected += 1
            return Verdict.REJECT
        if self.base_us is None:
            self._adopt(t_us, arrival_us)
            return Verdict.ACCEPT
        w = self.window
        if self.base_us - w.max_back_us <= t_us <= self._forward_edge(arrival_us):
            self.base_us = max(self.base_us, t_us)
            if self._envelope_at_us is not None and arrival_us is not None:
                self._envelope_us = min(self._envelope_now(arrival_us), self.base_us)
                self._envelope_at_us = arrival_us
            self._run_count = 0
            return Verdict.ACCEPT
        if self._run_count and -w.consensus_back_us <= t_us - self._run_last_us <= w.consensus_step_us:
            self._run_count += 1
        else:  # does not continue the run: it may start a new one
            self._run_count, self._run_start_at_us = 1, arrival_us
        self._run_last_us = t_us
        lasted = (arrival_us is None or self._run_start_at_us is None
                  or arrival_us - self._run_start_at_us >= w.consensus_span_us)
        if self._run_count >= w.consensus_samples and lasted:
            self._adopt(t_us, arrival_us)
            self.resets += 1
            return Verdict.RESET
        self.rejected += 1
        return Verdict.REJECT

    def _envelope_now(self, arrival_us: int) -> float:
        assert self._envelope_at_us is not None
        return self._envelope_us + self.window.max_rate * max(arrival_us - self._envelope_at_us, 0)

    def _forward_edge(self, arrival_us: int | None) -> float:
        assert self.base_us is not None
        if self.window.max_rate > 0 and arrival_us is not None and self._envelope_at_us is not None:
            return self._envelope_now(arrival_us) + self.window.max_forward_us
        return self.base_us + self.window.max_forward_us

    def _adopt(self, t_us: int, arrival_us: int | None) -> None:
        self.base_us = t_us
        self._run_count = 0
        self._envelope_us, self._envelope_at_us = t_us, arrival_us

    def reset(self) -> None:
        """Forget the time base (e.g. the stream's user restarted)."""
        self.base_us = None
        self._run_count = 0
        self._envelope_at_us = None
