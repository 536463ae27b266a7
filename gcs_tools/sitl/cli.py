"""``beliefnav sitl``: fly a mission as three processes over MAVLink/UDP (argument parsing and wiring)."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from companion.errors import UserError
from companion.telemetry import pubsub as telemetry
from gcs_tools import choices
from simvehicle.harness.sitl.outcome import check_run_arguments

if TYPE_CHECKING:
    from companion.mission import Mission
    from simvehicle.harness.sitl.launcher import Progress


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from gcs_tools.sitl import autopilot_cli
    from simvehicle.harness.backend import SITL_VEHICLES

    parser.add_argument("--vehicle", default="sim", choices=SITL_VEHICLES,
                        help="sim: our simulated vehicle; ardupilot: ArduCopter SITL, px4: PX4 SITL (SIH "
                             "quadrotor), each flying on our GNSS (simvehicle.harness.backend.BACKENDS)")
    autopilot_cli.add_arguments(parser)
    parser.add_argument("--mission", default="default", help="mission name or YAML path")
    parser.add_argument("--profile", type=int, default=0, help="mission profile index")
    choices.add_method_argument(parser)
    parser.add_argument("--seed", type=int, default=0, help="seed of the vehicle's random draws")
    parser.add_argument("--scenario", default=None,
                        help="sensor scenario: paper, realistic, mismatch, canyon (default: the mission "
                             "file's; --vehicle ardupilot|px4: paper or canyon, the calibrated raw receiver)")
    parser.add_argument("--out", type=Path, default=Path("runs/sitl"),
                        help="output directory (default runs/sitl)")
    parser.add_argument("--json", action="store_true", help="print summary.json instead of the summary lines")
    parser.add_argument("--realtime", action="store_true", help="pace to the wall clock (default: lockstep)")
    parser.add_argument("--signing-key-file", type=Path,
                        help="MAVLink 2 signing key for all three processes (default: a fresh key per run, "
                             "OUT/signing.key, mode 0600)")
    parser.add_argument("--no-signing", action="store_true",
                        help="no MAVLink 2 signing (anyone on the host could then fly the vehicle)")
    parser.add_argument("--ports", help="vehicle UDP ports ESTIMATOR,BRIDGE,GROUND (default: free ones)")
    parser.add_argument("--ubx-port", type=choices.tcp_port, default=None,
                        help="scenario canyon: the raw receiver's UBX TCP port on 127.0.0.1 "
                             "(default: a free one, named in OUT/receiver.json)")
    from simvehicle.groundlink import add_ground_arguments

    add_ground_arguments(parser)
    parser.add_argument("--max-duration-s", type=float, help="simulated time limit (default: as fly)")
    parser.add_argument("--wall-timeout-s", type=float, help="stop everything after this much wall time")
    parser.add_argument("--drop-probability", type=float, default=0.0, help=argparse.SUPPRESS)  # tests only
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--no-figures", action="store_true",
                        help="no map.png and belief.png (summary.json, timeseries.csv and the logs only)")
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
    if args.vehicle in ("ardupilot", "px4"):
        from gcs_tools.sitl import autopilot_cli

        return autopilot_cli.run(args)
    if args.feed != "none" or args.speedup or args.speed_factor or args.ulog:
        raise UserError("--feed, --speedup, --speed-factor and --ulog apply to --vehicle ardupilot or px4")
    from companion.mavlink.signing import read_signing_key
    from companion.mission import with_scenario
    from gcs_tools import choices
    from gcs_tools.outdir import ensure_out_dir
    from simvehicle.groundlink import ground_out_targets
    from simvehicle.harness.sitl.vehicle_id import claim_vehicle_id

    mission = choices.mission(args.mission)  # every option checked before any process starts
    if args.scenario is not None:
        mission = with_scenario(mission, args.scenario)
    check_run_arguments(args.method, args.seed)
    choices.profile(mission, args.profile)
    ground_out_targets(args)  # a bad --ground-out too
    if args.signing_key_file is not None and not args.signing_key_file.is_file():
        raise UserError(f"--signing-key-file {args.signing_key_file}: no such file")
    if args.signing_key_file is not None and args.no_signing:
        raise UserError("--signing-key-file and --no-signing contradict each other")
    if args.signing_key_file is not None:  # an empty or unusable key: here, not from a child process
        read_signing_key(args.signing_key_file)
    ensure_out_dir(args.out)
    claim = claim_vehicle_id(telemetry.config_from_args(args), args.vehicle_id)
    try:
        if claim is not None:
            args.vehicle_id = claim.vehicle_id
            if claim.note:
                print(f"beliefnav: note: {claim.note}", file=sys.stderr)
        return _fly(args, mission)
    finally:
        if claim is not None:
            claim.close()


def _fly(args: argparse.Namespace, mission: Mission) -> int:
    from gcs_tools.fly.output import strict_json, write_outputs
    from gcs_tools.summaries import print_summary, run_info
    from simvehicle.groundlink import ground_out_arguments
    from simvehicle.harness.backend import FlightRequest, backend
    from simvehicle.harness.sitl.launcher import SitlOptions, flight_plan

    request = FlightRequest(args.mission, args.profile, args.method, args.seed, args.out, args.max_duration_s,
                            args.scenario)
    options: dict[str, Any] = {
        "realtime": args.realtime, "signing_key_file": args.signing_key_file, "signing": not args.no_signing,
        "ports": _ports(args.ports), "wall_timeout_s": args.wall_timeout_s,
        "drop_probability": args.drop_probability, "telemetry_args": tuple(telemetry.forward_arguments(args)),
        "ground_args": tuple(ground_out_arguments(args)), "ubx_port": args.ubx_port,
    }
    _, max_duration_s = flight_plan(SitlOptions(args.mission, args.profile, args.method, args.seed, args.out,
                                                args.max_duration_s))
    bar = None
    if not args.no_progress and sys.stderr.isatty():
        from tqdm import tqdm

        bar = tqdm(total=round(max_duration_s, 1), unit="s sim", desc=f"sitl {args.method}", leave=False)
    start_unix_s = time.time()
    try:
        result = backend("sim", progress=None if bar is None else _progress_to(bar), **options).fly(request)
    finally:
        if bar is not None:
            bar.close()
    result.summary["sitl"]["vehicle_id"] = None if args.no_telemetry else args.vehicle_id
    result.summary.update(run_info(mission, args.mission, start_unix_s))
    if (args.out / "run.tlog").is_file():
        result = dataclasses.replace(result, fixes=tlog_fixes(args.out / "run.tlog", mission))
    if result.series:
        write_outputs(result, mission.world, args.out, figures=not args.no_figures)
    else:
        (args.out / "summary.json").write_text(json.dumps(strict_json(result.summary), indent=2) + "\n")
    files = sorted(p.name + ("/" if p.is_dir() else "") for p in args.out.iterdir() if p.suffix != ".key")
    print_summary("sitl", result.summary, args.out, files, args.json)
    if result.failure:
        print(f"beliefnav: error: {result.failure}", file=sys.stderr)
        return 1
    return 0


def tlog_fixes(tlog: Path, mission: Mission) -> dict[str, Any]:
    """The fixes the vehicle sent (run.tlog's GPS_RAW_INT) as ``FlightResult.fixes`` in the
    mission's frame; whether the estimator's gate rejected each one is not known here (NaN)."""
    import numpy as np

    from gcs_tools.export.tlog_flight import read_fixes, tlog_epoch

    fixes = read_fixes(tlog, tlog_epoch(tlog))
    lla = np.array([(f.lat_deg, f.lon_deg, f.alt_m) for f in fixes]).reshape(-1, 3)
    ned = np.asarray(mission.frame.to_ned_m(lla[:, 0], lla[:, 1], lla[:, 2]), dtype=float).T.reshape(-1, 3)
    return {"t_s": np.array([f.t_s for f in fixes]),
            "t_validity_s": np.array([f.t_validity_s for f in fixes]), "p_ned_m": ned,
            "h_acc_m": np.array([f.h_acc_m for f in fixes]), "rejected": np.full(len(fixes), np.nan)}


def _progress_to(bar: Any) -> Progress:
    """A launcher progress callback that moves a tqdm bar (simulated seconds, metres to goal)."""

    def update(t_s: float, d_m: float) -> None:
        bar.update(round(t_s - bar.n, 2))
        bar.set_postfix(goal_m=f"{d_m:.1f}")

    return update
