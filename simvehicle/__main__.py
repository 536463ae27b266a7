"""``python -m simvehicle``: the simulated vehicle as a MAVLink/UDP process (see simvehicle.node)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def _parser() -> argparse.ArgumentParser:
    from companion.mavlink.udp_link import add_link_arguments
    from companion.telemetry import pubsub as telemetry
    from simvehicle.groundlink import add_ground_arguments

    p = argparse.ArgumentParser(
        prog="python -m simvehicle", description=__doc__.splitlines()[0],
        allow_abbrev=False)
    p.add_argument("--mission", default="default", help="mission name or YAML path")
    p.add_argument("--profile", type=int, default=0, help="mission profile index")
    p.add_argument("--seed", type=int, default=0, help="seed of every random draw of the vehicle")
    p.add_argument("--scenario", default=None,
                   help="sensor scenario: paper, realistic, mismatch, canyon (default: the mission's)")
    p.add_argument("--estimator-port", type=int, required=True, help="UDP port the estimator talks to")
    p.add_argument("--bridge-port", type=int, required=True, help="UDP port the planner bridge talks to")
    p.add_argument("--ground-port", type=int, required=True, help="UDP port for a ground station")
    p.add_argument("--out", type=Path, required=True, help="directory for run.tlog and the records")
    p.add_argument("--max-duration-s", type=float, required=True, help="simulated time limit")
    p.add_argument("--goal-ned-m", type=float, nargs=3, required=True, help="the route's last waypoint")
    p.add_argument("--goal-radius-m", type=float, default=1.0, help="arrival: true position this close")
    p.add_argument("--goal-speed-m-s", type=float, default=0.5, help="arrival: and this slow")
    p.add_argument("--arrive-after-s", type=float, default=0.0, help="arrival: not before this time")
    p.add_argument("--realtime", action="store_true", help="pace to the wall clock (default: lockstep)")
    p.add_argument("--ubx-port", type=int, default=0,
                   help="raw receiver (scenario canyon): UBX TCP port on 127.0.0.1 (default 0: a free one, "
                        "named in <out>/receiver.json)")
    p.add_argument("--estimator-param", action="append", default=[], metavar="NAME=VALUE",
                   help="a companion estimator parameter shown on the ground link (EST_*; repeatable)")
    add_ground_arguments(p)
    add_link_arguments(p)
    telemetry.add_arguments(p, publisher=True)
    return p


def estimator_params(items: list[str]) -> tuple[tuple[str, float], ...]:
    """``["EST_ETA=0.5", ...]`` -> ``(("EST_ETA", 0.5), ...)``; a bad item is a one-line UserError."""
    from companion.errors import UserError
    from simvehicle.params import ESTIMATOR_PARAMS

    out = []
    for item in items:
        name, _, value = item.partition("=")
        try:
            number = float(value)
        except ValueError:
            number = float("nan")
        if name not in ESTIMATOR_PARAMS or number != number:
            raise UserError(f"--estimator-param {item!r}: expected NAME=NUMBER, NAME one of "
                            f"{', '.join(ESTIMATOR_PARAMS)}")
        out.append((name, number))
    return tuple(out)


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)

    from companion.errors import UserError
    from companion.mavlink.udp_link import link_settings
    from companion.mission import load_mission
    from companion.runtime import exit_on_sigterm
    from companion.telemetry.pubsub import publisher_from_args
    from simvehicle import SimVehicle
    from simvehicle.groundlink import ground_out_targets
    from simvehicle.node import VehicleNode, VehicleNodeConfig
    from simvehicle.recording import SPOOL_NAME, FlightRecorder

    exit_on_sigterm()
    node = None
    result: dict[str, object] = {"outcome": "interrupted"}
    try:
        mission = load_mission(args.mission, args.scenario)
        sim = SimVehicle(mission, args.profile, args.seed)
        args.out.mkdir(parents=True, exist_ok=True)
        recorder = FlightRecorder(args.goal_ned_m, args.goal_radius_m, args.goal_speed_m_s,
                                  args.arrive_after_s, spool_path=args.out / SPOOL_NAME)
        fields, rng = link_settings(args)
        config = VehicleNodeConfig(
            estimator_port=args.estimator_port, bridge_port=args.bridge_port, ground_port=args.ground_port,
            out_dir=args.out, max_duration_s=args.max_duration_s, realtime=args.realtime,
            ground_out=ground_out_targets(args), estimator_params=estimator_params(args.estimator_param),
            ubx_port=args.ubx_port,
        )
        node = VehicleNode(sim, mission, recorder, config, fields, rng, publisher_from_args(args, "vehicle"))
        result = node.fly()
    except UserError as exc:
        print(f"simvehicle: error: {exc}", file=sys.stderr)
        return 2
    except TimeoutError as exc:
        print(f"simvehicle: error: {exc}", file=sys.stderr)
        result = {"outcome": "no_companions"}
        return 3
    except KeyboardInterrupt:
        pass
    finally:
        if node is not None:
            result.setdefault("t_s", node.t_us / 1e6)
            node.close()
            node.write_stats(result)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
