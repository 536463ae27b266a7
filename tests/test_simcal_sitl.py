"""SITL under the canyon scenario: the vehicle process serves its receiver's UBX on TCP; a client reads
it while the flight runs, decodes it with pyubx2 and companion.gnss.ubx, and finds the same fixes the
vehicle sent as GPS_RAW_INT (same position, validity time = receiver.json's GPS time of boot + boot time)."""

from __future__ import annotations

import io
import json
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from pyubx2 import UBXReader
from sitl_helpers import children_of, require_pieces

from companion.gnss.observations import GnssEpoch
from companion.gnss.timescale import week_tow
from companion.gnss.ubx import ReceiverPvt, UbxDecoder

pytestmark = [pytest.mark.slow, pytest.mark.timeout(90)]


def _read_stream(info_path: Path, sink: dict, deadline_s: float) -> None:
    end = time.monotonic() + deadline_s
    while time.monotonic() < end and not info_path.exists():
        time.sleep(0.02)
    try:
        info = json.loads(info_path.read_text())
    except (OSError, ValueError):
        return
    sink["info"] = info
    _, host, port = info["ubx"].split(":")
    data = b""
    with socket.create_connection((host, int(port)), timeout=30) as s:
        while chunk := s.recv(1 << 16):
            data += chunk
    sink["data"] = data


def test_sitl_canyon_streams_ubx_matching_its_gps_raw_int(tmp_path):
    require_pieces()
    out = tmp_path / "run"
    got: dict = {}
    reader = threading.Thread(target=_read_stream, args=(out / "receiver.json", got, 40.0), daemon=True)
    reader.start()
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "gcs_tools",
            "sitl",
            "--no-progress",
            "--no-figures",
            "--mission",
            "test",
            "--scenario",
            "canyon",
            "--profile",
            "0",
            "--max-duration-s",
            "8",
            "--no-telemetry",
            "--no-ground-out",
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=80,
    )
    reader.join(timeout=10)
    assert not children_of(out)
    assert "data" in got, done.stderr
    vehicle = json.loads((out / "vehicle.json").read_text())
    assert vehicle["ubx"]["clients"] == 1 and vehicle["ubx"]["dropped_slow"] == 0
    assert (out / "receiver.ubx").read_bytes() == got["data"]  # the log holds what the client got
    dec = UbxDecoder()
    epochs, pvts = [], []
    for _, msg in UBXReader(io.BytesIO(got["data"]), protfilter=2):
        item = dec.feed(msg)
        if isinstance(item, GnssEpoch):
            epochs.append(item)
        elif isinstance(item, ReceiverPvt):
            pvts.append(item)
    assert 30 <= len(epochs) <= 41 and all(e.n >= 4 for e in epochs)  # 5 Hz for 8 s
    # the fixes on the MAVLink link (GPS_RAW_INT, validity on the boot clock) are the NAV-PVT solutions
    from companion.mavlink.tlog import read_tlog

    raw_int = {int(m.time_usec): m for _, m in read_tlog(out / "run.tlog", ("GPS_RAW_INT",))}
    assert len(raw_int) >= 25
    t0 = got["info"]["t0_gps_s"]
    by_itow = {round(week_tow(p.t_gps_s)[1] * 1000): p for p in pvts}
    matched = 0
    for t_us, m in raw_int.items():
        p = by_itow.get(round(week_tow(t0 + t_us * 1e-6)[1] * 1000))
        if p is None:
            continue
        matched += 1
        assert abs(p.lat_deg - m.lat / 1e7) < 2e-7 and abs(p.lon_deg - m.lon / 1e7) < 2e-7
        assert abs(p.height_ellipsoid_m - m.alt / 1e3) < 0.01 and p.num_sv == m.satellites_visible
    assert matched >= len(raw_int) - 1  # (the last fix may be cut by the time limit)
    _replay_tight(out, raw_int)


def _replay_tight(out: Path, raw_int: dict) -> None:
    """``beliefnav replay run.tlog --ubx receiver.ubx --coupling tight``: the raw epochs join the log's boot
    time through receiver.json (each within the receiver's clock offset, < 1 ms, of the fix the vehicle
    sent from it); no map without a mission, the mission's map (and home) with ``--mission``."""
    import numpy as np

    from gcs_tools.cli import main
    from gcs_tools.gnss.tight_replay import ubx_raw_log_reader

    reader, _, note = ubx_raw_log_reader(out / "run.tlog", out / "receiver.ubx")
    t_raw = np.array([r.t_us for r in reader.items])
    assert note["epochs"] == len(t_raw) >= 30
    for t_us in raw_int:
        assert np.min(np.abs(t_raw - t_us)) < 1_000
    base = ["replay", str(out / "run.tlog"), "--ubx", str(out / "receiver.ubx"), "--coupling", "tight",
            "--no-progress", "--no-telemetry", "--no-figures"]  # figures: test_replay_figures
    summaries = []
    for extra, name in (([], "nomap"), (["--mission", "test"], "map")):
        assert main([*base, *extra, "--out", str(out / name)]) == 0
        summaries.append(json.loads((out / name / "summary.json").read_text()))
    nomap, withmap = summaries
    assert nomap["raw_gnss"]["map"] is None and withmap["raw_gnss"]["map"].startswith("mission test")
    for s in summaries:
        nav, truth = s["navigator"], s["errors"]["truth"]
        assert nav["gnss_fused"] >= len(t_raw) - 3 and nav["gnss_rejected_no_ephemeris"] == 0
        assert truth["error_horizontal_m"]["median"] < 30.0 and truth["coverage_horizontal"]["n"] > 100
    assert main([*base, "--out", str(out / "bad"), "--rinex-nav", "x.nav"]) == 2  # one raw source
