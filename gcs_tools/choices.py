"""Checks of the options every command shares, done before anything starts: one line naming the
valid choices (and the nearest one) for a mistyped method, mission or profile."""

from __future__ import annotations

import argparse
import difflib
from pathlib import Path
from typing import TYPE_CHECKING

from companion.errors import UserError
from companion.estimator.methods import DEFAULT_METHOD

if TYPE_CHECKING:
    from companion.mission import Mission


def add_method_argument(parser: argparse.ArgumentParser) -> None:
    """``--method`` with the one default (``companion.estimator.DEFAULT_METHOD``)."""
    parser.add_argument("--method", default=DEFAULT_METHOD,
                        help=f"estimator method (default {DEFAULT_METHOD})")


def method(name: str, option: str = "--method") -> str:
    """An estimator method registered in :mod:`companion.estimator` (plugins included): its one check."""
    from companion.estimator import check_method

    return check_method(name, option)


def methods(text: str, option: str = "--methods") -> list[str]:
    """A comma-separated list of methods, each checked."""
    names = [m.strip() for m in text.split(",") if m.strip()]
    if not names:
        raise UserError(f"{option}: no method given")
    return [method(m, option) for m in names]


def mission_names() -> tuple[str, ...]:
    from companion.mission.loader import BUILTIN_MISSIONS

    return BUILTIN_MISSIONS


def mission(which: str, option: str = "--mission") -> Mission:
    """A packaged mission by name or a mission YAML file; anything else names the packaged ones."""
    from companion.mission import load_mission

    names = mission_names()
    if which not in names and not Path(which).is_file():
        near = difflib.get_close_matches(which, names, n=1, cutoff=0.5)
        hint = f"; did you mean {near[0]!r}?" if near else ""
        raise UserError(f"{option} {which!r}: no such file and not a packaged mission "
                        f"(packaged: {', '.join(names)}{hint})")
    return load_mission(which)


def profile(m: Mission, index: int, option: str = "--profile") -> int:
    if not 0 <= index < len(m.profiles):
        listed = ", ".join(f"{i} {p.name}" for i, p in enumerate(m.profiles))
        raise UserError(f"{option} {index}: mission {m.name!r} has profiles {listed}")
    return index
