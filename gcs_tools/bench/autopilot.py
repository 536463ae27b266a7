"""The generic MAVLink path beside a foreign autopilot (``beliefnav bench autopilot --json``).

On the real log's frames (tests/data/quad106.tlog, all of them, in order):
- ``mavutil_parse_msgs_per_s``: pymavlink's parser (what ``--master`` uses for every transport),
- ``frames_parse_msgs_per_s``: our own CRC-checked scanner (what our SITL's UdpLink uses),
- ``companion_msgs_per_s``: the whole ``--master`` receive path per message — pymavlink parse,
  discovery, time base, Navigator, run.tlog write — through a loopback UDP socket pair,
all per CPU second of this process (the machine is shared: the wall figure waits for others).
"""

from __future__ import annotations

import argparse
import os
import socket
import tempfile
import time
from pathlib import Path
from typing import Any

from companion.autopilot.connection import MavConnection, parse_connection
from companion.autopilot.node import AutopilotCompanion, CompanionConfig
from companion.mavlink.frames import parse_datagram
from companion.mavlink.tlog import TlogWriter

REAL_LOG = Path(__file__).resolve().parents[2] / "tests" / "data" / "quad106.tlog"
STAMP_BYTES = 8


def _frames(path: Path) -> list[bytes]:
    from pymavlink import mavutil

    conn = mavutil.mavlink_connection(str(path))
    out = []
    while (msg := conn.recv_match()) is not None:
        out.append(bytes(msg.get_msgbuf()))
    conn.close()
    return out


def _cpu(fn: Any) -> tuple[float, float, Any]:
    c0, w0 = time.process_time(), time.perf_counter()
    result = fn()
    return time.process_time() - c0, time.perf_counter() - w0, result


def measure(args: argparse.Namespace) -> dict[str, Any]:
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    frames = _frames(REAL_LOG)
    if getattr(args, "quick", False):
        frames = frames[:10_000]
    blob = b"".join(frames)
    parser = mavlink.MAVLink(None)
    mav_cpu, _, parsed = _cpu(lambda: parser.parse_buffer(blob) or [])
    ours_cpu, _, (ours, _) = _cpu(lambda: parse_datagram(blob))

    port = _free_port()
    with tempfile.TemporaryDirectory() as tmp:
        url = f"udpin:127.0.0.1:{port}"
        conn = MavConnection(parse_connection(url), 1, 197, TlogWriter(Path(tmp) / "run.tlog"))
        node = AutopilotCompanion(CompanionConfig(master=url, out_dir=Path(tmp)), conn)
        sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sent = received = 0
        c0, w0 = time.process_time(), time.perf_counter()
        for i in range(0, len(frames), 32):  # 32 frames at a time, read back before the next batch: no loss
            for frame in frames[i:i + 32]:
                sender.sendto(frame, ("127.0.0.1", port))
                sent += 1
            while received < sent:
                for msg in conn.recv(timeout_s=1.0):
                    node.handle(msg, time.monotonic())
                    received += 1
        node_cpu, node_wall = time.process_time() - c0, time.perf_counter() - w0
        sender.close()
        conn.close()
        assert conn.tlog is not None
        conn.tlog.close()
    return {
        "autopilot_messages": len(frames),
        "mavutil_parse_msgs_per_s": len(parsed) / mav_cpu,
        "frames_parse_msgs_per_s": len(ours) / ours_cpu,
        "companion_msgs_per_s": received / node_cpu,
        "companion_wall_msgs_per_s": received / node_wall,
        "companion_samples_used": dict(node.nav_counters()),
        "load_1min": os.getloadavg()[0],
    }


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]
