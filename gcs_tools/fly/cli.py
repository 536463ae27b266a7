"""``beliefnav fly --mission FILE|default --profile N --method M --seed S --out DIR``."""

from __future__ import annotations

import argparse
import sys
import time

from gcs_tools import choices


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--mission", default="default", help="mission YAML file, or 'default' / 'test'")
    parser.add_argument("--profile", type=int, default=0, help="mission profile index (default 0)")
    choices.add_method_argument(parser)
    parser.add_argument("--seed", type=int, default=0, help="random seed of the run (default 0)")
    parser.add_argument("--scenario", default=None,
                        help="sensor scenario: paper, realistic, mismatch (default: the mission file's)")
    parser.add_argument("--max-duration-s", type=float, default=None, metavar="S",
                        help="stop after S simulated seconds (default: route duration + margin)")
    choices.add_deprecated_alias(parser, "--max-duration", "--max-duration-s", "max_duration_s", type=float)
    parser.add_argument("--out", default="runs/fly", help="output directory (default runs/fly)")
    parser.add_argument("--json", action="store_true", help="print summary.json instead of the summary lines")


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from companion.mission import with_scenario
    from gcs_tools import choices
    from gcs_tools.fly.output import write_outputs
    from gcs_tools.outdir import ensure_out_dir
    from gcs_tools.summaries import print_summary, run_info
    from simvehicle.harness.fly import fly

    mission = choices.mission(args.mission)  # every option checked before anything is written
    if args.scenario is not None:
        mission = with_scenario(mission, args.scenario)
    choices.profile(mission, args.profile)
    choices.method(args.method)
    ensure_out_dir(args.out)
    start_unix_s = time.time()
    result = fly(mission, args.profile, args.method, args.seed, max_duration_s=args.max_duration_s)
    result.summary.update(run_info(mission, args.mission, start_unix_s))
    paths = write_outputs(result, mission.world, args.out)
    s = result.summary
    print_summary("fly", s, Path(args.out), [p.name for p in paths], args.json)
    if not s["reached_goal"]:  # time-out or collision: a failure, said in one line
        why = f"collided {s['collisions']} time(s)" if s["collisions"] else "did not reach the goal in time"
        print(f"beliefnav: error: the vehicle {why} ({s['duration_s']:.1f} s simulated)", file=sys.stderr)
        return 1
    return 0
