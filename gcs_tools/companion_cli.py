"""``beliefnav companion``: the estimator beside a real autopilot (= ``python -m companion estimator
--master``): discovery, stream requests, estimates, optional feed back, run.tlog + summary.json.
``--config FILE`` gives any option in a YAML file (:mod:`gcs_tools.companion_config`).
``--setup-signing`` instead gives the autopilot our signing key (SETUP_SIGNING) and checks that it
signs from then on."""

from __future__ import annotations

import argparse
import dataclasses
import json
import signal
import sys

from companion.autopilot.options import add_master_arguments, add_signing_argument
from companion.errors import UserError
from companion.telemetry import pubsub as telemetry
from gcs_tools import choices, companion_config


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_master_arguments(parser, master_required=False)  # required, but it may come from --config
    add_signing_argument(parser)
    parser.add_argument("--setup-signing", action="store_true",
                        help="send the autopilot our --signing-key-file (SETUP_SIGNING), check that it "
                             "signs with it, and exit")
    choices.add_method_argument(parser)
    telemetry.add_arguments(parser, publisher=True)
    companion_config.add_config_argument(parser)
    parser.set_defaults(_option_defaults=companion_config.defer_defaults(parser), _config_parser=parser)


def run(args: argparse.Namespace) -> int:
    from companion.autopilot.service import config_from_args
    from companion.autopilot.service import run as run_companion
    from companion.runtime import dump_stacks_on_sigusr1, exit_on_sigterm

    sections = companion_config.merge(args, args._config_parser, args._option_defaults)
    if args.master is None:
        raise UserError("--master URL is required (or `master:` in the --config file)")
    if args.setup_signing:
        from companion.autopilot.signing_setup import setup_from_args

        ok, line = setup_from_args(args)
        print(line if ok else f"beliefnav: error: {line}", file=sys.stdout if ok else sys.stderr)
        return 0 if ok else 1
    exit_on_sigterm()  # while setting up; the run itself reads Ctrl-C and SIGTERM between messages
    dump_stacks_on_sigusr1()
    config = config_from_args(args)
    if sections:
        config = dataclasses.replace(config,
                                     estimator=companion_config.estimator_config(sections, args.config),
                                     tight=companion_config.tight_config(sections, args.config))
    print(f"companion: waiting for a HEARTBEAT on {args.master} (up to {args.discovery_timeout_s:g} s)",
          flush=True)
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
    if summary.get("failure"):
        print(f"beliefnav: error: {summary['failure']}", file=sys.stderr)
        return 1
    return 128 + signal.SIGTERM if summary.get("stop_signal") == "SIGTERM" else 0  # 143, as before
