"""``beliefnav sitl --vehicle ardupilot|px4``: one profile flown by a real autopilot's SITL on our
degraded GNSS.

ArduCopter SITL (EKF3, GPS_INPUT) or PX4 SITL with its SIH quadrotor (EKF2, HIL_GPS); both
through the harness's one ``VehicleBackend`` interface (``simvehicle.harness.backend``).
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import json
from pathlib import Path
from typing import Any

from companion.errors import UserError

# vehicle -> (config class "module:Class", its speed field, the EKF, the raw fixes' message, sent counter)
VEHICLES: dict[str, tuple[str, str, str, str, str]] = {
    "ardupilot": ("simvehicle.harness.ardupilot.config:ArduPilotConfig", "speedup", "ekf3", "GPS_INPUT",
                  "gps_input_sent"),
    "px4": ("simvehicle.harness.px4.config:Px4FlightConfig", "speed_factor", "ekf2", "HIL_GPS",
            "hil_gps_sent"),
}
FEEDS = ("none", "gps-input", "vision", "odometry")
RAW_ROWS = ("spp", "tight-second-order")  # printed with --scenario canyon (every row is in summary.json)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options only the SITL autopilots take (``sitl`` adds them to its own)."""
    parser.add_argument("--feed", default="none", choices=FEEDS,
                        help="ardupilot/px4: none = it flies on its EKF fed our raw fixes; closed loop "
                             "(`beliefnav companion` runs beside it): ardupilot gps-input = on the "
                             "companion's cleaned fixes, vision = on its position as ExternalNav; px4 "
                             "odometry = on its ODOMETRY as external vision")
    parser.add_argument("--no-gnss-velocity", action="store_true",
                        help="ardupilot/px4: send the EKF positions only (default: with a Doppler velocity, "
                             "truth + 0.1 m/s noise)")
    parser.add_argument("--speedup", type=float, help="ardupilot: SITL --speedup (default 10)")
    parser.add_argument("--speed-factor", type=float,
                        help="px4: PX4_SIM_SPEED_FACTOR, at most 10 (default 5)")
    parser.add_argument("--gnss-rate-hz", type=float,
                        help="ardupilot/px4: raw fix rate, 5-20 Hz (default 10)")
    parser.add_argument("--ulog", action="store_true",
                        help="px4: keep PX4's own ULog of the flight (OUT/px4/rootfs/log; "
                             "`beliefnav replay` reads it)")


def run(args: argparse.Namespace) -> int:
    from gcs_tools.fly.output import strict_json, write_outputs
    from simvehicle.harness.backend import FlightRequest, backend

    vehicle = args.vehicle
    config_path, speed_field, _, _, _ = VEHICLES[vehicle]
    if args.realtime or args.signing_key_file is not None or args.ports is not None or args.max_duration_s:
        raise UserError("--realtime, --signing-key-file, --ports and --max-duration-s "
                        "apply to --vehicle sim only")
    speed = {"ardupilot": args.speedup, "px4": args.speed_factor}
    for name, option in (("ardupilot", "--speedup"), ("px4", "--speed-factor")):
        if name != vehicle and speed[name] is not None:
            raise UserError(f"{option} applies to --vehicle {name} only")
    if args.ulog and vehicle != "px4":
        raise UserError("--ulog applies to --vehicle px4 only")
    module, _, cls = config_path.partition(":")
    config_class = getattr(importlib.import_module(module), cls)
    given = ((speed_field, speed[vehicle]), ("gnss_rate_hz", args.gnss_rate_hz),
             ("wall_timeout_s", args.wall_timeout_s))
    changes: dict[str, Any] = {k: v for k, v in given if v is not None}
    if vehicle == "px4":
        changes["ulog"] = args.ulog
    cfg = dataclasses.replace(config_class(), gnss_velocity=not args.no_gnss_velocity, **changes)
    request = FlightRequest(args.mission, args.profile, args.method, args.seed, Path(args.out),
                            scenario=args.scenario)
    result = backend(vehicle, feed=args.feed, config=cfg).fly(request)
    if result.series:
        write_outputs(result, _world(args.mission), args.out, figures=not args.no_figures)
    else:
        (Path(args.out) / "summary.json").write_text(json.dumps(strict_json(result.summary), indent=2) + "\n")
    _print(result.summary, Path(args.out), figures=not args.no_figures)
    return 0 if result.summary["reached_goal"] else 1


def _world(mission: str) -> Any:
    from companion.mission import load_mission

    return load_mission(mission).world


def _print(s: dict, out: Path, figures: bool = True) -> None:
    vehicle = s["vehicle"]
    _, _, ekf, message, sent = VEHICLES[vehicle]
    run = s[vehicle]
    print(f"sitl {vehicle} {s['method']} seed {s['seed']} (feed {s['feed']}): "
          f"{'reached goal' if s['reached_goal'] else 'did not reach the goal'} "
          f"({run['ended_by']}); {run['sim_s']:.0f} s simulated in {run['wall_s']:.1f} s wall")
    rows = [(s["method"], s["estimation_error_horizontal_m"]),
            (f"{vehicle}-{ekf}", s["autopilot_estimation_error_horizontal_m"])]
    rows += [(name, s["methods"][name]["estimation_error_horizontal_m"]) for name in RAW_ROWS
             if name in s.get("methods", {})]  # the canyon receiver: its fixes, the tight rows
    for name, e in rows:
        print(f"  {name:>18}: horizontal estimation error median {_m(e['median'])} p95 {_m(e['p95'])}")
    t = s["tracking_error_m"]
    print(f"  tracking error median {_m(t['median'])} p95 {_m(t['p95'])}; "
          f"collisions {s['collisions']}; min clearance {_m(s['min_clearance_m'])}")
    print(f"  {message} sent {run[sent]}; wrote {out / 'summary.json'}{', figures' if figures else ''} and "
          f"{out / 'run.tlog'}")
    for ulog in run.get("ulogs", []):
        print(f"  PX4's ULog: {out / ulog} (beliefnav replay reads it)")


def _m(x: float | None) -> str:
    return "n/a" if x is None or x != x else f"{x:.2f} m"
