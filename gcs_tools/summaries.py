"""The human summary of a flight (``fly``, ``sitl``): a few readable lines; ``--json`` prints the
summary itself instead."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from gcs_tools.jsonvalues import plain_json


def _m(x: Any) -> str:
    return "n/a" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.2f} m"


def flight_lines(command: str, s: dict[str, Any], out: Path, files: Sequence[str]) -> list[str]:
    est, trk = s["estimation_error_m"], s["tracking_error_m"]
    sitl = s.get("sitl")
    lock = sitl["lockstep"] if sitl and sitl["mode"] == "lockstep" else None
    how = f" ({sitl['mode']})" if sitl else ""
    outcome = sitl["outcome"] if sitl else ("reached goal" if s["reached_goal"] else "did not reach the goal")
    lines = [
        f"{command} {s['method']} seed {s['seed']}{how}, {s['mission']} profile {s['profile']}: "
        f"{outcome.replace('_', ' ')} after {s['duration_s']:.1f} s simulated in {s['wall_s']:.1f} s wall"
        + (f" (ended by {sitl['ended_by']})" if sitl else ""),
        f"  estimation error median {_m(est['median'])} p95 {_m(est['p95'])}; tracking error median "
        f"{_m(trk['median'])} p95 {_m(trk['p95'])}; min clearance {_m(s['min_clearance_m'])}",
        f"  GNSS fixes sent {s['gnss']['sent']} fused {s['gnss']['fused']} rejected {s['gnss']['rejected']};"
        f" collisions {s['collisions']}"
        + (f"; lockstep waits {lock.get('retries', 0)}, gave up {lock.get('gave_up', 0)}" if lock else ""),
        f"  wrote {out}/: {', '.join(files)}",
    ]
    return lines


def print_summary(command: str, s: dict[str, Any], out: Path, files: Sequence[str], as_json: bool) -> None:
    if as_json:
        print(json.dumps(plain_json(s, nan_to_none=True), indent=2, allow_nan=False))
    else:
        print("\n".join(flight_lines(command, s, out, files)))
