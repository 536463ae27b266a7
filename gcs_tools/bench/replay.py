"""Replay speed and memory: ``beliefnav bench replay --json``.

``measure_replay(path, method)`` -> simulated s per wall s on one log, with the read/estimator
split measured (a read+decode-only pass over the same file, and the time spent inside the
navigator); the estimator benchmark quotes it too.

``measure(args)``: the peak resident memory (``ru_maxrss``) of a fresh process replaying quad106
once and concatenated 20 times (``--quick``: 5 times), as ``beliefnav replay --out`` does it
(estimates streamed to CSV), against the same process's peak after only importing everything
(``baseline``): memory flat in the log's length means the 1x and 20x growth figures agree.
The concatenated log restarts its boot time at every copy; the printed counters are the
navigators' own, summed over the segments.
"""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from companion.estimator.methods import DEFAULT_METHOD
from gcs_tools.replay import core
from gcs_tools.replay.tlog_source import TlogSource

REAL_LOG = Path(__file__).resolve().parents[2] / "tests" / "data" / "quad106.tlog"
CHILD = """
import json, resource, sys, time
from pathlib import Path
from gcs_tools.replay import core
import companion.estimator  # noqa: F401  (imported in the baseline too)
path, method, out = sys.argv[1], sys.argv[2], sys.argv[3]
result = None
cpu0 = time.process_time()
if path != "-":
    result = core.replay(Path(path), method, out_dir=Path(out))
cpu_s = time.process_time() - cpu0
s = result.summary if result else {}
print(json.dumps({"max_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "cpu_s": cpu_s, "wall_s": s.get("wall_s"), "duration_s": s.get("duration_s"),
                  "log_restarts": s.get("log_restarts"), "navigator": s.get("navigator"),
                  "samples_used": s.get("samples_used")}))
"""


def measure_read(path: Path) -> float:
    """Wall seconds to read and decode every estimator input of ``path`` (no estimator)."""
    t0 = time.perf_counter()
    for _ in TlogSource(path):
        pass
    return time.perf_counter() - t0


def measure_replay(path: str | Path = REAL_LOG, method: str = DEFAULT_METHOD) -> dict[str, Any]:
    path = Path(path)
    read_s = measure_read(path)
    cpu0 = time.process_time()
    result = core.replay(path, method)
    cpu_s = time.process_time() - cpu0
    s = result.summary
    return {
        "replay_realtime_factor": s["realtime_factor"],
        # per CPU second of this process (the machine is shared: wall time includes waiting)
        "replay_realtime_factor_cpu": s["duration_s"] / cpu_s,
        "replay_log_duration_s": s["duration_s"],
        "replay_wall_s": s["wall_s"],
        "replay_estimator_s": s["timing_s"]["estimator"],
        "replay_read_decode_only_s": read_s,
        "replay_read_realtime_factor": s["duration_s"] / read_s,
        "replay_method": method,
    }


def _child(path: str, method: str, out: Path) -> dict[str, Any]:
    proc = subprocess.run([sys.executable, "-c", CHILD, path, method, str(out)], capture_output=True,
                          text=True, check=False)
    if proc.returncode != 0:
        raise RuntimeError(f"replay child failed: {proc.stderr.strip().splitlines()[-1:]}")
    return dict(json.loads(proc.stdout.strip().splitlines()[-1]))


def measure(args: Any) -> dict[str, Any]:
    method = DEFAULT_METHOD
    copies = 5 if getattr(args, "quick", False) else 20
    with tempfile.TemporaryDirectory() as tmp:
        big = Path(tmp) / f"quad106x{copies}.tlog"
        data = REAL_LOG.read_bytes()
        with open(big, "wb") as f:
            for _ in range(copies):
                f.write(data)
        del data
        baseline = _child("-", method, Path(tmp) / "base")
        one = _child(str(REAL_LOG), method, Path(tmp) / "one")
        many = _child(str(big), method, Path(tmp) / "many")
        size_mb = big.stat().st_size / 2**20
    base = baseline["max_rss_mb"]
    load = float("nan")
    with contextlib.suppress(OSError):
        load = os.getloadavg()[0]
    return {
        "replay_method": method,
        "replay_realtime_factor": one["duration_s"] / one["wall_s"],
        "replay_realtime_factor_cpu": one["duration_s"] / one["cpu_s"],
        "replay_wall_s_1x": one["wall_s"],
        "replay_cpu_s_1x": one["cpu_s"],
        "replay_log_s_1x": one["duration_s"],
        "replay_rss_baseline_mb": base,
        "replay_rss_1x_mb": one["max_rss_mb"],
        f"replay_rss_{copies}x_mb": many["max_rss_mb"],
        "replay_rss_growth_1x_mb": one["max_rss_mb"] - base,
        f"replay_rss_growth_{copies}x_mb": many["max_rss_mb"] - base,
        f"replay_log_mb_{copies}x": size_mb,
        f"replay_log_s_{copies}x": many["duration_s"],
        f"replay_wall_s_{copies}x": many["wall_s"],
        f"replay_cpu_s_{copies}x": many["cpu_s"],
        f"replay_log_restarts_{copies}x": many["log_restarts"],
        f"replay_navigator_{copies}x": many["navigator"],
        f"replay_read_{copies}x": many["samples_used"],
        "load_1min": load,
    }
