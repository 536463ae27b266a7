"""One vehicle id per run on a telemetry network: claimed with a Zenoh liveliness token.

``beliefnav sitl`` claims ``beliefnav/<id>/run/<pid>`` before its processes start and holds it for
the run. If another live run already holds the wanted id, the next free ``<stem><n>`` is taken and
said in one line (``uav1`` busy -> ``uav2``), so two runs never publish under one id silently.
Two launchers racing for the same id both see each other after declaring: the one with the
higher pid moves on. The token dies with the session (even on ``kill -9`` of the launcher).
"""

from __future__ import annotations

import os
import re
import time
from dataclasses import dataclass
from typing import Any

from companion.errors import UserError
from companion.telemetry import codec as zc
from companion.telemetry.pubsub import TelemetryConfig, open_session

RUN_SEGMENT = "run"
SETTLE_S = 0.5  # wall time for a new session to meet the others before it asks who is there
QUERY_TIMEOUT_S = 1.0
MAX_CANDIDATES = 50


@dataclass
class VehicleIdClaim:
    """A held vehicle id; ``close`` releases it (also released when the process dies)."""

    vehicle_id: str
    note: str  # "" or one line saying the wanted id was taken
    _session: Any
    _token: Any

    def close(self) -> None:
        token, session, self._token, self._session = self._token, self._session, None, None
        if token is not None:
            token.undeclare()
        if session is not None:
            session.close()


def _holders(session: Any, vehicle_id: str) -> list[int]:
    """Pids of the live runs holding ``vehicle_id``."""
    pids = []
    for reply in session.liveliness().get(f"{zc.KEY_PREFIX}/{vehicle_id}/{RUN_SEGMENT}/*",
                                          timeout=QUERY_TIMEOUT_S):
        ok = getattr(reply, "ok", None)
        if ok is None:
            continue
        last = str(ok.key_expr).rsplit("/", 1)[-1]
        if last.isdigit():
            pids.append(int(last))
    return pids


def _candidates(wanted: str) -> list[str]:
    m = re.fullmatch(r"(.*?)(\d+)", wanted)
    stem, first = (m.group(1), int(m.group(2))) if m else (wanted, 1)
    return [wanted] + [f"{stem}{n}" for n in range(first + 1, first + MAX_CANDIDATES)]


def claim_vehicle_id(config: TelemetryConfig, wanted: str) -> VehicleIdClaim | None:
    """Hold ``wanted`` or the next free id; None when telemetry is off (nothing is published)."""
    if not config.enabled:
        return None
    session = open_session(config)
    pid = os.getpid()
    time.sleep(SETTLE_S)
    for vehicle_id in _candidates(wanted):
        if _holders(session, vehicle_id):
            continue
        token = session.liveliness().declare_token(f"{zc.KEY_PREFIX}/{vehicle_id}/{RUN_SEGMENT}/{pid}")
        rivals = [p for p in _holders(session, vehicle_id) if p != pid]
        if any(p < pid for p in rivals):  # a racing launcher with a lower pid keeps it
            token.undeclare()
            continue
        note = "" if vehicle_id == wanted else (
            f"vehicle id {wanted!r} is in use by another run on this telemetry network: publishing as "
            f"{vehicle_id!r}")
        return VehicleIdClaim(vehicle_id, note, session, token)
    session.close()
    raise UserError(f"--vehicle-id {wanted!r}: it and the next {MAX_CANDIDATES - 1} ids are in use")
