"""``beliefnav companion``: the estimator beside a real autopilot (= ``python -m companion estimator
--master``): discovery, stream requests, estimates, optional feed back, run.tlog + summary.json."""

from __future__ import annotations

import argparse
import json

from companion.autopilot.node import config_from_args
from companion.autopilot.node import run as run_companion
from companion.autopilot.options import add_master_arguments
from companion.telemetry import pubsub as telemetry
from gcs_tools import choices


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_master_arguments(parser, master_required=True)
    choices.add_method_argument(parser)
    telemetry.add_arguments(parser, publisher=True)


def run(args: argparse.Namespace) -> int:
    from companion.runtime import exit_on_sigterm

    exit_on_sigterm()  # SIGTERM ends the run like Ctrl-C: summary.json is still written
    config = config_from_args(args)
    publisher = telemetry.publisher_from_args(args, "companion")
    try:
        summary = run_companion(config, publisher)
    except KeyboardInterrupt:
        summary = json.loads((config.out_dir / "summary.json").read_text())
    finally:
        publisher.close()
    ap = summary.get("autopilot") or {}
    err = (summary.get("errors") or {}).get("autopilot_estimate") or {}
    horiz = (err.get("error_horizontal_m") or {}).get("median")
    print(f"autopilot: {ap.get('autopilot', '-')} {ap.get('vehicle', '')} system {ap.get('system_id', '-')}; "
          f"samples used {summary['samples']['used']}; "
          f"median horizontal difference to the autopilot's estimate: "
          f"{'-' if horiz is None else f'{horiz:.2f} m'}; outputs in {config.out_dir}")
    return 0
