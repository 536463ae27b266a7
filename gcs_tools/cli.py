"""``beliefnav``: one CLI, one module per subcommand (argument parsing and wiring only).

Each subcommand module defines ``add_arguments(parser)`` and ``run(args) -> int`` and is
imported only when its command runs, so a slow import never slows the others.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.metadata
import sys
from collections.abc import Sequence

from companion.errors import UserError

# name -> (module, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "replay": ("gcs_tools.replay.cli", "replay a flight log (tlog, .bin, .ulg) through the estimator"),
    "fly": ("gcs_tools.fly.cli", "fly a mission in-process (vehicle, planner, estimator)"),
    "sitl": ("gcs_tools.sitl.cli", "fly a mission as three processes over MAVLink/UDP"),
    "companion": ("gcs_tools.companion_cli", "run the estimator beside a real autopilot (--master URL)"),
    "dashboard": ("gcs_tools.dashboard.cli", "live web dashboard fed by Zenoh"),
    "record": ("gcs_tools.recorder.cli", "record Zenoh telemetry to a file"),
    "plot": ("gcs_tools.recorder.plot_cli", "redraw a run's figures from a recording"),
    "top": ("gcs_tools.top", "terminal view of live telemetry"),
    "evaluate": ("gcs_tools.evaluate.cli", "evaluation campaign across missions, methods, seeds"),
    "export": ("gcs_tools.export.cli", "a run, tlog or recording as MCAP (Foxglove) or CSV"),
    "bench": ("gcs_tools.bench.cli", "benchmarks that print JSON"),
    "gnss": ("gcs_tools.gnss.cli", "raw GNSS (smartLoc, RINEX 3, UBX): single-point solutions vs truth"),
}


def version() -> str:
    """The installed distribution's version ("unknown" when run from a tree that is not installed)."""
    try:
        return importlib.metadata.version("beliefnav")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


def build_parser(names: Sequence[str] | None = None) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="beliefnav", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"beliefnav {version()}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMANDS if names is None else names:
        module_name, help_text = COMMANDS[name]
        p = sub.add_parser(name, help=help_text, description=help_text)
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            if exc.name is None or not module_name.startswith(exc.name):
                raise
            p.set_defaults(_missing=module_name)
            continue
        module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    # Build only the chosen subcommand's parser when it is named, so others' imports are skipped.
    chosen = [argv[0]] if argv and argv[0] in COMMANDS else None
    if argv[:1] == ["--version"]:
        chosen = []  # no subcommand module needs importing to print the version
    parser = build_parser(chosen)
    args = parser.parse_args(argv)
    if getattr(args, "_missing", None):
        print(f"beliefnav: error: command {args.command!r} is not available in this build", file=sys.stderr)
        return 2
    try:
        return int(args._run(args) or 0)
    except UserError as exc:
        print(f"beliefnav: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("beliefnav: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
