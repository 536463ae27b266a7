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
:func:`within` is the stateless form for a receiver that owns the reference time (the vehicle
checks an estimate or a setpoint against its own clock). No I/O, no wall clock.
"""

from __future__ import annotations

from dataclasses import dataclass, field
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

    def __post_init__(self) -> None:
        if min(self.max_back_us, self.max_forward_us, self.consensus_step_us) < 0:
            raise ValueError("clock window bounds must be >= 0")
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
    _candidates: list[int] = field(default_factory=list)

    def check(self, t_us: int) -> Verdict:
        if not 0 <= t_us <= MAX_STAMP_US:
            self.rejected += 1
            return Verdict.REJECT
        if self.base_us is None:
            self.base_us = t_us
            return Verdict.ACCEPT
        if within(t_us, self.base_us, self.window):
            self.base_us = max(self.base_us, t_us)
            self._candidates.clear()
            return Verdict.ACCEPT
        c = self._candidates
        if c and not 0 <= t_us - c[-1] <= self.window.consensus_step_us:
            c.clear()  # does not continue the chain: it may start a new one
        c.append(t_us)
        if len(c) >= self.window.consensus_samples:
            self.base_us = t_us
            c.clear()
            self.resets += 1
            return Verdict.RESET
        self.rejected += 1
        return Verdict.REJECT

    def reset(self) -> None:
        """Forget the time base (e.g. the stream's user restarted)."""
        self.base_us = None
        self._candidates.clear()
