"""The ``--master`` path beside a real autopilot (``beliefnav bench autopilot --json``).

On the real log's frames (tests/data/quad106.tlog, all of them, in order):
- ``mavutil_parse_msgs_per_s``: pymavlink's byte-wise parser (for comparison),
- ``frames_parse_msgs_per_s``: our CRC-checked scanner (what ``--master`` and the SITL links use),
- ``companion_msgs_per_s``: the whole ``--master`` receive path per message — per-datagram scan,
  discovery, the clock rule, Navigator, run.tlog write — through a loopback UDP socket pair,
all per CPU second of this process (the machine is shared: the wall figure waits for others).
The log is played as fast as the path takes it (about 200x real time): the clock rule's forward
envelope (20x the arrival times) is widened to a million times for the measurement
(:data:`REPLAY_CLOCK`), otherwise it would rightly refuse a clock running that fast.

``flood``: what hostile datagrams cost the same receive path once the autopilot is found, per
datagram and per CPU µs, each kind from ``FLOOD_DATAGRAMS`` distinct source addresses (a fresh
socket each): ``junk`` (random bytes, false magic bytes), ``other_systems`` (valid HEARTBEATs of
other systems), ``forged`` (valid HIGHRES_IMU frames with the autopilot's ids, stamped an hour
ahead: refused by the clock rule). ``peers`` is how many addresses the connection answers after
each flood (bounded), ``idle_cpu_fraction_after`` the CPU share of 2 s of the loop with no traffic
after all floods (no per-sender state left to work through). The log's stream is paused during
the floods: the forged frames, all stamped alike and arriving for seconds with no genuine stamp
between them, are then (rightly, by the clock rule) believed after 0.25 s as a clock jump
(``clock_rule`` says how many were refused first); beside a streaming autopilot none is
(tests/test_fuzz_master.py).
"""

from __future__ import annotations

import argparse
import os
import socket
import tempfile
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from companion.autopilot.connection import MavConnection, parse_connection
from companion.autopilot.node import BOOT_CLOCK_DATAGRAM, AutopilotCompanion, CompanionConfig
from companion.mavlink.frames import pack_frame, parse_datagram
from companion.mavlink.tlog import TlogWriter

REAL_LOG = Path(__file__).resolve().parents[2] / "tests" / "data" / "quad106.tlog"
FLOOD_DATAGRAMS = 20_000
BATCH = 200  # datagrams sent before they are read back (well within the socket's buffer)
REPLAY_CLOCK = replace(BOOT_CLOCK_DATAGRAM, max_rate=1e6)  # a log played far faster than real time


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


def _drain(conn: MavConnection, node: AutopilotCompanion, datagrams: int) -> float:
    """CPU seconds to receive and handle ``datagrams`` datagrams already sent."""
    c0 = time.process_time()
    seen = conn.counters["datagrams"] + datagrams
    deadline = time.monotonic() + 10.0
    while conn.counters["datagrams"] < seen and time.monotonic() < deadline:
        for msg in conn.recv(timeout_s=0.05):
            node.handle(msg, time.monotonic())
    return time.process_time() - c0


def _flood(conn: MavConnection, node: AutopilotCompanion, port: int, make: Any) -> dict[str, Any]:
    cpu = 0.0
    for start in range(0, FLOOD_DATAGRAMS, BATCH):
        for k in range(start, min(start + BATCH, FLOOD_DATAGRAMS)):
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:  # a new source address each
                s.sendto(make(k), ("127.0.0.1", port))
        cpu += _drain(conn, node, min(BATCH, FLOOD_DATAGRAMS - start))
    return {"datagrams": FLOOD_DATAGRAMS, "cpu_us_per_datagram": cpu / FLOOD_DATAGRAMS * 1e6,
            "peers": len(conn.peer_addresses)}


def _floods(frames: list[bytes], tmp: Path) -> dict[str, Any]:
    """The floods of the module doc, on a companion that has found the log's autopilot."""
    from pymavlink.dialects.v20 import common as mavlink

    port = _free_port()
    url = f"udpin:127.0.0.1:{port}"
    conn = MavConnection(parse_connection(url), 1, 197, TlogWriter(tmp / "flood.tlog"))
    node = AutopilotCompanion(CompanionConfig(master=url, out_dir=tmp), conn)  # the clock rule as deployed
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as autopilot:
        for start in range(0, 1500, 50):  # the log's first frames (~13 s of it) at ~10x: found, streaming
            for frame in frames[start:start + 50]:
                autopilot.sendto(frame, ("127.0.0.1", port))
            _drain(conn, node, 50)
            time.sleep(0.04)
    assert node.discovery.autopilot is not None, "the log's autopilot was not found"
    base = node.clock.base_us or 0
    rng = np.random.default_rng(26)
    junk_pool = [rng.integers(0, 256, int(n), dtype=np.uint8).tobytes() for n in rng.integers(8, 300, 500)]
    junk_pool += [bytes((0xFD, 0xFF, 0, 0)) + j[:40] for j in junk_pool[:100]]
    hb = mavlink.MAVLink_heartbeat_message(2, 12, 0, 0, 4, 3)
    forged = mavlink.MAVLink_highres_imu_message(base + 3_600_000_000, 0, 0, -9.8, *[0] * 10, 63, 0)
    out: dict[str, Any] = {
        "junk": _flood(conn, node, port, lambda k: junk_pool[k % len(junk_pool)]),
        "other_systems": _flood(conn, node, port, lambda k: pack_frame(hb, k & 0xFF, 2 + k % 250, 1)),
        "forged": _flood(conn, node, port, lambda k: pack_frame(forged, k & 0xFF, 1, 1)),
    }
    c0, w0 = time.process_time(), time.monotonic()
    while time.monotonic() - w0 < 2.0:  # the loop with nothing arriving
        node.tick(time.monotonic())
        conn.recv(timeout_s=0.02)
    out["idle_cpu_fraction_after"] = (time.process_time() - c0) / (time.monotonic() - w0)
    out["clock_rule"] = {k: v for k, v in node.counters.items()
                         if k.startswith(("rejected_clock", "autopilot_"))}
    out["link"] = {k: conn.counters[k] for k in ("garbage", "bad_crc", "unknown_message", "peers_refused")}
    conn.close()
    assert conn.tlog is not None
    conn.tlog.close()
    return out


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
        config = CompanionConfig(master=url, out_dir=Path(tmp), boot_clock=REPLAY_CLOCK)
        node = AutopilotCompanion(config, conn)
        sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sent = received = 0
        c0, w0 = time.process_time(), time.perf_counter()
        for i in range(0, len(frames), 32):  # 32 frames at a time, read back before the next batch: no loss
            for frame in frames[i:i + 32]:
                sender.sendto(frame, ("127.0.0.1", port))
                sent += 1
            while received < sent:
                batch = conn.recv(timeout_s=1.0)
                for msg in batch:
                    node.handle(msg, time.monotonic())
                received += len(batch)
                if not batch:
                    break
        node_cpu, node_wall = time.process_time() - c0, time.perf_counter() - w0
        sender.close()
        conn.close()
        assert conn.tlog is not None
        conn.tlog.close()
        flood = _floods(frames, Path(tmp))
    return {
        "autopilot_messages": len(frames),
        "mavutil_parse_msgs_per_s": len(parsed) / mav_cpu,
        "frames_parse_msgs_per_s": len(ours) / ours_cpu,
        "companion_msgs_per_s": received / node_cpu,
        "companion_wall_msgs_per_s": received / node_wall,
        "companion_samples_used": dict(node.nav_counters()),
        "flood": flood,
        "load_1min": os.getloadavg()[0],
    }


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]
