"""The parameter reference, docs/parameters.md, written from the code: every option of
``beliefnav companion`` (the keys of its ``--config`` file) and every field of the configuration
dataclasses (their defaults, units from their names, and the comments beside them).

``python -m gcs_tools.paramdoc`` rewrites the file; ``--check`` exits 1 when the committed file is
not what the code says (``make docs`` and a test run it).
"""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import io
import sys
import tokenize
from pathlib import Path
from typing import Any

OUT = Path(__file__).resolve().parents[1] / "docs" / "parameters.md"

# name suffix -> unit (units are in every name: docs/ARCHITECTURE.md); the longest suffix wins
UNITS = dict((
    ("_m_s2_sqrt_s", "m/s²·√s"), ("_m_sqrt_s", "m/√s"), ("_m_rt_s", "m/√s"),
    ("_m_s2_rt_hz", "m/s²/√Hz"), ("_rad_s_rt_hz", "rad/s/√Hz"),
    ("_m_s2", "m/s²"), ("_rad_s2", "rad/s²"), ("_m_s", "m/s"), ("_rad_s", "rad/s"), ("_m_rad", "m/rad"),
    ("_kg_m2", "kg·m²"), ("_n_s_m", "N·s/m"), ("_nm", "N·m"), ("_1_s3", "1/s³"), ("_1_s2", "1/s²"),
    ("_1_s", "1/s"), ("_m2", "m²"), ("_deg", "°"), ("_rad", "rad"), ("_hz", "Hz"), ("_ms", "ms"),
    ("_us", "µs"), ("_kg", "kg"), ("_n", "N"), ("_m", "m"), ("_s", "s"),
))


def unit(name: str) -> str:
    return next((UNITS[s] for s in sorted(UNITS, key=len, reverse=True) if name.endswith(s)), "")


def field_comments(cls: type) -> dict[str, str]:
    """Each field's comment: the one on its line, else the comment lines right above it (section
    headings ``# ---`` left out)."""
    source = inspect.getsource(cls)
    comments: dict[int, str] = {}
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            comments[tok.start[0]] = tok.string.lstrip("#").strip()
    lines = source.splitlines()
    out: dict[str, str] = {}
    names = {f.name for f in dataclasses.fields(cls)}
    for number, line in enumerate(lines, 1):
        stripped = line.strip()
        name = stripped.split(":", 1)[0].strip()
        if name not in names or not stripped.startswith(name + ":") or name in out:
            continue
        if number in comments and not stripped.startswith("#"):
            out[name] = comments[number]
            continue
        above: list[str] = []
        k = number - 1
        while k >= 1 and lines[k - 1].strip().startswith("#") and not lines[k - 1].strip().startswith("# -"):
            above.insert(0, comments.get(k, ""))
            k -= 1
        previous = lines[number - 2].strip().split(":", 1)[0] if number >= 2 else ""
        out[name] = " ".join(above) or ("(with the key above)" if previous in out else "")
    return out


def _default(f: dataclasses.Field) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return None


def _shown(value: Any) -> str:
    if dataclasses.is_dataclass(value):
        return "(see below)"
    if isinstance(value, float):
        return f"{value:g}"
    if value is None:
        return "none"
    return str(value).replace("|", "\\|")


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def dataclass_table(cls: type) -> list[str]:
    comments = field_comments(cls)
    rows = ["| key | default | unit | meaning |", "| --- | --- | --- | --- |"]
    for f in dataclasses.fields(cls):
        value = _default(f)
        if dataclasses.is_dataclass(value):
            continue
        rows.append(f"| `{f.name}` | {_shown(value)} | {unit(f.name)} | {_cell(comments.get(f.name, ''))} |")
    return rows


def companion_table() -> list[str]:
    from gcs_tools.cli import build_parser
    from gcs_tools.companion_config import NOT_IN_FILE

    parser = build_parser(["companion"])
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    companion = sub.choices["companion"]
    defaults = companion.get_default("_option_defaults") or {}
    rows = ["| option | `--config` key | default | meaning |", "| --- | --- | --- | --- |"]
    for action in companion._actions:
        longs = [s for s in action.option_strings if s.startswith("--")]
        if not longs or action.help == argparse.SUPPRESS or action.dest in ("help",):
            continue
        key = "—" if action.dest in NOT_IN_FILE else f"`{longs[0][2:]}`"
        value = defaults.get(action.dest, action.default)
        shown = "—" if value is None or action.nargs == 0 and value is False else f"`{value}`"
        meta = "" if action.nargs == 0 else f" {action.metavar or action.dest.upper()}"
        choices = f" (one of {', '.join(map(str, action.choices))})" if action.choices else ""
        text = (action.help or "").replace("%(default)s", str(value))
        rows.append(f"| `{longs[0]}{meta}` | {key} | {shown} | {_cell(text + choices)} |")
    return rows


def render() -> str:
    from companion.estimator.config import EstimatorConfig
    from companion.estimator.plugin_config import PluginConfig
    from companion.mission.config import FlightConfig, PlannerConfig
    from companion.tight import TightConfig
    from simvehicle.config import _SECTION_TYPES

    parts = [
        "# Parameter reference",
        "",
        "Written from the code by `python -m gcs_tools.paramdoc` (`make docs`; a test fails when this",
        "file and the code disagree): every option of `beliefnav companion` and every field of the",
        "configuration sections, with its default, its unit (from its name) and the comment beside it in",
        "the source. A mission file or the companion's `--config` file sets only what it changes; a wrong",
        "key or value is one line naming the file and the key.",
        "",
        "## `beliefnav companion`: options and `--config` keys",
        "",
        "Each option can be given in the YAML file of `--config FILE` by its long name without the dashes",
        "(`gps-delay-ms: 120`, a flag as `no-telemetry: true`); the command line wins over the file. The",
        "file may also have an `estimator:` section (the next table). See [deploy.md](deploy.md).",
        "",
        *companion_table(),
        "",
        "## `estimator:` — the filter (a mission file, or the companion's `--config`)",
        "",
        "The defaults suit a real vehicle's MEMS sensors; a mission's sensor scenario and its own",
        "`estimator:` section override them for the simulation ([estimator.md](estimator.md)).",
        "",
        *dataclass_table(EstimatorConfig),
        "",
        "## `tight:` — the tightly coupled filter (the companion's `--config` with `--coupling tight`)",
        "",
        "Defaults for an IMU-driven vehicle; `TightConfig.for_ground_vehicle()` (the smartLoc replay)",
        "changes the motion model ([tight.md](tight.md)).",
        "",
        *dataclass_table(TightConfig),
        "",
        "## `belief_plugins:` — the ablation methods' own parameters",
        "",
        *dataclass_table(PluginConfig),
        "",
        "## `flight:` and `planner:` — a mission's route",
        "",
        *dataclass_table(FlightConfig),
        "",
        *dataclass_table(PlannerConfig),
    ]
    for name, cls in _SECTION_TYPES.items():
        summary = (cls.__doc__ or "").strip().splitlines()[0]
        parts += ["", f"## `{name}:` — the simulated vehicle ({summary})", "", *dataclass_table(cls)]
    return "\n".join(parts) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__.split("\n\n", 1)[0].replace("``", "`"),
        allow_abbrev=False)
    ap.add_argument("--check", action="store_true",
                    help="only compare with the committed file (exit 1 if stale)")
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args(argv)
    text = render()
    if args.check:
        current = args.out.read_text(encoding="utf-8") if args.out.is_file() else ""
        if current != text:
            print(f"{args.out} is stale: run `python -m gcs_tools.paramdoc` (make docs)", file=sys.stderr)
            return 1
        return 0
    args.out.write_text(text, encoding="utf-8")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
