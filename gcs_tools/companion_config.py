"""``beliefnav companion --config FILE``: every option of the command in one YAML file.

A key is an option's long name without the dashes (``master``, ``feed``, ``gps-delay-ms``,
``vehicle-id``, ``no-telemetry``: ``beliefnav companion --help`` lists them), its value what the
option takes (a number, a string, ``true`` for a flag). An ``estimator:`` section sets fields of the
estimator's parameters (``EstimatorConfig``, docs/parameters.md) for a real vehicle's sensors, a
``tight:`` section those of the tightly coupled filter (``TightConfig``, ``--coupling tight``). An
option given on the command line wins over the file; the file over the defaults. Every mistake is
one line naming the file and the key (an unknown key names the nearest one).

How: :func:`defer_defaults` replaces every option's default by a marker after the parser is built,
so :func:`merge` can tell an option the user gave from one left alone, whatever its value.
"""

from __future__ import annotations

import argparse
import difflib
import math
from pathlib import Path
from typing import Any

from companion.errors import ConfigError

SECTIONS = ("estimator", "tight")  # the file's sections besides the options
NOT_IN_FILE = frozenset({"help", "config"})


class _Unset:
    """An option the command line did not give (its real default is in ``defaults``)."""

    def __repr__(self) -> str:
        return "<not given>"


UNSET = _Unset()


def add_config_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", type=Path, metavar="FILE",
                        help="YAML file with any of these options by their long name (e.g. `master: "
                             "serial:/dev/ttyAMA0:921600`, `feed: gps-input`) and an optional `estimator:` "
                             "section; options given here win over the file (docs/deploy.md)")


def options(parser: argparse.ArgumentParser) -> dict[str, argparse.Action]:
    """The options a file may set: long name without dashes -> its action."""
    out = {}
    for action in parser._actions:
        longs = [s for s in action.option_strings if s.startswith("--")]
        if longs and action.dest not in NOT_IN_FILE and action.help != argparse.SUPPRESS:
            out[longs[0][2:]] = action
    return out


def defer_defaults(parser: argparse.ArgumentParser) -> dict[str, Any]:
    """Replace every option's default by ``UNSET``; returns the real defaults by dest."""
    defaults = {}
    for action in options(parser).values():
        defaults[action.dest] = action.default
        action.default = UNSET
    return defaults


def _value(action: argparse.Action, name: str, value: Any, where: str, default: Any) -> Any:
    """A file's value as the option would have it (its type and choices), or a one-line error."""
    at = f"{where}: {name}"
    if action.nargs == 0:  # a flag (store_true / store_false / store_const)
        if not isinstance(value, bool):
            raise ConfigError(f"{at}: expected true or false, got {value!r}")
        return action.const if value else default
    if isinstance(value, (dict, list)) or value is None:
        raise ConfigError(f"{at}: expected a single value, got {value!r}")
    kind: Any = action.type
    converted: Any
    try:
        if kind in (int, float):
            if isinstance(value, bool) or not isinstance(value, (int, float, str)):
                raise ValueError
            if kind is int and isinstance(value, float):
                raise ValueError  # 1.5 is not an id (int() would make it 1)
            converted = kind(value)
            if kind is float and not math.isfinite(converted):
                raise ValueError
        elif kind is Path:
            converted = Path(str(value))
        else:
            converted = str(value) if kind is None else kind(str(value))
    except (TypeError, ValueError, argparse.ArgumentTypeError):
        want = "an integer" if kind is int else "a number" if kind is float else "a value"
        raise ConfigError(f"{at}: expected {want}, got {value!r}") from None
    if action.choices is not None and converted not in action.choices:
        near = difflib.get_close_matches(str(converted), [str(c) for c in action.choices], n=1, cutoff=0.5)
        hint = f" (did you mean {near[0]!r}?)" if near else ""
        raise ConfigError(f"{at}: {converted!r} is not one of {', '.join(map(str, action.choices))}{hint}")
    return converted


def read(path: Path, parser: argparse.ArgumentParser,
         defaults: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """(option values by dest, sections) of a config file, every key and value checked."""
    from companion.mission.schema import load_yaml

    data = load_yaml(path)
    known = options(parser)
    values: dict[str, Any] = {}
    sections: dict[str, Any] = {}
    for key, value in data.items():
        name = str(key)
        if name in SECTIONS:
            if not isinstance(value, dict):
                raise ConfigError(f"{path}: {name}: expected a mapping of fields")
            sections[name] = value
            continue
        action = known.get(name) or known.get(name.replace("_", "-"))
        if action is None:
            near = difflib.get_close_matches(name, [*known, *SECTIONS], n=1, cutoff=0.6)
            hint = f" (did you mean {near[0]!r}?)" if near else ""
            raise ConfigError(f"{path}: unknown key {name!r}{hint}; the keys are the options of "
                              "`beliefnav companion --help` without their dashes")
        values[action.dest] = _value(action, name, value, str(path), defaults.get(action.dest))
    return values, sections


def merge(args: argparse.Namespace, parser: argparse.ArgumentParser,
          defaults: dict[str, Any]) -> dict[str, Any]:
    """Fill ``args`` in place: the command line, else ``--config``'s file, else the defaults; returns
    the file's sections ({} without a file)."""
    values: dict[str, Any] = {}
    sections: dict[str, Any] = {}
    if getattr(args, "config", None) is not None:
        values, sections = read(args.config, parser, defaults)
    for dest, default in defaults.items():
        if getattr(args, dest, UNSET) is UNSET:
            setattr(args, dest, values.get(dest, default))
    return sections


def estimator_config(sections: dict[str, Any], where: Path | None) -> Any:
    """The ``estimator:`` section as an ``EstimatorConfig`` (its defaults where the file is silent)."""
    from companion.estimator import EstimatorConfig
    from companion.mission.schema import build

    return build(EstimatorConfig, sections.get("estimator", {}), f"{where}: estimator")


def tight_config(sections: dict[str, Any], where: Path | None) -> Any:
    """The ``tight:`` section (``--coupling tight``) as a ``TightConfig`` (its defaults where silent)."""
    from companion.mission.schema import build
    from companion.tight import TightConfig

    return build(TightConfig, sections.get("tight", {}), f"{where}: tight")
