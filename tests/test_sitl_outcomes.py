"""Truthful outcomes: a vehicle killed with SIGKILL is named with its signal, and what it recorded
up to its last second survives (the spooled series, every process's counters)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
from sitl_helpers import children_of

from simvehicle.recording import ROW_FLOATS, SERIES_KEYS, FlightRecorder, series_from_rows


def _out(t_s: float):
    truth = SimpleNamespace(p_ned_m=np.array([t_s, 0.0, -10.0]), v_ned_m_s=np.zeros(3),
                            gnss_bias_ned_m=np.array([0.1, 0.2, 0.0]), gnss_latency_s=0.3, clearance_m=5.0,
                            q_ned_frd=np.array([1.0, 0.0, 0.0, 0.0]))
    return SimpleNamespace(truth=[truth], t_us=round(t_s * 1e6))


def test_spooled_rows_equal_the_in_memory_record_and_a_cut_row_is_dropped(tmp_path):
    spool = tmp_path / "rows.f64"
    a = FlightRecorder(np.zeros(3), 1.0, 0.5, 0.0, spool_path=spool)
    b = FlightRecorder(np.zeros(3), 1.0, 0.5, 0.0)
    for k in range(50):
        for rec in (a, b):
            rec.record(_out(0.05 * k), None, None, 0.5, 1.0)
        if k % 7 == 0:
            a.flush()
    a.flush()
    assert spool.stat().st_size == 50 * ROW_FLOATS * 8
    sa, sb = series_from_rows(spool.read_bytes()[:-5]), b.series()  # a kill mid-write: 49 whole rows
    assert tuple(sa) == SERIES_KEYS and sa["t_s"].shape == (49,)
    for key in SERIES_KEYS:
        np.testing.assert_array_equal(sa[key], sb[key][:49], err_msg=key)
    a.save(tmp_path / "s.npz")
    assert not spool.exists()
    with np.load(tmp_path / "s.npz") as saved:
        np.testing.assert_array_equal(saved["p_true_ned_m"], sb["p_true_ned_m"])


def test_vehicle_killed_run_names_the_signal_and_keeps_the_record(tmp_path):
    out = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "gcs_tools", "sitl", "--no-progress", "--no-telemetry",
                             "--no-figures", "--mission", "test", "--realtime", "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        stats = out / "vehicle.json"
        while not stats.exists() or json.loads(stats.read_text())["t_s"] < 3:
            assert time.monotonic() < deadline and proc.poll() is None
            time.sleep(0.2)
        vehicle = next(p for p in children_of(out)
                       if b"simvehicle" in Path(f"/proc/{p}/cmdline").read_bytes())
        os.kill(vehicle, signal.SIGKILL)
        _, stderr = proc.communicate(timeout=40)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 1
    assert stderr.strip().splitlines()[-1] == "beliefnav: error: vehicle process killed by SIGKILL"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["sitl"]["ended_by"] == "crash:vehicle" and not summary["reached_goal"]
    assert summary["duration_s"] >= 2.0  # the spooled record, up to its last second
    assert summary["gnss"]["fused"] > 20 and summary["gnss"]["sent"] > 20  # counters of the last second
    assert (out / "vehicle_series.f64").exists() and not (out / "vehicle_series.npz").exists()
