"""TIMESYNC as the MAVLink spec has it, done once for the whole companion (as MAVROS does).

A request is ``tc1 = 0, ts1 = the sender's clock (ns)``; the answer is ``tc1 = our clock (ns),
ts1 = the request's ts1``. Our clock, for the autopilot, is ITS boot time: every stamp we send it
(ODOMETRY, VISION_POSITION_ESTIMATE, GPS_INPUT ``time_usec``) is on that base, so a request is
answered with the autopilot's own time at asking (``tc1 = ts1``). PX4 derives from these answers
the offset it adds to our stamps (``Timesync::sync_stamp``, once converged); answered with a
host clock, that offset moved every ODOMETRY stamp by the host's uptime and EKF2 fused none of
them (measured on PX4 SITL: ``vehicle_visual_odometry.timestamp_sample`` ~2^64, ``cs_ev_pos``
false). Answered on the boot time, PX4's offset is half the round trip. We send our own requests
once a second on our monotonic clock; from each answer to ours, with ``rtt = now - ts1``, the
remote clock minus ours is ``offset = tc1 - (ts1 + now) / 2`` (its error is at most ``rtt / 2``).
The offset is smoothed (exponential, weight ``alpha``) and restarted when a new sample is further
than ``reset_ns`` away (a reboot). Answers with an rtt above ``max_rtt_ns`` are counted and not used.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

from pymavlink.dialects.v20 import common as mavlink


def answer(request: Any, now_ns: int) -> mavlink.MAVLink_timesync_message:
    """The spec's answer to a TIMESYNC request: our clock in ``tc1`` (> 0), its ``ts1`` echoed."""
    return mavlink.MAVLink_timesync_message(tc1=max(int(now_ns), 1), ts1=int(request.ts1))


def answer_on_boot_time(request: Any) -> mavlink.MAVLink_timesync_message:
    """The answer when our clock is the requester's boot time: its own time at asking."""
    return answer(request, int(request.ts1))


@dataclass(frozen=True, slots=True)
class TimesyncConfig:
    request_period_s: float = 1.0  # our requests (wall clock)
    alpha: float = 0.2  # weight of a new offset sample
    max_rtt_ns: int = 50_000_000  # answers slower than this are not used (50 ms)
    reset_ns: int = 500_000_000  # an offset jump beyond this restarts the estimate (500 ms)


@dataclass(slots=True)
class Timesync:
    config: TimesyncConfig = field(default_factory=TimesyncConfig)
    offset_ns: float = math.nan  # remote clock minus ours
    rtt_ns: float = math.nan  # last round trip
    counters: Counter[str] = field(default_factory=Counter)
    _outstanding: set[int] = field(default_factory=set)

    def request(self, now_ns: int) -> mavlink.MAVLink_timesync_message:
        """Our request (remember its stamp so the answer can be matched)."""
        self._outstanding = {t for t in self._outstanding if now_ns - t < 10 * self.config.max_rtt_ns}
        self._outstanding.add(now_ns)
        self.counters["requests_sent"] += 1
        return mavlink.MAVLink_timesync_message(tc1=0, ts1=now_ns)

    def handle(self, msg: Any, now_ns: int) -> mavlink.MAVLink_timesync_message | None:
        """The answer to a request (to send, on the autopilot's boot time), or None after taking in
        an answer to ours (``now_ns``: our monotonic clock)."""
        if msg.tc1 == 0:
            self.counters["requests_answered"] += 1
            return answer_on_boot_time(msg)
        if int(msg.ts1) not in self._outstanding:
            self.counters["responses_not_ours"] += 1
            return None
        self._outstanding.discard(int(msg.ts1))
        rtt = now_ns - int(msg.ts1)
        if rtt > self.config.max_rtt_ns:
            self.counters["responses_slow"] += 1
            return None
        sample = int(msg.tc1) - (int(msg.ts1) + now_ns) / 2.0
        self.counters["responses_used"] += 1
        self.rtt_ns = float(rtt)
        if math.isnan(self.offset_ns) or abs(sample - self.offset_ns) > self.config.reset_ns:
            self.offset_ns = sample
        else:
            self.offset_ns += self.config.alpha * (sample - self.offset_ns)
        return None

    def as_dict(self) -> dict[str, Any]:
        return {"offset_ns": None if math.isnan(self.offset_ns) else self.offset_ns,
                "rtt_ms": None if math.isnan(self.rtt_ns) else self.rtt_ns / 1e6, **self.counters}
