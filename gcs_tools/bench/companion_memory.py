"""``beliefnav bench companion-memory``: the resident memory of ``beliefnav companion --master`` beside
PX4 SITL over a long run: flat, or it grows.

A PX4 SITL (SIH quadrotor on the ground, ``PX4_SIM_SPEED_FACTOR`` = :data:`SPEED_FACTOR`) and the
companion as its own process (``python -m companion estimator --master udpin:...``, no telemetry)
run until the autopilot's boot time has advanced :data:`SIM_MINUTES` simulated minutes
(``--quick``: :data:`QUICK_SIM_MINUTES`). Every :data:`SAMPLE_S` wall seconds the companion's
resident set (``/proc/<pid>/status`` VmRSS) is read with the autopilot's boot time from the
companion's own summary.json (rewritten every second).

Figures: ``rss_mb_by_sim_min`` (at each whole simulated minute), ``rss_growth_mb_10_to_end`` and
``rss_growth_mb_per_sim_hour`` (least squares over the samples after 10 simulated minutes),
``sim_s_per_wall_s`` (the speed PX4 reached), the companion's samples used, comparisons made and
CPU seconds, and the machine's 1-minute load.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from simvehicle.harness.px4.sitl import Px4Config, Px4Sitl

SPEED_FACTOR = 10.0  # the most PX4 reaches on two cores (9.5x measured)
SIM_MINUTES = 60.0
QUICK_SIM_MINUTES = 5.0
SAMPLE_S = 2.0  # wall seconds between RSS samples
WALL_LIMIT_FACTOR = 3.0  # give up when the run takes this many times the nominal wall time


def _rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    raise RuntimeError("no VmRSS")


def _boot_s(out: Path) -> float | None:
    try:
        s = json.loads((out / "summary.json").read_text())
    except (OSError, ValueError):
        return None
    base = (s.get("clock") or {}).get("base_us")
    return None if base is None else base / 1e6


def measure(args: argparse.Namespace) -> dict[str, Any]:
    sim_minutes = QUICK_SIM_MINUTES if getattr(args, "quick", False) else SIM_MINUTES
    with tempfile.TemporaryDirectory(prefix="beliefnav-bench-companion-memory-") as tmp:
        work = Path(tmp)
        out = work / "companion"
        with Px4Sitl(Px4Config(work_dir=work / "px4", speed_factor=SPEED_FACTOR)) as px4:
            proc = subprocess.Popen(
                [sys.executable, "-m", "companion", "estimator", "--master", px4.url, "--out", str(out),
                 "--no-telemetry"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
            samples: list[tuple[float, float, float]] = []  # (wall s, autopilot boot s, RSS MB)
            start = time.monotonic()
            boot0 = None
            limit_s = WALL_LIMIT_FACTOR * sim_minutes * 60.0 / SPEED_FACTOR + 60.0
            try:
                while time.monotonic() - start < limit_s and proc.poll() is None:
                    time.sleep(SAMPLE_S)
                    boot = _boot_s(out)
                    if boot is None:
                        continue
                    boot0 = boot if boot0 is None else boot0
                    samples.append((time.monotonic() - start, boot - boot0, _rss_mb(proc.pid)))
                    if boot - boot0 >= sim_minutes * 60.0:
                        break
            finally:
                proc.terminate()
                _, err = proc.communicate(timeout=30)
        summary = json.loads((out / "summary.json").read_text())
    if not samples:
        raise RuntimeError(f"the companion never found PX4: {err[-500:]}")
    wall = np.array([s[0] for s in samples])
    sim_min = np.array([s[1] for s in samples]) / 60.0
    rss = np.array([s[2] for s in samples])
    by_min = {}
    for minute in (1, 2, 5, 10, 20, 30, 40, 50, 60):
        k = int(np.searchsorted(sim_min, minute))
        if minute <= sim_min[-1] and k < len(rss):
            by_min[str(minute)] = round(float(rss[k]), 2)
    late = sim_min >= min(10.0, sim_min[-1] / 2)
    slope = float(np.polyfit(sim_min[late], rss[late], 1)[0]) * 60.0 if late.sum() > 2 else float("nan")
    err_block = (summary.get("errors") or {}).get("autopilot_estimate") or {}
    return {
        "autopilot": "PX4 SITL (SIH quadrotor, on the ground)",
        "speed_factor": SPEED_FACTOR,
        "sim_minutes": round(float(sim_min[-1]), 2),
        "wall_s": round(float(wall[-1]), 1),
        "sim_s_per_wall_s": round(float(sim_min[-1] * 60.0 / (wall[-1] - wall[0] + 1e-9)), 2)
        if len(wall) > 1 else None,
        "rss_mb_by_sim_min": by_min,
        "rss_mb_first": round(float(rss[0]), 2),
        "rss_mb_last": round(float(rss[-1]), 2),
        "rss_growth_mb_10_to_end": round(float(rss[-1] - rss[np.argmax(late)]), 2),
        "rss_growth_mb_per_sim_hour": round(slope, 2),
        "samples_used": summary["samples"]["used"],
        "comparisons": (err_block.get("error_horizontal_m") or {}).get("count"),
        "companion_cpu_s": round(float(summary["cpu_s"]), 1),
        "problems": summary["problems"],
        "load_1min": os.getloadavg()[0],
    }
