"""``beliefnav export RUN --format mcap|csv [--out FILE]``."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from companion.errors import UserError
from gcs_tools import choices

FORMATS = ("mcap", "csv")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run", type=Path,
                        help="run directory (fly/sitl --out), a .tlog or a .jsonl recording")
    parser.add_argument("--format", choices=FORMATS, default="mcap", help="output format (default mcap)")
    parser.add_argument("--out", type=Path, default=None,
                        help="output file (default: RUN/export.FORMAT for a directory, else RUN with the "
                             "format's suffix)")
    parser.add_argument("--vehicle-id", default=None, metavar="ID",
                        help="telemetry vehicle id of a recording (default: the first)")
    # the old spelling (`sitl --vehicle` names a backend, not a telemetry id): works, with a note
    choices.add_deprecated_alias(parser, "--vehicle", "--vehicle-id", "vehicle_id")
    parser.add_argument("--home", default=None, metavar="LAT,LON,ALT",
                        help="local frame origin (default: the flight's own: the log's GPS_GLOBAL_ORIGIN or "
                             "HOME_POSITION, the run's mission, else the first 3-D fix); a --home far from "
                             "the flight is refused, one off the log's origin warned about")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")


def run(args: argparse.Namespace) -> int:
    from companion.domain.geodesy import parse_home
    from gcs_tools.cli import version
    from gcs_tools.export.flight import load_flight
    from gcs_tools.export.mcap_out import write_mcap

    home = parse_home(args.home) if args.home else None
    flight = load_flight(args.run, args.vehicle_id, home)
    for warning in flight.warnings:
        print(f"beliefnav: warning: {warning}", file=sys.stderr)
    out = args.out or (args.run / f"export.{args.format}" if args.run.is_dir()
                       else args.run.with_suffix(f".{args.format}"))
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        if args.format == "mcap":
            counts = write_mcap(flight, out, version())
        else:
            flight.write_csv(out)
            counts = {"rows": len(flight.t_s)}
    except OSError as exc:
        raise UserError(f"{out}: cannot write: {exc.strerror or exc}") from None
    f = flight.frame
    result = {"out": str(out), "format": args.format, "source": flight.source, "rows": len(flight.t_s),
              "duration_s": float(flight.t_s[-1] - flight.t_s[0]) if len(flight.t_s) else 0.0,
              "fixes": len(flight.fixes), "clock": flight.clock, "epoch_unix_s": flight.epoch_unix_s,
              "home": None if f is None else {"lat_deg": f.home_lat_deg, "lon_deg": f.home_lon_deg,
                                              "alt_m": f.home_alt_m, "source": flight.home_source},
              "warnings": flight.warnings, "messages": counts, "bytes": out.stat().st_size}
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    print(f"exported {flight.name}: {result['rows']} rows, {result['duration_s']:.1f} s, "
          f"{len(flight.fixes)} GNSS fixes -> {out} ({result['bytes'] / 1e6:.2f} MB)")
    t0_s = float(flight.t_s[0]) if len(flight.t_s) else 0.0
    when = ("unknown wall clock" if flight.epoch_unix_s is None
            else time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(flight.epoch_unix_s + t0_s)))
    where = ("no home" if f is None
             else f"home {f.home_lat_deg:.6f},{f.home_lon_deg:.6f} from {flight.home_source}")
    print(f"  starts {when}; {where}")
    if args.format == "mcap":
        print("  topics: " + ", ".join(f"{k} ({n})" for k, n in counts.items()))
    return 0

