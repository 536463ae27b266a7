"""``beliefnav sitl``: fly a mission as three processes over MAVLink/UDP (argument parsing and wiring)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from companion.errors import UserError
from companion.telemetry import pubsub as telemetry

if TYPE_CHECKING:
    from gcs_tools.sitl.launcher import Progress


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from gcs_tools.ardupilot import cli as ardupilot_cli

    parser.add_argument("--vehicle", default="sim", choices=("sim", "ardupilot"),
                        help="sim: our simulated vehicle; ardupilot: ArduCopter SITL flying on our GNSS")
    ardupilot_cli.add_arguments(parser)
    parser.add_argument("--mission", default="default", help="mission name or YAML path")
    parser.add_argument("--profile", type=int, default=0, help="mission profile index")
    parser.add_argument("--method", default="second-order", help="estimator method")
    parser.add_argument("--seed", type=int, default=0, help="seed of the vehicle's random draws")
    parser.add_argument("--out", type=Path, required=True, help="output directory")
    parser.add_argument("--realtime", action="store_true", help="pace to the wall clock (default: lockstep)")
    parser.add_argument("--signing-key-file", type=Path, help="MAVLink 2 signing key for all three processes")
    parser.add_argument("--ports", help="vehicle UDP ports ESTIMATOR,BRIDGE,GROUND (default: free ones)")
    parser.add_argument("--max-duration-s", type=float, help="simulated time limit (default: as fly)")
    parser.add_argument("--wall-timeout-s", type=float, help="stop everything after this much wall time")
    parser.add_argument("--drop-probability", type=float, default=0.0, help=argparse.SUPPRESS)  # tests only
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    telemetry.add_arguments(parser, publisher=True)  # every process publishes on Zenoh unless --no-telemetry


def _ports(text: str | None) -> tuple[int, int, int] | None:
    if text is None:
        return None
    try:
        ports = tuple(int(p) for p in text.split(","))
    except ValueError:
        ports = ()
    if len(ports) != 3 or not all(0 < p < 65536 for p in ports):
        raise UserError(f"--ports: expected three UDP ports ESTIMATOR,BRIDGE,GROUND, got {text!r}")
    return ports


def run(args: argparse.Namespace) -> int:
    if args.vehicle == "ardupilot":
        from gcs_tools.ardupilot import cli as ardupilot_cli

        return ardupilot_cli.run(args)
    from companion.mission import load_mission
    from gcs_tools.fly.output import strict_json, write_outputs
    from gcs_tools.sitl.launcher import SitlOptions, flight_plan, launch
    from gcs_tools.sitl.report import flight_result

    mission = load_mission(args.mission)
    if not 0 <= args.profile < len(mission.profiles):
        last = len(mission.profiles) - 1
        raise UserError(f"--profile {args.profile}: mission {mission.name!r} has profiles 0..{last}")
    if args.signing_key_file is not None and not args.signing_key_file.is_file():
        raise UserError(f"--signing-key-file {args.signing_key_file}: no such file")
    opts = SitlOptions(
        mission=args.mission, profile=args.profile, method=args.method, seed=args.seed, out_dir=args.out,
        max_duration_s=args.max_duration_s, realtime=args.realtime, signing_key_file=args.signing_key_file,
        ports=_ports(args.ports), wall_timeout_s=args.wall_timeout_s, drop_probability=args.drop_probability,
        telemetry_args=tuple(telemetry.forward_arguments(args)),
    )
    route, max_duration_s = flight_plan(opts)
    bar = None
    if not args.no_progress and sys.stderr.isatty():
        from tqdm import tqdm

        bar = tqdm(total=round(max_duration_s, 1), unit="s sim", desc=f"sitl {args.method}", leave=False)
    progress = None if bar is None else _progress_to(bar)
    try:
        run_ = launch(opts, progress)
    finally:
        if bar is not None:
            bar.close()
    result = flight_result(opts, run_, route, mission.name)
    if result.series:
        write_outputs(result, mission.world, args.out)
    else:
        (args.out / "summary.json").write_text(json.dumps(strict_json(result.summary), indent=2) + "\n")
    _print(result.summary, args.out)
    if run_.ended_by.startswith("crash"):
        print(f"beliefnav: error: {run_.ended_by.split(':', 1)[1]} process failed: {run_.crash_detail}",
              file=sys.stderr)
        return 1
    return 0 if run_.ended_by == "vehicle" else 1


def _print(s: dict, out: Path) -> None:
    est, trk, sitl = s["estimation_error_m"], s["tracking_error_m"], s["sitl"]
    print(f"sitl {s['method']} seed {s['seed']} ({sitl['mode']}): {sitl['outcome']} after "
          f"{s['duration_s']:.1f} s simulated in {s['wall_s']:.1f} s wall (ended by {sitl['ended_by']})")
    print(f"  estimation error median {est['median']:.2f} m p95 {est['p95']:.2f} m; "
          f"tracking error median {trk['median']:.2f} m p95 {trk['p95']:.2f} m; "
          f"min clearance {s['min_clearance_m']:.1f} m")
    print(f"  GNSS sent {s['gnss']['sent']} fused {s['gnss']['fused']} rejected {s['gnss']['rejected']}; "
          f"lockstep {json.dumps(sitl['lockstep'])}")
    print(f"  wrote {out / 'summary.json'}, figures and {out / 'run.tlog'}")


def _progress_to(bar: Any) -> Progress:
    """A launcher progress callback that moves a tqdm bar (simulated seconds, metres to goal)."""

    def update(t_s: float, d_m: float) -> None:
        bar.update(round(t_s - bar.n, 2))
        bar.set_postfix(goal_m=f"{d_m:.1f}")

    return update
