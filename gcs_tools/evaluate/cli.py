"""``beliefnav evaluate``: argument parsing and wiring only.

    beliefnav evaluate --profiles 10 --methods naive,adaptive,first-order,second-order \\
        --seeds 0-49 --workers 2 --out runs/eval [--scheduler tcp://127.0.0.1:8786]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path
from typing import Any

from companion.errors import UserError
from companion.estimator.methods import DEFAULT_METHOD
from gcs_tools import choices
from gcs_tools.evaluate import campaign, tuning
from gcs_tools.evaluate import rows as rows_mod
from gcs_tools.jsonvalues import plain_json

DEFAULT_METHODS = "naive,adaptive,first-order,second-order"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--vehicle", default="sim", choices=("sim", "ardupilot", "px4"),
                        help="sim: our simulated vehicle; ardupilot: ArduCopter SITL, EKF3 as its own row; "
                             "px4: PX4 SITL (SIH quadrotor), EKF2 as its own row")
    parser.add_argument("--speedup", type=float, default=None, help="ardupilot: SITL --speedup (default 10)")
    parser.add_argument("--speed-factor", type=float, default=None,
                        help="px4: PX4_SIM_SPEED_FACTOR, at most 10 (default 5)")
    parser.add_argument("--feeds", default=None,
                        help="ardupilot/px4: loops flown (default all): none (open loop, the EKF with GNSS "
                             "velocity), none-posonly (the EKF on positions only), and closed loops on the "
                             "companion process: ardupilot gps-input, vision; px4 odometry")
    parser.add_argument("--resume", action="store_true",
                        help="ardupilot/px4: continue a campaign in --out (e.g. after Ctrl-C) with the "
                             "options it was started with: a flight whose directory holds a complete result "
                             "is read back, not flown; incomplete ones are cleared and flown again")
    parser.add_argument("--mission", default="default",
                        help="mission name (default, test, default-tuning, mild, mild-tuning) or YAML path")
    parser.add_argument("--profiles", default="10",
                        help="mission profiles: a count N (profiles 0..N-1) or a list/range like 10-13")
    choices.add_deprecated_alias(parser, "--missions", "--profiles", "profiles")
    parser.add_argument("--methods", default=None,
                        help=f"comma-separated estimator methods (default {DEFAULT_METHODS}), "
                             "or row labels of --rows")
    parser.add_argument("--rows", type=Path, default=None, metavar="FILE",
                        help="ablation rows: YAML 'rows: {label: {method: M, set: {SECTION.FIELD: V}}}' "
                             "(each method with its own hyper-parameters)")
    parser.add_argument("--scenario", default=None,
                        help="sensor scenario: paper, realistic, mismatch, canyon (default: the mission "
                             "file's; --vehicle ardupilot|px4: paper or canyon, the calibrated raw receiver)")
    parser.add_argument("--reference", default=None, metavar="ROW[,ROW...]",
                        help="row the paired per-flight differences are taken against "
                             "(default second-order if present, else the first row); more rows after "
                             "a comma get their own paired table in results.json")
    parser.add_argument("--seeds", default="0", help="seeds, e.g. 0-49 or 0,3,7 (default: 0)")
    parser.add_argument("--workers", type=int, default=1, help="local worker processes (default: 1)")
    parser.add_argument("--scheduler", default=None, metavar="ADDRESS",
                        help="run on this Dask distributed scheduler instead of the local pool")
    parser.add_argument("--max-duration-s", type=float, default=None, metavar="S",
                        help="cap each flight at S seconds of simulated time")
    choices.add_deprecated_alias(parser, "--max-duration", "--max-duration-s", "max_duration_s", type=float)
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.FIELD=VALUE",
                        help="override one mission config field for every flight (all methods), e.g. "
                             "estimator.r_inflation_max=100; repeatable")
    parser.add_argument("--out", type=Path, default=Path("runs/eval"),
                        help="output directory (default runs/eval)")
    parser.add_argument("--json", action="store_true",
                        help="print the campaign's headline (paper claims, per-method medians) as JSON")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--readme", type=Path, default=None, metavar="PATH",
                        help="also splice the table and figures into this README (block keyed by --out)")


def parse_methods(text: str) -> tuple[str, ...]:
    return tuple(choices.methods(text))  # each checked: the valid ones and the nearest named


def parameters(mission: Any) -> dict[str, Any]:
    """Estimator defaults and this mission's overrides, for the report."""
    from companion.estimator import EstimatorConfig

    out: dict[str, Any] = {"estimator_defaults": campaign.jsonable(dataclasses.asdict(EstimatorConfig()))}
    for name in ("estimator", "gnss", "imu", "ahrs", "belief_plugins", "autopilot", "vehicle"):
        section = mission.section(name)
        if section:
            out[f"mission_{name}"] = campaign.jsonable(section)
    return out


def run(args: argparse.Namespace) -> int:
    if args.vehicle in ("ardupilot", "px4"):
        return run_autopilot(args)
    if args.feeds is not None or args.speedup is not None or args.speed_factor is not None or args.resume:
        raise UserError("--feeds, --speedup, --speed-factor and --resume apply to --vehicle ardupilot or px4")
    overrides = tuple(tuning.parse_override(text) for text in args.set)
    mission = campaign.mission(args.mission, overrides, args.scenario)
    tuning.check(mission)
    profiles = choices.profiles(args.profiles, len(mission.profiles))
    if args.rows is not None:
        rows = rows_mod.select(rows_mod.load_rows(args.rows), args.methods)
    else:
        rows = [campaign.Row(m, m) for m in parse_methods(args.methods or DEFAULT_METHODS)]
    for row in rows:
        tuning.check(campaign.mission(args.mission, overrides + row.overrides, args.scenario))
    methods = tuple(row.label for row in rows)
    references = [r.strip() for r in (args.reference or "").split(",") if r.strip()] or [
        DEFAULT_METHOD if DEFAULT_METHOD in methods else methods[0]]
    for ref in references:
        if ref not in methods:
            raise UserError(f"--reference {ref!r}: not among the rows ({', '.join(methods)})")
    reference = references[0]
    seeds = choices.seeds(args.seeds)
    jobs = campaign.grid_rows(args.mission, profiles, rows, seeds, args.max_duration_s, overrides,
                              args.scenario)
    t0 = time.perf_counter()
    results = campaign.run(jobs, args.workers, args.scheduler, progress=not args.no_progress)
    wall_s = time.perf_counter() - t0
    info = {
        "mission": args.mission, "profiles": list(profiles), "methods": list(methods), "seeds": list(seeds),
        "max_duration_s": args.max_duration_s, "flights": len(jobs), "workers": args.workers,
        "scheduler": args.scheduler, "wall_s": wall_s, "overrides": dict(overrides),
        "parameters": parameters(mission), "scenario": mission.scenario, "reference": reference,
        "more_references": references[1:],
        "rows": {row.label: {"method": row.method, "overrides": dict(row.overrides)} for row in rows},
        "flight_cpu_s": sum(r.flight.get("cpu_s", 0.0) for r in results),
    }
    from gcs_tools.evaluate import report  # (matplotlib: imported only when there is something to draw)

    res = report.write(args.out, results, methods, info, mission)
    if args.readme is not None:
        report.splice_readme(args.readme, args.out.name, report.readme_section(res, args.out, args.readme))
    if args.json:
        head = {"out": str(args.out), "flights": len(jobs), "wall_s": wall_s,
                "paper_claims": res.get("paper_claims"), "methods": res.get("methods")}
        print(json.dumps(plain_json(head, nan_to_none=True), indent=2, allow_nan=False))
    else:
        print(report.table(res), end="")
    print(f"wrote {args.out}/results.json, report.md and {len(res['figures'])} figures "
          f"({len(jobs)} flights, {wall_s:.1f} s)", file=sys.stderr)
    return 0



def run_autopilot(args: argparse.Namespace) -> int:
    from companion.mission import load_mission
    from gcs_tools.evaluate import ardupilot, autopilot, px4
    from simvehicle.harness.foreign.flight import FOREIGN_SCENARIOS

    if args.set or args.scheduler or args.readme or args.rows is not None \
            or args.max_duration_s is not None:
        raise UserError("--set, --scheduler, --readme, --max-duration-s and --rows apply to --vehicle sim "
                        "only")
    speed = {"ardupilot": ("--speedup", args.speedup), "px4": ("--speed-factor", args.speed_factor)}
    for name, (option, value) in speed.items():
        if name != args.vehicle and value is not None:
            raise UserError(f"{option} applies to --vehicle {name} only")
    spec = (ardupilot if args.vehicle == "ardupilot" else px4).CAMPAIGN
    config = spec.config(speed[args.vehicle][1])
    mission = load_mission(args.mission, args.scenario)
    if mission.scenario not in FOREIGN_SCENARIOS:
        raise UserError(f"--scenario {mission.scenario}: with --vehicle {args.vehicle}, one of "
                        f"{', '.join(FOREIGN_SCENARIOS)}")
    profiles = choices.profiles(args.profiles, len(mission.profiles))
    methods = parse_methods(args.methods or DEFAULT_METHODS)
    seeds = choices.seeds(args.seeds)
    feeds = autopilot.check_feeds(spec, args.feeds or ",".join(spec.loop_names))
    res = autopilot.evaluate(spec, args.mission, profiles, methods, seeds, args.workers, args.out, config,
                             feeds, args.scenario, args.resume)
    print(autopilot.table_text(spec, res), end="")
    print(f"wrote {args.out}/results.json, report.md, errors_horizontal.png and flights/ "
          f"({len(res['info']['flights'])} flights, {res['info']['read_back']} read back, "
          f"{res['info']['wall_s']:.1f} s)", file=sys.stderr)
    return 0
