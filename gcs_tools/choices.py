"""Checks of the options every command shares, done before anything starts: one line naming the
valid choices (and the nearest one) for a mistyped method, mission or profile.

One meaning per option name across commands: ``--mission`` a mission (name or YAML path),
``--profile`` one of its profiles, ``--profiles`` a set of them (a count or a list/range: ``profiles``),
``--method``/``--methods``, ``--seed``/``--seeds``. An old spelling stays as a hidden alias that
prints one note (``add_deprecated_alias``)."""

from __future__ import annotations

import argparse
import difflib
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from companion.errors import UserError
from companion.estimator.methods import DEFAULT_METHOD

if TYPE_CHECKING:
    from companion.mission import Mission


def tcp_port(text: str) -> int:
    """An argparse ``type`` for a TCP/UDP port to bind: 1-65535 (argparse makes the error one line)."""
    try:
        port = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a TCP port (1-65535)") from None
    if not 0 < port < 65536:
        raise argparse.ArgumentTypeError(f"{port} is not a TCP port (1-65535)")
    return port


def run_time_s(text: str) -> float:
    """An argparse ``type`` for ``--duration-s`` of a command that runs until stopped: finite and ≥ 0
    (0: until Ctrl-C; a negative or NaN duration would silently mean "never stop")."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of seconds") from None
    if not (math.isfinite(value) and value >= 0.0):
        raise argparse.ArgumentTypeError(f"{text} must be a finite number of seconds >= 0 (0: until Ctrl-C)")
    return value


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


def profiles(text: str, available: int, option: str = "--profiles") -> tuple[int, ...]:
    """``"10"`` → profiles 0..9; ``"10-13"`` or ``"0,4"`` → those profiles; checked against the
    ``available`` profiles of the mission."""
    if "-" in text or "," in text:
        picked = _int_list(text.replace(" ", ""), option)
    else:
        try:
            n = int(text)
        except ValueError:
            raise UserError(f"{option}: expected a count or a range, got {text!r}") from None
        if n < 1:
            raise UserError(f"{option}: expected ≥ 1, got {n}")
        picked = tuple(range(n))
    if max(picked) >= available:
        raise UserError(f"{option}: the mission has {available} profiles (0–{available - 1}), got {text}")
    return picked


def _int_list(text: str, option: str) -> tuple[int, ...]:
    """``"0-49"``, ``"3"`` or ``"0,2,5-7"`` → sorted unique integers ≥ 0; one-line error otherwise."""
    values: set[int] = set()
    try:
        for part in text.split(","):
            lo, _, hi = part.strip().partition("-")
            a = int(lo)
            b = int(hi) if hi else a
            if b < a or a < 0:
                raise ValueError
            values.update(range(a, b + 1))
    except ValueError:
        raise UserError(f"{option}: expected e.g. 0-49 or 0,3,7, got {text!r}") from None
    return tuple(sorted(values))


def seeds(text: str, option: str = "--seeds") -> tuple[int, ...]:
    """``"0-49"``, ``"3"`` or ``"0,2,5-7"`` → sorted unique seeds."""
    return _int_list(text, option)


def positive(value: float | None, option: str) -> float | None:
    """An optional number that must be finite and > 0 when given (a duration, a rate, a density):
    ``None`` passes, anything else is a one-line error naming the option."""
    if value is not None and not (math.isfinite(value) and value > 0):
        raise UserError(f"{option} must be a finite number > 0, got {value!r}")
    return value


class _DeprecatedAlias(argparse.Action):
    def __init__(self, option_strings: Sequence[str], dest: str, new: str = "", **kwargs: Any) -> None:
        super().__init__(option_strings, dest, **kwargs)
        self.new = new

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any,
                 option_string: str | None = None) -> None:
        print(f"{parser.prog}: note: {option_string} is now {self.new}", file=sys.stderr)
        setattr(namespace, self.dest, values)


def add_deprecated_alias(parser: argparse.ArgumentParser, old: str, new: str, dest: str,
                         **kwargs: Any) -> None:
    """``old`` as a hidden spelling of ``new`` (same ``dest``): works, and prints one note."""
    parser.add_argument(old, dest=dest, action=_DeprecatedAlias, new=new, help=argparse.SUPPRESS, **kwargs)
