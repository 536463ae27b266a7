"""``python -m companion estimator|bridge``: the companion computer's processes.

``estimator --vehicle-port P`` talks to our own simulated vehicle (``beliefnav sitl``, lockstep);
``estimator --master URL --out DIR`` sits beside a foreign autopilot (:mod:`companion.autopilot`).
"""

from __future__ import annotations

import argparse
import signal
import sys
from pathlib import Path

from companion.errors import UserError
from companion.estimator.methods import DEFAULT_METHOD


def _parser() -> argparse.ArgumentParser:
    from companion.autopilot.options import add_master_arguments
    from companion.mavlink.udp_link import add_link_arguments
    from companion.telemetry import pubsub as telemetry

    parser = argparse.ArgumentParser(
        prog="python -m companion", description=__doc__.splitlines()[0],
        allow_abbrev=False)
    sub = parser.add_subparsers(dest="process", required=True)
    for name, text in (("estimator", "belief-adaptive estimator"), ("bridge", "planner bridge")):
        p = sub.add_parser(name, help=text, allow_abbrev=False)
        p.add_argument("--vehicle-port", type=int, required=name == "bridge",
                       help="our simulated vehicle's UDP port for us")
        p.add_argument("--bind-port", type=int, default=0, help="our UDP port (0: any free one)")
        p.add_argument("--mission", default=None,
                       help="mission name or YAML path (default: default; with --master: none, no map)")
        p.add_argument("--stats", type=Path, help="write link/node counters here (JSON) on exit")
        add_link_arguments(p)
        telemetry.add_arguments(p, publisher=True)
        if name == "estimator":
            p.add_argument("--method", default=DEFAULT_METHOD,
                           help=f"estimator method (default {DEFAULT_METHOD})")
            p.add_argument("--step-markers", action="store_true",
                           help="TIMESYNC requests are our simulated vehicle's step markers (beliefnav sitl)")
            add_master_arguments(p, master_required=False, mission=False)  # --mission is above
        else:
            p.add_argument("--profile", type=int, default=0, help="mission profile index")
            p.add_argument("--start-delay-s", type=float, default=0.0, help="hover before the route (s)")
    return parser


def main(argv: list[str] | None = None) -> int:
    from companion.runtime import exit_on_sigterm, write_json

    args = _parser().parse_args(argv)
    exit_on_sigterm()
    if args.process == "estimator" and (args.master is None) == (args.vehicle_port is None):
        print("companion estimator: error: give exactly one of --vehicle-port (our simulated vehicle) "
              "and --master (a foreign autopilot)", file=sys.stderr)
        return 2
    if args.process == "estimator" and args.master is not None:
        return _run_master(args)
    node = None
    try:
        node = _build(args)
        if args.process == "estimator":
            from companion.nodes.estimator_node import serve

            serve(node, stats_path=args.stats)
        else:
            from companion.nodes.bridge_node import serve as serve_bridge

            serve_bridge(node, stats_path=args.stats)
    except UserError as exc:
        print(f"companion {args.process}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        pass
    finally:
        if node is not None:
            crashed = sys.exc_info()[0] not in (None, SystemExit)  # SIGTERM ends through SystemExit
            if hasattr(node, "telemetry_ended") and not crashed:  # the estimator says it ended cleanly
                node.telemetry_ended()
            node.telemetry.close()
            if args.stats is not None:
                write_json(args.stats, node.stats())
    return 0


def _run_master(args: argparse.Namespace) -> int:
    from companion.autopilot.service import config_from_args, run
    from companion.telemetry.pubsub import publisher_from_args

    telemetry = None
    try:
        config = config_from_args(args)
        telemetry = publisher_from_args(args, "companion")
        summary = run(config, telemetry)
    except UserError as exc:
        print(f"companion estimator: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 0
    finally:
        if telemetry is not None:
            telemetry.close()
    if summary.get("failure"):
        print(f"companion estimator: error: {summary['failure']}", file=sys.stderr)
        return 1
    return 128 + signal.SIGTERM if summary.get("stop_signal") == "SIGTERM" else 0


def _build(args: argparse.Namespace):  # noqa: ANN202 (EstimatorNode | BridgeNode)
    from companion.mavlink.udp_link import UdpLink, link_settings
    from companion.mission import load_mission
    from companion.telemetry.pubsub import publisher_from_args

    mission = load_mission(args.mission or "default")
    fields, rng = link_settings(args)
    if args.process == "estimator":
        from companion.mavlink.udp_link import ESTIMATOR_COMPONENT_ID
        from companion.nodes.estimator_node import EstimatorNode, make_navigator

        navigator, nis_gate = make_navigator(mission, args.method)
        link = UdpLink(_config(args, ESTIMATOR_COMPONENT_ID, fields, link_id=1), rng)
        return EstimatorNode(link, navigator, nis_gate, publisher_from_args(args, "companion"),
                             new_navigator=lambda: make_navigator(mission, args.method)[0],
                             home=mission.frame, step_markers=args.step_markers)
    from companion.mavlink.udp_link import BRIDGE_COMPONENT_ID
    from companion.nodes.bridge_node import BridgeNode, route_info
    from companion.planning import plan_route

    route = plan_route(mission, args.profile, t_start_s=args.start_delay_s)
    link = UdpLink(_config(args, BRIDGE_COMPONENT_ID, fields, link_id=2), rng)
    return BridgeNode(link, route, publisher_from_args(args, "bridge"),
                      route_info(mission, args.profile, route))


def _config(args: argparse.Namespace, component_id: int, fields: dict[str, object], link_id: int):  # noqa: ANN202
    from companion.mavlink.udp_link import VEHICLE_COMPONENT_ID, VEHICLE_SYSTEM_ID, LinkConfig

    return LinkConfig(
        bind_port=args.bind_port, peer_port=args.vehicle_port, system_id=VEHICLE_SYSTEM_ID,
        component_id=component_id, accept_system_ids=frozenset({VEHICLE_SYSTEM_ID}),
        accept_component_ids=frozenset({VEHICLE_COMPONENT_ID}), link_id=link_id,
        **fields,  # type: ignore[arg-type]
    )


if __name__ == "__main__":
    raise SystemExit(main())
