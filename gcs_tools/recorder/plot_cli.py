"""``beliefnav plot FILE``: redraw a run's figures from a recording (the shared ``gcs_tools.figures``).

Per vehicle: ``<vehicle>_map.png`` (buildings and planned path of the last ``route`` message, true
and estimated tracks) and ``<vehicle>_belief.png`` (β, clearance, biases, latency, errors) — the
same figures ``beliefnav fly`` and ``beliefnav sitl`` draw.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from gcs_tools.recorder.recording import read_recording, recorded_route, recorded_vehicle, series


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", help="recording made by `beliefnav record`")
    parser.add_argument("--out", help="output folder (default: beside the recording, named after it: "
                                      "run/ for run.jsonl)")
    parser.add_argument("--vehicle", help="only this vehicle (default: all)")


def run(args: argparse.Namespace) -> int:
    from gcs_tools.figures import belief_figure, map_figure

    rec = read_recording(args.file)
    vehicles = [recorded_vehicle(rec, args.vehicle, args.file)] if args.vehicle else rec.vehicles
    out = Path(args.out) if args.out else Path(args.file).with_suffix("")
    out.mkdir(parents=True, exist_ok=True)
    for v in vehicles:
        s = series(rec, v)
        world, waypoints_ned_m, route_name = recorded_route(rec, v)
        title = f"{Path(args.file).name}: {v}{route_name}"
        map_figure(out / f"{v}_map.png", world, waypoints_ned_m,
                   {"true": s["p_true_ned_m"], "estimated": s["p_est_ned_m"]}, title)
        belief_figure(out / f"{v}_belief.png", s, title)
        print(f"{out / v}_{{map,belief}}.png: {len(s['t_s'])} estimates, "
              f"median error {np.nanmedian(s['est_error_m']):.2f} m")
    if rec.malformed:
        print(f"{rec.malformed} malformed lines skipped", file=sys.stderr)
    return 0
