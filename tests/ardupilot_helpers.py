"""ArduCopter SITL for tests: the binary from ``<repo>/../shared/tools/ardupilot/`` (or
$BELIEFNAV_ARDUPILOT_BIN). Missing, the tests skip on a developer machine and FAIL in CI
(environment CI=true), where the shared directory is always checked out beside the repo."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from pymavlink import mavutil

from companion.errors import UserError
from simvehicle.harness.ardupilot.sitl import resolve_binary

M = mavutil.mavlink
COPTER_MODE_GUIDED = 4


# The test city's cross street (profile 2: 90 m, a 56 s route), its first 55 m: a 34 s route. The flights
# whose checks are rates, medians and counts of at most 500 setpoints (20 Hz: 25 s of route) fly it; most
# of a flight beside ArduPilot is EKF3 getting ready (42 s of its time) and the take-off.
SHORT_CROSS_STREET = """extends: test
profiles:
  - {name: cross-street-55m, start_ne_m: [52, 5], goal_ne_m: [52, 60]}
"""


def short_cross_street(directory: Path) -> Path:
    """``SHORT_CROSS_STREET`` as a mission file in ``directory`` (its profile 0)."""
    path = directory / "cross-street-55m.yaml"
    path.write_text(SHORT_CROSS_STREET)
    return path


def require_tool(resolve: Callable[[], Path], what: str) -> Path:
    """``resolve()``'s path; if it raises UserError: skip on a developer machine, fail in CI."""
    try:
        return resolve()
    except UserError as exc:
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(f"{what} is required in CI: {exc}")
        pytest.skip(str(exc))


def require_ardupilot() -> Path:
    return require_tool(resolve_binary, "ArduPilot SITL")


def run_companion(master: str, out: Path, *extra: str) -> subprocess.Popen[str]:
    """``beliefnav companion --master ...`` as a child process (stops with SIGTERM, summary written)."""
    return subprocess.Popen(
        [sys.executable, "-m", "gcs_tools", "companion", "--master", master, "--out", str(out),
         "--no-telemetry", *extra],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def stop(proc: subprocess.Popen[str], timeout_s: float = 15.0) -> tuple[int, str]:
    """SIGTERM (if still running), wait; (return code, stderr)."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
    try:
        _, err = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        _, err = proc.communicate()
    return proc.returncode, err


def interrupt_when(proc: subprocess.Popen[str], out: Path, done: Callable[[dict[str, Any]], bool],
                   timeout_s: float) -> bool:
    """Ctrl-C (SIGINT) to a ``run_companion`` process once its summary.json (rewritten every second)
    satisfies ``done``, or after ``timeout_s`` of wall time. Ctrl-C is a clean end (exit 0, the summary
    written), as the end of its ``--duration-s`` is. Whether ``done`` was seen (the process may also have
    ended by itself: it is then left alone)."""
    deadline = time.monotonic() + timeout_s
    seen = False
    while proc.poll() is None and time.monotonic() < deadline and not seen:
        with contextlib.suppress(OSError, ValueError, KeyError, TypeError):  # not written yet, or incomplete
            seen = done(json.loads((out / "summary.json").read_text()))
        if not seen:
            time.sleep(0.1)
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    return seen


def wait_or_dump(proc: subprocess.Popen[str], timeout_s: float) -> None:
    """Wait for ``proc`` to end; one still running ``timeout_s`` later fails the test with where it is
    (SIGUSR1: the companion prints every thread's stack and goes on) and the rest of its stderr."""
    try:
        proc.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGUSR1)
        time.sleep(1.0)
        _, err = stop(proc)
        raise AssertionError(f"still running {timeout_s:g} s later; stderr, stacks:\n{err[-6000:]}") from None


def tlog_messages(path: Path) -> list[Any]:
    """Every message of a tlog with its sender ids (pymavlink's reader)."""
    conn = mavutil.mavlink_connection(str(path), dialect="ardupilotmega")
    out = []
    while (msg := conn.recv_match()) is not None:
        if msg.get_type() != "BAD_DATA":
            out.append(msg)
    conn.close()
    return out


class GroundStation:
    """A minimal GCS on one of the SITL's serial ports (system 255): arm in GUIDED, take off."""

    def __init__(self, url: str, system_id: int = 255) -> None:
        self.conn = mavutil.mavlink_connection(url, source_system=system_id, source_component=190,
                                               dialect="ardupilotmega")
        self.conn.wait_heartbeat(timeout=30)
        self.conn.mav.request_data_stream_send(1, 1, M.MAV_DATA_STREAM_ALL, 5, 1)

    def heartbeat(self) -> None:
        self.conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)

    def try_arm_guided(self) -> None:
        self.conn.mav.set_mode_send(1, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, COPTER_MODE_GUIDED)
        self.conn.mav.command_long_send(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)

    def takeoff(self, altitude_m: float) -> None:
        self.conn.mav.command_long_send(1, 1, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 0, altitude_m)

    def close(self) -> None:
        self.conn.close()


def assert_rescored_from_the_tlog(rescore: Any, out: Path, s: dict[str, Any], mission: str,
                                  config: Any) -> None:
    """A foreign-autopilot flight's session replayed from its tlog (no SITL) and scored again by
    ``rescore`` (``rescore_px4``, ``rescore_ardupilot``) gives every row's statistics, the collisions
    and the outcome exactly as flown (``evaluate --resume`` relies on it)."""
    from gcs_tools.evaluate.autopilot import same_scores

    ekf = s["vehicle"] + "-ekf"  # ardupilot-ekf3, px4-ekf2
    methods = tuple(m for m in s["methods"] if m != "companion-live" and not m.startswith(ekf))
    again = rescore(out, mission, methods, config)
    assert same_scores(s, again.summary)
    assert not same_scores(s, {**again.summary, "collisions": s["collisions"] + 1})
