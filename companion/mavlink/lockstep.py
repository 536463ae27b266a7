"""Lockstep barrier between the vehicle and its companions, built on MAVLink TIMESYNC.

At the end of control step k the vehicle has sent every sample up to ``t_k`` and then sends a
step marker: TIMESYNC request ``tc1 = 0, ts1 = t_k`` (ns of boot time). A companion processes
messages in arrival order, so when it sees the marker it has consumed everything up to ``t_k``;
it sends its answer for the step (ODOMETRY stamped ``t_k``, or the setpoint for ``t_k``) and
then the TIMESYNC response ``tc1 = its clock (> 0), ts1 = t_k``. One socket delivers in order,
so a response behind an answer means the answer has arrived (unless the network lost it).

The vehicle advances only when every companion that is present has responded for ``t_k``; a
lost marker or response is re-requested after ``retry_s``. A companion is absent when its
process is known to be gone (its port is closed: the marker comes back as ICMP port
unreachable) or when it stays silent for ``give_up_s`` of wall time (several seconds: a
companion that is merely slow, descheduled or stopped for a while on a loaded machine is
waited for, so it never changes the result). An absent companion is waited for only
``retry_s`` per step, so the flight goes on (the autopilot holds on a stale estimate), and it
rejoins as soon as it answers. With no loss and no companion gone the sequence of states is
a function of the seed alone; a repeated marker only repeats an identical answer.
"""

from __future__ import annotations

from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

NS_PER_US = 1_000


@dataclass(frozen=True, slots=True)
class LockstepConfig:
    retry_s: float = 0.01  # wall time before a missing response is requested again
    give_up_s: float = 5.0  # wall time after which a silent (but not gone) companion counts as absent


def step_marker(t_us: int) -> mavlink.MAVLink_timesync_message:
    """The vehicle's end-of-step marker for boot time ``t_us``."""
    return mavlink.MAVLink_timesync_message(tc1=0, ts1=t_us * NS_PER_US)


def marker_time_us(msg: mavlink.MAVLink_message) -> int | None:
    """Boot time of a step marker (a TIMESYNC request), else None."""
    if msg.get_type() == "TIMESYNC" and msg.tc1 == 0 and msg.ts1 >= 0:
        return int(msg.ts1) // NS_PER_US
    return None


def step_response(marker_t_us: int, clock_ns: int) -> mavlink.MAVLink_timesync_message:
    """A companion's response once its answer for ``marker_t_us`` has been sent."""
    return mavlink.MAVLink_timesync_message(tc1=max(int(clock_ns), 1), ts1=marker_t_us * NS_PER_US)


def response_time_us(msg: mavlink.MAVLink_message) -> int | None:
    """Boot time a TIMESYNC response answers, else None."""
    if msg.get_type() == "TIMESYNC" and msg.tc1 != 0:
        return int(msg.ts1) // NS_PER_US
    return None
