"""Every parser of every command takes options by their whole names only. argparse's default takes a
unique prefix (``--prof`` for ``--profiles``): a user's script then works until an option sharing the
prefix is added, and breaks with an "ambiguous option" error on an upgrade. Checked on the parser trees
themselves (every ``beliefnav`` command and action, every ``python -m`` tool of ours), and end to end."""

from __future__ import annotations

import argparse
import re
import runpy
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("gcs_tools", "companion", "simvehicle")


class _BuiltError(Exception):
    pass


def tree(parser: argparse.ArgumentParser) -> Iterator[argparse.ArgumentParser]:
    """The parser and every subcommand's parser below it."""
    yield parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for child in dict.fromkeys(action.choices.values()):
                yield from tree(child)


def module_tools() -> list[str]:
    """Our modules that build their own argparse parser (``python -m MODULE``)."""
    names = []
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            if "argparse.ArgumentParser(" in path.read_text():
                parts = path.relative_to(ROOT).with_suffix("").parts
                names.append(".".join(parts[:-1] if parts[-1] == "__main__" else parts))
    return names


def test_the_tools_are_found() -> None:
    tools = module_tools()
    assert {"companion", "simvehicle", "gcs_tools.evaluate.tight",
            "gcs_tools.evaluate.ablation"} <= set(tools)
    assert len(tools) > 15


def test_every_beliefnav_command_and_action_takes_whole_option_names_only() -> None:
    from gcs_tools.cli import build_parser

    parsers = list(tree(build_parser()))
    assert {"beliefnav replay", "beliefnav gnss spp"} <= {p.prog for p in parsers}  # commands and actions
    assert [p.prog for p in parsers if p.allow_abbrev] == []


@pytest.mark.filterwarnings("ignore:.*found in sys.modules after import of package:RuntimeWarning")
@pytest.mark.parametrize("module", module_tools())
def test_every_module_tool_takes_whole_option_names_only(module: str,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    built: list[argparse.ArgumentParser] = []

    def stop(self: argparse.ArgumentParser, *args: object, **kwargs: object) -> None:
        built.append(self)
        raise _BuiltError

    monkeypatch.setattr(argparse.ArgumentParser, "parse_args", stop)
    monkeypatch.setattr(sys, "argv", [module])
    with pytest.raises(_BuiltError):
        runpy.run_module(module, run_name="__main__", alter_sys=True)
    assert [p.prog for p in tree(built[0]) if p.allow_abbrev] == []


@pytest.mark.parametrize(("argv", "unknown"), [
    (["-m", "gcs_tools", "replay", "tests/data/quad106.tlog", "--no-fig"], "--no-fig"),
    (["-m", "gcs_tools", "evaluate", "--prof", "3"], "--prof"),
    (["-m", "gcs_tools.evaluate.tight", "--smartloc", "x.txt", "--block", "20"], "--block"),
])
def test_a_prefix_is_refused_in_one_line(argv: list[str], unknown: str) -> None:
    done = subprocess.run([sys.executable, *argv], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert done.returncode == 2, done.stderr
    lines = [line for line in done.stderr.splitlines() if line.strip()]
    assert re.search(rf"unrecognized arguments: .*{re.escape(unknown)}", lines[-1]), done.stderr
