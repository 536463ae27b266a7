"""A foreign-autopilot flight's session replayed from its ``run.tlog`` (no SITL).

The session's tlog holds every frame it received and sent, in the order it received and sent
them. Its analysis inputs (``Recording``, the fixes the GNSS source released, the driver's phases)
depend only on the frames received after ``connect`` (the source and the driver are seeded and
driven by the autopilot's time), so feeding those frames to a freshly planned session, in order,
rebuilds them exactly: the flight can be scored again (``px4.rescore``) without flying it.

``connect`` consumes the frames it receives until it has the autopilot's HEARTBEAT and then asks
for the streams (COMMAND_LONG): the frames received before our first COMMAND_LONG are skipped, as
``connect`` skipped them. The replay stops where ``run`` stopped: when the driver is done.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any, cast

from companion.autopilot.connection import DIALECT, MavConnection
from companion.errors import UserError
from companion.mavlink.frames import (
    HEADER_V2,
    IFLAG_SIGNED,
    MAGIC_V2,
    SIGNATURE_BYTES,
    frame_at,
    full_payload,
)
from companion.mavlink.tlog import STAMP_BYTES
from simvehicle.harness.foreign.session import ForeignSession


class _NoLink:
    """The replay's connection: what the session sends goes nowhere (it is in the tlog already)."""

    def send(self, msg: Any) -> bool:
        return True


def link_frames(tlog_path: Path) -> Iterator[Any]:
    """Every frame of a tlog as the connection's link views (sender's system and component), in order;
    a damaged record is a UserError (a campaign's own tlog is not repaired, it is flown again)."""
    try:
        data = tlog_path.read_bytes()
    except OSError as exc:
        raise UserError(f"{tlog_path}: cannot read: {exc.strerror or exc}") from None
    pos, n = 0, len(data)
    while pos < n:
        m = pos + STAMP_BYTES
        parsed = frame_at(data, m, n, link=True, dialect=DIALECT)
        if parsed == "unknown_msgid" and data[m] == MAGIC_V2:  # not delivered by the connection either
            pos = m + HEADER_V2 + data[m + 1] + 2 + (SIGNATURE_BYTES if data[m + 2] & IFLAG_SIGNED else 0)
            continue
        if isinstance(parsed, str):
            raise UserError(f"{tlog_path}: {parsed} frame at byte {pos}")
        end, _, spec, body = parsed
        src = data[m + 5] if data[m] == MAGIC_V2 else data[m + 3]
        yield spec.view(full_payload(spec, body), src, bytes(data[m:end]))
        pos = end


def replay(session: ForeignSession, tlog_path: Path, own: tuple[int, int], target: tuple[int, int]) -> None:
    """Feed ``session`` (planned as the flight was: same source seed, driver, frame) the frames its
    flight received after connecting. ``own``: our (system, component) in the tlog; ``target``: the
    autopilot's, as ``connect`` found it."""
    session.conn = cast(MavConnection, _NoLink())
    session.target = target
    connected = False
    for view in link_frames(tlog_path):
        if (view.get_srcSystem(), view.get_srcComponent()) == own:
            connected = connected or view.get_type() == "COMMAND_LONG"
            continue
        if connected:
            session._handle(view)
            if session.driver.phase == "done":
                return
