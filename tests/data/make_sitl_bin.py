"""Make ``tests/data/arducopter_sitl_hover.bin``: a short ArduCopter SITL flight's DataFlash log.

How the committed log was made (kept so it can be made again; not run by the tests)::

    python tests/data/make_sitl_bin.py --arducopter ../shared/tools/ardupilot/arducopter \
        --out tests/data/arducopter_sitl_hover.bin

It starts ArduCopter SITL (``-I 40``, ``--speedup 10``, the autotest defaults in
``copter.parm`` plus the logging parameters below) in a temporary directory, waits for the EKF
to use GPS, arms in GUIDED, takes off to 10 m, hovers, lands, disarms and copies the
DataFlash log the autopilot wrote under ``logs/``.
"""

from __future__ import annotations

import argparse
import shutil
import struct
import subprocess
import tempfile
import time
from pathlib import Path

from pymavlink import mavutil
from pymavlink.DFReader import FORMAT_TO_STRUCT

HOME = "-35.363261,149.165230,584,353"  # ArduPilot's autotest home (CMAC, Canberra)
# Loop-rate IMU and attitude (IMU_FAST, ATTITUDE_FAST on top of the default bitmask), logging
# from boot so the ground phase with GPS is in the log too.
EXTRA_PARAMS = {"LOG_BITMASK": 176126 | 1 | 262144, "LOG_DISARMED": 1, "SCHED_LOOP_RATE": 200}


# What the replay reads (and a little context); the rest (ESC, RATE, PID, ...) is dropped to
# keep the file small. IMU and XKF1/XKQ of the second instance/core are dropped too.
KEEP = frozenset({"FMT", "FMTU", "UNIT", "MULT", "PARM", "MSG", "VER", "MODE", "EV", "ARM", "ORGN",
                  "IMU", "ATT", "XKQ", "XKF1", "POS", "GPS", "GPA", "SIM", "BARO"})
FIRST_ONLY = {"IMU": "I", "XKQ": "C", "XKF1": "C", "GPS": "I", "GPA": "I"}
HEAD = b"\xa3\x95"
FMT_TYPE = 128


def trim(src: Path, dst: Path, keep: frozenset[str]) -> tuple[int, int]:
    """Copy the DataFlash messages of the types in ``keep`` (instance/core 0 only for those in
    FIRST_ONLY) from ``src`` to ``dst``, byte for byte; returns (kept, dropped)."""
    data = src.read_bytes()
    lengths: dict[int, tuple[str, int]] = {FMT_TYPE: ("FMT", 89)}
    instance_offset: dict[int, int] = {}  # type -> byte offset of its instance field
    out = bytearray()
    pos, kept, dropped = 0, 0, 0
    while pos + 3 <= len(data):
        if data[pos : pos + 2] != HEAD or data[pos + 2] not in lengths:
            raise SystemExit(f"{src}: unexpected bytes at {pos}")
        name, length = lengths[data[pos + 2]]
        msg = data[pos : pos + length]
        if len(msg) < length:
            break  # the log's last message was cut by the stop
        if name == "FMT":
            mtype, mlen = msg[3], msg[4]
            mname = msg[5:9].rstrip(b"\0").decode()
            fmt = msg[9:25].rstrip(b"\0").decode()
            cols = msg[25:89].rstrip(b"\0").decode().split(",")
            lengths[mtype] = (mname, mlen)
            if mname in FIRST_ONLY:
                k = cols.index(FIRST_ONLY[mname])
                layout = "<" + "".join(FORMAT_TO_STRUCT[c][0] for c in fmt[:k])
                instance_offset[mtype] = 3 + struct.calcsize(layout)
        k = instance_offset.get(data[pos + 2])
        if name in keep and (k is None or msg[k] == 0):
            out += msg
            kept += 1
        else:
            dropped += 1
        pos += length
    dst.write_bytes(bytes(out))
    return kept, dropped


def wait_text(mav: mavutil.mavfile, needle: str, timeout_s: float) -> None:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        msg = mav.recv_match(type="STATUSTEXT", blocking=True, timeout=1)
        if msg is not None:
            print("  ", msg.text)
            if needle in msg.text:
                return
    raise SystemExit(f"no {needle!r} within {timeout_s} s")


def command(mav: mavutil.mavfile, cmd: int, *params: float) -> None:
    p = [*params, 0, 0, 0, 0, 0, 0, 0][:7]
    mav.mav.command_long_send(mav.target_system, mav.target_component, cmd, 0, *p)


def fly(mav: mavutil.mavfile, hover_s: float) -> None:
    mav.wait_heartbeat()
    mav.mav.request_data_stream_send(mav.target_system, mav.target_component,
                                     mavutil.mavlink.MAV_DATA_STREAM_ALL, 4, 1)
    wait_text(mav, "using GPS", 60)
    mav.set_mode("GUIDED")
    for _ in range(60):
        command(mav, mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)
        ack = mav.recv_match(type="COMMAND_ACK", blocking=True, timeout=2)
        arm = mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM
        if ack is not None and ack.command == arm and ack.result == 0:
            break
        time.sleep(0.5)
    else:
        raise SystemExit("would not arm")
    command(mav, mavutil.mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 10)
    time.sleep(hover_s)
    mav.set_mode("LAND")
    end = time.monotonic() + 30
    while time.monotonic() < end:
        hb = mav.recv_match(type="HEARTBEAT", blocking=True, timeout=2)
        if hb is not None and not hb.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED:
            return
    raise SystemExit("did not land and disarm")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--arducopter", type=Path, required=True)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--instance", type=int, default=40)
    ap.add_argument("--speedup", type=int, default=10)
    ap.add_argument("--hover-s", type=float, default=2.0, help="wall seconds between take-off and land")
    args = ap.parse_args()
    arducopter = args.arducopter.resolve()
    with tempfile.TemporaryDirectory() as tmp:
        run = Path(tmp)
        extra = run / "extra.parm"
        extra.write_text("".join(f"{k} {v}\n" for k, v in EXTRA_PARAMS.items()))
        defaults = f"{arducopter.parent / 'copter.parm'},{extra}"
        proc = subprocess.Popen(
            [str(arducopter), "--model", "+", "--speedup", str(args.speedup), "--home", HOME,
             "--defaults", defaults, f"-I{args.instance}", "-w"],
            cwd=run, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            time.sleep(1.0)
            mav = mavutil.mavlink_connection(f"tcp:127.0.0.1:{5760 + 10 * args.instance}")
            fly(mav, args.hover_s)
            time.sleep(1.0)
        finally:
            proc.terminate()
            proc.wait(10)
        logs = sorted((run / "logs").glob("*.BIN"))
        if not logs:
            raise SystemExit("SITL wrote no log")
        shutil.copyfile(logs[-1], run / "full.bin")
        kept, dropped = trim(run / "full.bin", args.out, KEEP)
        print(f"wrote {args.out} ({args.out.stat().st_size} bytes) from {logs[-1].name}: "
              f"kept {kept} messages, dropped {dropped}")


if __name__ == "__main__":
    main()
