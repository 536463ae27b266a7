"""``beliefnav``: one CLI, one module per subcommand (argument parsing and wiring only).

Each subcommand module defines ``add_arguments(parser)`` and ``run(args) -> int`` and is
imported only when its command runs (``beliefnav --help`` imports none of them), so a slow
import never slows the others. Every parse error is one line (``beliefnav: error: ...``, exit 2).
"""

from __future__ import annotations

import argparse
import importlib
import importlib.metadata
import re
import sys
from collections.abc import Sequence
from typing import Any, NoReturn

from companion.errors import UserError, not_one_of

DESCRIPTION = """\
beliefnav: GNSS/IMU navigation for quadrotors between buildings. An extended Kalman filter keeps
a belief in the GNSS and adapts it online, so late and multipath-biased fixes do not drag the
vehicle into a wall. Fly it in a simulated city, replay real flight logs through it, run it on a
companion computer beside an ArduPilot or PX4 autopilot, and watch it live or in Foxglove."""

EPILOG = """\
examples:
  beliefnav fly --mission default --profile 3 --out runs/fly     one flight in seconds
  beliefnav sitl --mission test --out runs/sitl                  three processes over MAVLink
  beliefnav replay tests/data/quad106.tlog --out runs/replay     a real 668 s flight log
  beliefnav companion --config companion.yaml                    beside a real autopilot
  beliefnav dashboard --port 8080                                live view on http://127.0.0.1:8080/
  beliefnav export runs/sitl                                     -> runs/sitl/export.mcap (Foxglove)

`beliefnav COMMAND --help` for a command's options."""

# name -> (module, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "fly": ("gcs_tools.fly.cli", "fly a mission in one process: vehicle, planner, estimator (seeded)"),
    "sitl": ("gcs_tools.sitl.cli", "fly a mission as processes over MAVLink 2/UDP (or ArduPilot, PX4 SITL)"),
    "replay": ("gcs_tools.replay.cli",
               "run the estimator on a flight log (tlog, .bin, .ulg, ANSFL) or smartLoc"),
    "companion": ("gcs_tools.companion_cli", "the estimator beside a real autopilot (--master, --config)"),
    "evaluate": ("gcs_tools.evaluate.cli", "campaign: missions x methods x seeds, report, figures"),
    "dashboard": ("gcs_tools.dashboard.cli", "live web dashboard: map, belief, errors, health"),
    "top": ("gcs_tools.top", "live telemetry in the terminal"),
    "record": ("gcs_tools.recorder.cli", "record live telemetry to a JSON Lines file"),
    "plot": ("gcs_tools.recorder.plot_cli", "draw a recording's map and belief figures"),
    "export": ("gcs_tools.export.cli", "a run, tlog or recording as MCAP (Foxglove) or CSV"),
    "bench": ("gcs_tools.bench.cli", "benchmarks that print JSON"),
    "gnss": ("gcs_tools.gnss.cli", "raw GNSS (smartLoc, RINEX 2-4, UBX): single-point solutions vs truth"),
}


class Parser(argparse.ArgumentParser):
    """An argparse parser whose errors are one line naming the command (no usage block), and that takes
    options by their whole names only: a prefix (``--prof`` for ``--profiles``) would keep working until
    another option shares it, then break a user's script."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> NoReturn:
        command = self.prog.removeprefix("beliefnav").strip()
        where = f"{command}: " if command else ""
        missing = re.fullmatch(r"argument (--[\w-]+)(?:/\S+)?: expected one argument", message)
        if missing:  # often a value starting with '-' (a southern latitude): argparse takes it for an option
            message += f" (if its value starts with '-': {missing.group(1)}=-VALUE)"
        self.exit(2, f"beliefnav: error: {where}{message} (see `{self.prog} --help`)\n")


class _Formatter(argparse.RawDescriptionHelpFormatter):
    """Every command's help on its own line, whatever the terminal's width."""

    def __init__(self, prog: str) -> None:
        super().__init__(prog, max_help_position=20, width=100)
        self._action_max_length = 16  # "    companion" + margin: no command name wraps


def version() -> str:
    """The installed distribution's version ("unknown" when run from a tree that is not installed)."""
    try:
        return importlib.metadata.version("beliefnav")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


def build_parser(names: Sequence[str] | None = None, options: bool = True) -> argparse.ArgumentParser:
    """The parser with every command (``names``: only these get their options; ``options=False``:
    none do, so no command module is imported, as for ``beliefnav --help``)."""
    parser = Parser(prog="beliefnav", description=DESCRIPTION, epilog=EPILOG,
                    formatter_class=_Formatter)
    parser.add_argument("--version", action="version", version=f"beliefnav {version()}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND",
                                title="commands")
    for name, (module_name, help_text) in COMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        if not options or (names is not None and name not in names):
            continue
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


def command_parser(parser: argparse.ArgumentParser, name: str) -> argparse.ArgumentParser:
    """The sub-parser of command ``name`` in a parser made by :func:`build_parser`."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return action.choices[name]
    raise LookupError(f"no command {name!r}")


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    # Only the chosen command's module is imported; without one (--help, --version, a typo) none is.
    chosen = argv[0] if argv and argv[0] in COMMANDS else None
    if argv and chosen is None and not argv[0].startswith("-"):
        print(f"beliefnav: error: {not_one_of('command', argv[0], tuple(COMMANDS))} (see `beliefnav --help`)",
              file=sys.stderr)
        return 2
    parser = build_parser([chosen] if chosen else [], options=chosen is not None)
    args, unknown = parser.parse_known_args(argv)
    if unknown:  # a misspelt option: the command's own parser says so and points at its own --help
        command_parser(parser, args.command).error(f"unrecognized arguments: {' '.join(unknown)}")
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
    except BrokenPipeError:  # `beliefnav ... | head`: the reader left; nothing more to say
        sys.stderr.close()
        return 0


if __name__ == "__main__":
    raise SystemExit(main())
