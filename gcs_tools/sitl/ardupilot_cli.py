"""``beliefnav sitl --vehicle ardupilot``: one profile flown by ArduCopter SITL on our degraded GNSS."""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path
from typing import Any

from companion.errors import UserError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options only the ArduPilot vehicle takes (``sitl`` adds them to its own)."""
    parser.add_argument("--feed", default="none", choices=("none", "gps-input", "vision"),
                        help="ardupilot: none = it flies on EKF3 fed our raw fixes; gps-input = on the "
                             "companion's cleaned fixes, vision = on the companion's position as "
                             "ExternalNav (closed loop: `beliefnav companion` runs beside it)")
    parser.add_argument("--no-gnss-velocity", action="store_true",
                        help="ardupilot: send EKF3 positions only (default: with a Doppler velocity, "
                             "truth + 0.1 m/s noise)")
    parser.add_argument("--speedup", type=float, help="ardupilot: SITL --speedup (default 10)")
    parser.add_argument("--gnss-rate-hz", type=float, help="ardupilot: GPS_INPUT rate, 5-20 Hz (default 10)")


def run(args: argparse.Namespace) -> int:
    from gcs_tools.fly.output import strict_json, write_outputs
    from simvehicle.harness.ardupilot.config import ArduPilotConfig
    from simvehicle.harness.backend import FlightRequest, backend

    if args.realtime or args.signing_key_file is not None or args.ports is not None or args.max_duration_s:
        raise UserError("--realtime, --signing-key-file, --ports and --max-duration-s "
                        "apply to --vehicle sim only")
    changes = {k: v for k, v in (("speedup", args.speedup), ("gnss_rate_hz", args.gnss_rate_hz),
                                  ("wall_timeout_s", args.wall_timeout_s)) if v is not None}
    cfg = dataclasses.replace(ArduPilotConfig(), gnss_velocity=not args.no_gnss_velocity, **changes)
    request = FlightRequest(args.mission, args.profile, args.method, args.seed, Path(args.out),
                            scenario=args.scenario)
    result = backend("ardupilot", feed=args.feed, config=cfg).fly(request)
    if result.series:
        write_outputs(result, _world(args.mission), args.out)
    else:
        (Path(args.out) / "summary.json").write_text(json.dumps(strict_json(result.summary), indent=2) + "\n")
    _print(result.summary, Path(args.out))
    return 0 if result.summary["reached_goal"] else 1


def _world(mission: str) -> Any:
    from companion.mission import load_mission

    return load_mission(mission).world


def _print(s: dict, out: Path) -> None:
    ap = s["ardupilot"]
    print(f"sitl ardupilot {s['method']} seed {s['seed']} (feed {s['feed']}): "
          f"{'reached goal' if s['reached_goal'] else 'did not reach the goal'} "
          f"({ap['ended_by']}); {ap['sim_s']:.0f} s simulated in {ap['wall_s']:.1f} s wall")
    for name, key in ((s["method"], "estimation_error_horizontal_m"),
                      ("ardupilot-ekf3", "autopilot_estimation_error_horizontal_m")):
        e = s[key]
        print(f"  {name:>15}: horizontal estimation error median {_m(e['median'])} p95 {_m(e['p95'])}")
    t = s["tracking_error_m"]
    print(f"  tracking error median {_m(t['median'])} p95 {_m(t['p95'])}; "
          f"collisions {s['collisions']}; min clearance {_m(s['min_clearance_m'])}")
    print(f"  GPS_INPUT sent {ap['gps_input_sent']}; "
          f"wrote {out / 'summary.json'}, figures and {out / 'run.tlog'}")


def _m(x: float | None) -> str:
    return "n/a" if x is None or x != x else f"{x:.2f} m"
