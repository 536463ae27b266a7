"""The human summary of a flight (``fly``, ``sitl``): a few readable lines; ``--json`` prints the
summary itself instead."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from gcs_tools.jsonvalues import plain_json


def run_info(mission: Any, given: str, start_unix_s: float) -> dict[str, Any]:
    """What a run records about itself beside the flight's summary (export's metadata): the mission
    as given on the command line, the sensor scenario, the wall clock of the start, the version."""
    from gcs_tools.cli import version

    return {"mission_source": given, "scenario": mission.scenario, "start_unix_s": start_unix_s,
            "beliefnav_version": version()}


def _m(x: Any) -> str:
    return "n/a" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.2f} m"


def _collisions(n: int) -> str:
    return "no collision" if n == 0 else f"{n} collision{'s' if n > 1 else ''}"


REJECTION_WORDS = {"innovation": "by the innovation gate", "too_old": "too old", "future": "from the future",
                   "duplicate": "repeated", "nonfinite": "not finite",
                   "before_imu": "before the first IMU sample", "fix_type": "without a 3-D fix"}


def gnss_line(g: dict[str, int], counters: dict[str, int] | None = None) -> str:
    """``GNSS fixes: 2,665 sent, 2,660 fused, 1 rejected (1 too old), 4 not yet delivered at the
    end``: the parts add up (a fix still inside the simulated receiver latency when the flight ends
    is neither fused nor rejected); the rejections by reason from the estimator's ``counters``."""
    sent, fused, rejected = g["sent"], g["fused"], g["rejected"]
    pending = sent - fused - rejected
    text = (f"GNSS fixes: {sent:,} sent, {fused:,} fused, "
            + (f"{rejected:,} rejected" if rejected else "none rejected"))
    reasons = {k.removeprefix("gnss_rejected_"): n for k, n in (counters or {}).items()
               if k.startswith("gnss_rejected_") and n}
    if rejected and sum(reasons.values()) == rejected:
        text += " (" + ", ".join(f"{n:,} {REJECTION_WORDS.get(r, r.replace('_', ' '))}"
                                 for r, n in sorted(reasons.items(), key=lambda kv: -kv[1])) + ")"
    if pending > 0:
        text += f", {pending:,} not yet delivered at the end"
    return text


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
        "  " + gnss_line(s["gnss"], s.get("estimator_counters")) + "; " + _collisions(s["collisions"])
        + (f"; lockstep: {lock.get('retries', 0)} waits, {lock.get('gave_up', 0)} give-ups" if lock else ""),
        f"  wrote {out}/: {', '.join(files)}",
    ]
    unclean = {n: p["exit"] for n, p in (sitl or {}).get("processes", {}).items() if not p["clean"]}
    if unclean:  # a clean run's processes are stopped by the launcher (143): nothing to say then
        lines.insert(-1, "  processes: " + "; ".join(f"{n} {e}" for n, e in unclean.items()))
    return lines


def print_summary(command: str, s: dict[str, Any], out: Path, files: Sequence[str], as_json: bool) -> None:
    if as_json:
        print(json.dumps(plain_json(s, nan_to_none=True), indent=2, allow_nan=False))
    else:
        print("\n".join(flight_lines(command, s, out, files)))
