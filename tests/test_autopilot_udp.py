"""A real flight log (quad106, PX4-style streams) played over UDP into ``beliefnav companion --master
udpin:`` — no mission, no home given: the frame comes from the log itself. Also: answers on the
same socket (HEARTBEAT, stream requests, TIMESYNC), other systems and bad frames counted."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import time
from pathlib import Path

from ardupilot_helpers import run_companion, stop
from pymavlink import mavutil

from gcs_tools import cli

M = mavutil.mavlink
LOG = Path(__file__).parent / "data" / "quad106.tlog"
LOG_SECONDS = 40.0  # of the log streamed
SPEEDUP = 10.0  # x real time


def _frames(seconds: float) -> list[tuple[float, str, bytes]]:
    conn = mavutil.mavlink_connection(str(LOG))
    out: list[tuple[float, str, bytes]] = []
    t0 = None
    while (msg := conn.recv_match()) is not None:
        t0 = msg._timestamp if t0 is None else t0
        if msg._timestamp - t0 > seconds:
            break
        out.append((msg._timestamp - t0, msg.get_type(), bytes(msg.get_msgbuf())))
    conn.close()
    return out


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_quad106_streamed_to_udpin_estimates_near_home_and_answers(tmp_path):
    frames = _frames(LOG_SECONDS)
    port = _free_udp_port()
    out = tmp_path / "companion"
    proc = run_companion(f"udpin:127.0.0.1:{port}", out, "--duration-s", "60")
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setblocking(False)
    parser = M.MAVLink(None)
    parser.robust_parsing = True
    replies = []
    stranger = M.MAVLink(None, srcSystem=9, srcComponent=1)
    log_sysid = M.MAVLink(None, srcSystem=1, srcComponent=1)

    def drain() -> None:
        while True:
            try:
                data = sock.recv(65536)
            except BlockingIOError:
                return
            replies.extend(m for m in parser.parse_buffer(data) or [] if m.get_type() != "BAD_DATA")

    try:
        heartbeat = next(f for _, kind, f in frames if kind == "HEARTBEAT")  # the log's own
        deadline = time.monotonic() + 30
        while not any(m.get_type() == "HEARTBEAT" for m in replies):  # until it has found the "autopilot"
            assert time.monotonic() < deadline and proc.poll() is None
            sock.sendto(heartbeat, ("127.0.0.1", port))
            time.sleep(0.2)
            drain()
        other = stranger.heartbeat_encode(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_PX4, 0, 0, 0)
        sock.sendto(other.pack(stranger), ("127.0.0.1", port))
        sock.sendto(log_sysid.timesync_encode(0, 777_000).pack(log_sysid), ("127.0.0.1", port))
        sock.sendto(b"\xfd\x09garbage-not-mavlink", ("127.0.0.1", port))  # eats the start of what follows
        start = time.monotonic()
        for t_s, _, frame in frames:
            delay = t_s / SPEEDUP - (time.monotonic() - start)
            if delay > 0:
                time.sleep(delay)
                drain()
            sock.sendto(frame, ("127.0.0.1", port))
        time.sleep(1.0)
        drain()
    finally:
        sock.close()
        code, err = stop(proc)
    assert code in (0, 143), err
    s = json.loads((out / "summary.json").read_text())
    assert s["autopilot"]["system_id"] == 1
    home = s["home"]
    assert home["source"] == "first good fix" and abs(home["lat_deg"] + 37.859491) < 1e-6
    est = s["estimate"]
    assert est["count"] > 200 and est["max_horizontal_from_home_m"] < 100  # not 11,000 km away
    used = s["samples"]["used"]
    assert used["gnss"] > 0.8 * 5 * LOG_SECONDS and used["imu"] > 0.8 * 50 * LOG_SECONDS
    rejected = s["samples"]["rejected"]
    assert rejected.get("autopilot_other_system", 0) >= 1 and s["link"].get("garbage", 0) >= 1
    assert rejected.get("autopilot_conflicting_autopilot") == 1  # system 9 says it is a PX4 quadrotor too
    assert len(s["problems"]) == 1 and "a second autopilot (system 9" in s["problems"][0]
    assert s["errors"]["autopilot_estimate"] is None  # the log carries no autopilot estimate
    ours = [m for m in replies if (m.get_srcSystem(), m.get_srcComponent()) == (1, 197)]
    assert any(m.get_type() == "HEARTBEAT" and m.type == M.MAV_TYPE_ONBOARD_CONTROLLER for m in ours)
    assert any(m.get_type() == "COMMAND_LONG" and m.command == M.MAV_CMD_SET_MESSAGE_INTERVAL
               and m.target_system == 1 for m in ours)
    assert any(m.get_type() == "TIMESYNC" and m.tc1 > 0 and m.ts1 == 777_000 for m in ours)


def test_companion_command_line_errors_are_one_line(tmp_path, capsys):
    for args, why in ((["--master", "bogus:1", "--out", str(tmp_path)], "expected tcp"),
                      (["--master", "udpin::14550"], "--out DIR is required"),
                      (["--master", "udpin::14550", "--out", str(tmp_path), "--home", "1,2"], "--home")):
        assert cli.main(["companion", *args, "--no-telemetry"]) == 2
        err = capsys.readouterr().err
        assert err.startswith("beliefnav: error:") and why in err and len(err.strip().splitlines()) == 1, err
    r = subprocess.run([sys.executable, "-m", "companion", "estimator", "--master", "udpin::1"],
                       capture_output=True, text=True, timeout=60)  # the same mode, the process's own entry
    assert r.returncode == 2 and "--out DIR is required" in r.stderr
