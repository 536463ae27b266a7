"""Closed loop: the companion as the separate process a user deploys beside the autopilot.

The flight tool starts ``beliefnav companion --master URL --feed F --mission M --home <SITL home> [extra]``
beside the SITL, on its own MAVLink connection: ArduCopter's SERIAL1 (``tcp:127.0.0.1:5762 +
10·I``, raw fixes read back as GPS2_RAW: ``--gnss-instance 2 --target-system 1``) or PX4's
onboard link (``udpin:127.0.0.1:14540 + i``, raw fixes as GPS_RAW_INT, ``--target-system i + 1``).
It reads the autopilot's IMU, attitude and GNSS streams (it asks for them itself) and sends its
feed: ``gps-input`` = GPS_INPUT of the cleaned fix, ``vision`` = VISION_POSITION_ESTIMATE,
``odometry`` = ODOMETRY (external navigation; it also sets the EKF origin to ``--home``). What it
sent is read back from its own ``run.tlog`` and scored against truth (:func:`sent_track`).
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np

from companion.autopilot.feeds import local_origin_ned_m
from companion.autopilot.frame import plausible
from companion.domain.geodesy import LocalNedFrame
from companion.errors import UserError

COMPANION_COMPONENT_ID = 197  # beliefnav companion's default (MAV_COMP_ID_VISUAL_INERTIAL_ODOMETRY)
STOP_TIMEOUT_S = 10.0  # SIGTERM -> summary.json written; then SIGKILL
FEED_MESSAGES = {"gps-input": "GPS_INPUT", "vision": "VISION_POSITION_ESTIMATE", "odometry": "ODOMETRY"}


def companion_command(master: str, out_dir: Path, feed: str, method: str, home: tuple[float, float, float],
                      *extra: str, mission: str | None = None) -> list[str]:
    """The command line a user would type (``extra``: e.g. ``--gnss-instance 2``; ``mission``: the
    mission flown, whose buildings are the companion's map)."""
    if feed not in FEED_MESSAGES:
        raise UserError(f"--feed {feed}: the companion process feeds one of {', '.join(FEED_MESSAGES)}")
    return [sys.executable, "-m", "gcs_tools", "companion", "--master", master, "--out", str(out_dir),
            "--feed", feed, "--method", method, *extra, *(("--mission", mission) if mission else ()),
            "--home", ",".join(f"{v:.9f}" for v in home), "--no-telemetry"]


class CompanionProcess:
    """``with CompanionProcess(cmd, log) as p``: started in its own session, stopped by SIGTERM."""

    def __init__(self, command: list[str], log_path: Path) -> None:
        self.command = command
        self.log_path = log_path
        self.process: subprocess.Popen[bytes] | None = None
        self.returncode: int | None = None

    def __enter__(self) -> CompanionProcess:
        return self.start()

    def start(self) -> CompanionProcess:
        self.log_path.parent.mkdir(parents=True, exist_ok=True)
        with self.log_path.open("ab") as log:
            # its own session: a Ctrl-C in the terminal reaches the flight tool, which stops it
            self.process = subprocess.Popen(self.command, stdin=subprocess.DEVNULL, stdout=log,
                                            stderr=subprocess.STDOUT, start_new_session=True)
        return self

    def running(self) -> bool:
        return self.process is not None and self.process.poll() is None

    def stop(self) -> int | None:
        proc, self.process = self.process, None
        if proc is None:
            return self.returncode
        if proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                proc.send_signal(signal.SIGTERM)  # the companion writes summary.json on SIGTERM
            try:
                proc.wait(STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
        self.returncode = proc.returncode
        return self.returncode

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.stop()


def sent_track(tlog_path: Path, feed: str, companion_frame: LocalNedFrame,
               mission_frame: LocalNedFrame) -> tuple[np.ndarray, np.ndarray]:
    """What the companion SENT the autopilot (its tlog): (boot µs (N,), mission NED (N, 3)), time-sorted.

    GPS_INPUT: geodetic (a fix_type below 3, sent while it had no valid estimate, is left out);
    VISION_POSITION_ESTIMATE and ODOMETRY: NED in the autopilot's local frame, about the origin the
    companion had then (``companion.autopilot.feeds.local_origin_ned_m`` of the last plausible
    GPS_GLOBAL_ORIGIN in its tlog before the message, in the companion's frame, ``--home``)."""
    from pymavlink import mavutil

    kind = FEED_MESSAGES[feed]
    t_us: list[int] = []
    p: list[np.ndarray] = []
    if not tlog_path.is_file():
        return np.zeros(0, dtype=np.int64), np.zeros((0, 3))
    log = mavutil.mavlink_connection(str(tlog_path), dialect="ardupilotmega")
    origin = np.zeros(3)
    try:
        while (msg := log.recv_match(type=[kind, "GPS_GLOBAL_ORIGIN"])) is not None:
            if msg.get_type() == "GPS_GLOBAL_ORIGIN":
                lla = (msg.latitude * 1e-7, msg.longitude * 1e-7, msg.altitude * 1e-3)
                if plausible(*lla):
                    origin = local_origin_ned_m(companion_frame, lla)
                continue
            if msg.get_srcComponent() != COMPANION_COMPONENT_ID:
                continue
            if kind == "GPS_INPUT":
                if msg.fix_type < 3:
                    continue
                t_us.append(int(msg.time_usec))
                p.append(mission_frame.to_ned_m(msg.lat * 1e-7, msg.lon * 1e-7, float(msg.alt)))
            else:
                lla = companion_frame.to_geodetic(np.array([msg.x, msg.y, msg.z], dtype=float) + origin)
                t_us.append(int(msg.usec if kind == "VISION_POSITION_ESTIMATE" else msg.time_usec))
                p.append(mission_frame.to_ned_m(*lla))
    finally:
        log.close()
    t = np.asarray(t_us, dtype=np.int64)
    order = np.argsort(t, kind="stable")
    return t[order], np.asarray(p, dtype=float).reshape(-1, 3)[order]


def read_summary(out_dir: Path) -> dict[str, Any]:
    import json

    path = out_dir / "summary.json"
    try:
        return dict(json.loads(path.read_text()))
    except (OSError, ValueError):
        return {}
