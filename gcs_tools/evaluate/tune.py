"""Hyper-parameter sweeps on the tuning set (never on the reported profiles or seeds).

    python -m gcs_tools.evaluate.tune --vary estimator.sigma_acc_m_s2=0.006,0.02,0.3 \\
        --set estimator.r_inflation_max=10 --seeds 1000-1002 --workers 2 --out docs/results/tuning

Each point of the cartesian product of ``--vary`` lists (plus the fixed ``--set`` overrides)
flies the ``default-tuning`` grid with every method, so shared parameters change for all
methods alike. One JSON record per point is appended to ``OUT/sweeps.jsonl`` (overrides,
profiles, seeds, per-method pooled medians); ``OUT/README.md`` is the table of every record,
rewritten after each point, so a sweep can be stopped and resumed.
"""

from __future__ import annotations

import argparse
import itertools
import json
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from companion.errors import UserError
from gcs_tools import choices
from gcs_tools.evaluate import aggregate, campaign, report, stats, tuning
from gcs_tools.evaluate.cli import DEFAULT_METHODS, parse_methods

RECORDS = "sweeps.jsonl"
TABLE = "README.md"


def points(vary: Sequence[str], fixed: Sequence[str]) -> list[tuple[tuple[str, Any], ...]]:
    """Cartesian product of ``KEY=v1,v2`` lists, each point followed by the fixed overrides."""
    axes = []
    for text in vary:
        key, _, values = text.partition("=")
        axes.append([tuning.parse_override(f"{key}={v}") for v in values.split(",")])
    tail = tuple(tuning.parse_override(t) for t in fixed)
    return [tuple(p) + tail for p in itertools.product(*axes)]


def record(results: Sequence[campaign.JobResult], methods: Sequence[str]) -> dict[str, Any]:
    """Per method: pooled median estimation and tracking error, and their change against naive."""
    out: dict[str, Any] = {}
    for method in methods:
        mine = aggregate.of_method(results, method)
        out[method] = {name: stats.summarize(aggregate.pooled(mine, attr))["median"]
                       for name, attr in aggregate.ERRORS.items()}
    return record_reductions(out)


def record_reductions(medians: dict[str, Any]) -> dict[str, Any]:
    """Add each method's ``reduction_vs_naive`` (per error) when naive is among them."""
    base = medians.get(aggregate.BASELINE)
    if base is not None:
        for entry in medians.values():
            entry["reduction_vs_naive"] = {k: stats.reduction(entry[k], base[k]) for k in aggregate.ERRORS}
    return medians


def table(records: Sequence[dict[str, Any]]) -> str:
    """Markdown: one row per record, ``est / track`` median (m) per method, Δ of second-order."""
    from companion.estimator import METHODS

    methods = [m for m in METHODS if any(m in r["methods"] for r in records)]
    head = ["#", "estimator section", "profiles", "seeds", *[f"`{m}` est / track [m]" for m in methods],
            "Δ est / track 2nd vs naive"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for i, r in enumerate(records):
        section = r["estimator_section"]
        cells = [str(i), ", ".join(f"{k}={v}" for k, v in section.items()) or "defaults",
                 report._ranges(r["profiles"]), report._ranges(r["seeds"])]
        for m in methods:
            e = r["methods"].get(m)
            cells.append(f"{e['estimation_error_m']:.3f} / {e['tracking_error_m']:.3f}" if e else "")
        d = r["methods"].get("second-order", {}).get("reduction_vs_naive")
        cells.append(f"{d['estimation_error_m']:+.0%} / {d['tracking_error_m']:+.0%}" if d else "")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def write_table(out: Path) -> None:
    lines = (out / RECORDS).read_text(encoding="utf-8").splitlines()
    records = [json.loads(line) for line in lines if line.strip()]
    text = (
        "# Tuning sweeps\n\n"
        f"Mission `{tuning.TUNING_MISSION}` only (profiles never reported), seeds from "
        f"{tuning.TUNING_SEEDS[0]}–{tuning.TUNING_SEEDS[-1]}; written by `python -m gcs_tools.evaluate.tune` "
        f"(records in `{RECORDS}`, commands there). Cells: median of the 20 Hz estimation / tracking "
        "errors pooled over the row's flights. The estimator section (mission file plus overrides) "
        "applies to every method alike; other fields keep the `EstimatorConfig` defaults of the "
        "record's commit.\n\n" + table(records)
    )
    (out / TABLE).write_text(text, encoding="utf-8")


def _commit() -> str:
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                             timeout=10, check=False)
    except OSError:
        return "unknown"
    return out.stdout.strip() or "unknown"


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m gcs_tools.evaluate.tune", description=__doc__.split("\n")[0],
        allow_abbrev=False)
    p.add_argument("--vary", action="append", default=[], metavar="SECTION.FIELD=V1,V2",
                   help="values to sweep (cartesian product over repeats)")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.FIELD=VALUE",
                   help="fixed override for every point")
    p.add_argument("--profiles", default=None,
                   help=f"profiles of {tuning.TUNING_MISSION} (default: all of them)")
    p.add_argument("--seeds", default="1000-1002", help="tuning seeds (within 1000-1009)")
    p.add_argument("--methods", default=DEFAULT_METHODS)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--out", type=Path, default=Path("docs/results/tuning"))
    args = p.parse_args(argv)
    try:
        profiles = tuning.profiles(args.profiles)
        seeds = choices.seeds(args.seeds)
        if not set(seeds) <= set(tuning.TUNING_SEEDS):
            raise UserError(f"--seeds: tuning seeds are {tuning.TUNING_SEEDS[0]}–{tuning.TUNING_SEEDS[-1]}")
        methods = parse_methods(args.methods)
        grid_points = points(args.vary, args.set)
        for overrides in grid_points:
            tuning.check(tuning.load(tuning.TUNING_MISSION, overrides))
    except UserError as exc:
        print(f"tune: error: {exc}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    command = "python -m gcs_tools.evaluate.tune " + " ".join(argv if argv is not None else sys.argv[1:])
    for overrides in grid_points:
        jobs = campaign.grid(tuning.TUNING_MISSION, profiles, methods, seeds, overrides=overrides)
        section = campaign.mission(tuning.TUNING_MISSION, overrides).section("estimator")
        t0 = time.perf_counter()
        results = campaign.run(jobs, args.workers, progress=sys.stderr.isatty())
        rec = {"estimator_section": section, "overrides": dict(overrides),
               "profiles": list(profiles), "seeds": list(seeds),
               "methods": record(results, methods), "flights": len(jobs),
               "wall_s": round(time.perf_counter() - t0, 1), "command": command, "commit": _commit()}
        with (args.out / RECORDS).open("a", encoding="utf-8") as f:
            f.write(json.dumps(rec) + "\n")
        write_table(args.out)
        print(table([rec]).splitlines()[-1], flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
