"""The canyon receiver beside a SITL autopilot, for tests: one short flight and its UBX record."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from companion.gnss.observations import GnssEpoch
from companion.gnss.ubx import ReceiverPvt
from companion.receiver.ubx_stream import open_stream, ubx_items

# the test city's cross street, 30 m of it: a short route, so a flight is mostly its set-up (beside
# ArduPilot EKF3 waits for the companion, which waits for the receiver's first complete LNAV subframes)
SHORT_MISSION = """extends: test
profiles:
  - {name: short-street, start_ne_m: [52, 35], goal_ne_m: [52, 65]}
"""


Flown = tuple[subprocess.CompletedProcess[str], Path]  # the sitl process, its --out


def fly_canyon(tmp_path: Path, vehicle: str, timeout_s: float, *extra: str) -> Flown:
    """``beliefnav sitl --vehicle V --scenario canyon`` on the short street, seed 0."""
    mission = tmp_path / "short.yaml"
    mission.write_text(SHORT_MISSION)
    out = tmp_path / vehicle
    cmd = [sys.executable, "-m", "gcs_tools", "sitl", "--vehicle", vehicle, "--scenario", "canyon",
           "--mission", str(mission), "--profile", "0", "--seed", "0", "--out", str(out), *extra]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s), out


def ubx_record(out: Path) -> tuple[int, list[ReceiverPvt]]:
    """The flight's receiver.ubx: (raw epochs, the receiver's own solutions NAV-PVT)."""
    items = list(ubx_items(open_stream(str(out / "receiver.ubx"))))
    return sum(isinstance(i, GnssEpoch) for i in items), [i for i in items if isinstance(i, ReceiverPvt)]
