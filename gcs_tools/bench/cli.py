"""``beliefnav bench TARGET --json``: each target module defines ``measure(args) -> dict``."""

from __future__ import annotations

import argparse
import importlib
import json
import platform
import sys

import numpy as np

TARGETS = {
    "estimator": "gcs_tools.bench.estimator",
    "fly": "gcs_tools.bench.fly",
    "sitl": "gcs_tools.bench.sitl",
    "telemetry": "gcs_tools.bench.telemetry",
    "evaluate": "gcs_tools.bench.evaluate",
    "plan": "gcs_tools.bench.plan",
    "autopilot": "gcs_tools.bench.autopilot",
    "replay": "gcs_tools.bench.replay",
    "ardupilot": "gcs_tools.bench.ardupilot",
    "companion-memory": "gcs_tools.bench.companion_memory",
    "gnss": "gcs_tools.bench.gnss",
    "cli": "gcs_tools.bench.cli_start",
    "robustness": "gcs_tools.bench.robustness",
    "receiver": "gcs_tools.bench.receiver",
    "tight": "gcs_tools.bench.tight",
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("target", choices=[*TARGETS, "all"], help="what to measure")
    parser.add_argument("--json", action="store_true",
                        help="print one JSON object (default: the same figures as aligned lines)")
    parser.add_argument("--quick", action="store_true", help="shorter runs (smoke check, noisier figures)")


def machine() -> dict[str, object]:
    import os

    return {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "cpu": platform.processor() or platform.machine(),
        "cores": os.cpu_count(),
    }


def human_lines(value: object, prefix: str = "") -> list[str]:
    """Nested figures as ``a.b.c  value`` lines (numbers to 4 significant digits); a list of records
    (e.g. ``bench robustness``'s cases) one line per record, ``key=value`` pairs, not one JSON line."""
    if isinstance(value, dict):
        return [line for k, v in value.items() for line in human_lines(v, f"{prefix}{k}.")]
    if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
        return [f"{prefix}{i}".ljust(48) + " " + "  ".join(_pairs(v)) for i, v in enumerate(value)]
    if isinstance(value, float):
        text = f"{value:.4g}"
    else:
        text = json.dumps(value) if isinstance(value, list) else str(value)
    return [f"{prefix.rstrip('.'):<48} {text}"]


def _pairs(record: dict[str, object], prefix: str = "") -> list[str]:
    out: list[str] = []
    for k, v in record.items():
        if isinstance(v, dict):
            out += _pairs(v, f"{prefix}{k}.")
        else:
            out.append(f"{prefix}{k}={f'{v:.4g}' if isinstance(v, float) else v}")
    return out


def run(args: argparse.Namespace) -> int:
    names = list(TARGETS) if args.target == "all" else [args.target]
    results = {name: importlib.import_module(TARGETS[name]).measure(args) for name in names}
    out = {"machine": machine(), **(results if len(names) > 1 else results[names[0]])}
    print(json.dumps(out, indent=2) if args.json else "\n".join(human_lines(out)))
    sys.stdout.flush()
    return 0
