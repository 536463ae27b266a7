"""The vehicle's side of the lockstep barrier (protocol: :mod:`companion.mavlink.lockstep`)."""

from __future__ import annotations

import select
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from companion.mavlink.lockstep import LockstepConfig, response_time_us, step_marker
from companion.mavlink.udp_link import UdpLink

OnMessage = Callable[[str, Any], None]


@dataclass(slots=True)
class StepBarrier:
    """Wait, per control step, until every present companion has answered that step."""

    links: Mapping[str, UdpLink]  # companions that must answer, by name
    config: LockstepConfig = field(default_factory=LockstepConfig)
    absent: set[str] = field(default_factory=set)
    counters: dict[str, int] = field(default_factory=lambda: {"retries": 0, "gave_up": 0})

    def wait(self, t_us: int, on_message: OnMessage, extra: Mapping[str, UdpLink] | None = None,
             meanwhile: Callable[[], None] | None = None) -> None:
        """Send the step marker for ``t_us`` and read every link (companions and ``extra``)
        until each present companion has responded for ``t_us`` (see module docstring).
        ``meanwhile`` runs once the markers are out (work that need not delay the companions)."""
        readers = {**self.links, **(extra or {})}
        by_fd = {link.fileno(): name for name, link in readers.items()}
        pending = set(self.links)
        refused = {name: self.links[name].counters.peer_refused for name in pending}
        for name in pending:
            self.links[name].send(step_marker(t_us))
            self.links[name].flush()  # the step's batch, marker last
        if meanwhile is not None:
            meanwhile()
        start = last_send = time.monotonic()
        while pending:
            timeout = last_send + self.config.retry_s - time.monotonic()
            ready, _, _ = select.select(list(by_fd), [], [], max(timeout, 0.0))
            for fd in ready:
                name = by_fd[fd]
                for msg in readers[name].recv_all():
                    self.absent.discard(name)
                    on_message(name, msg)
                    if name in pending and response_time_us(msg) == t_us:
                        pending.discard(name)
            for name in pending:
                if self.links[name].counters.peer_refused > refused[name]:  # its process is gone
                    self.absent.add(name)
            now = time.monotonic()
            if not pending or now < last_send + self.config.retry_s:
                continue
            if pending <= self.absent or now - start >= self.config.give_up_s:
                self.counters["gave_up"] += 1
                self.absent |= pending
                return
            self.counters["retries"] += 1
            for name in pending:
                self.links[name].send(step_marker(t_us))
            last_send = now
