"""``beliefnav export RUN --format mcap|csv [--out FILE]``."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from companion.errors import UserError

FORMATS = ("mcap", "csv")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run", type=Path,
                        help="run directory (fly/sitl --out), a .tlog or a .jsonl recording")
    parser.add_argument("--format", choices=FORMATS, default="mcap", help="output format (default mcap)")
    parser.add_argument("--out", type=Path, default=None,
                        help="output file (default: RUN/export.FORMAT for a directory, else RUN with the "
                             "format's suffix)")
    parser.add_argument("--vehicle", default=None, help="vehicle of a recording (default: the first)")
    parser.add_argument("--home", default=None, metavar="LAT,LON,ALT",
                        help="local NED origin for a tlog (default: its first 3-D fix)")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")


def run(args: argparse.Namespace) -> int:
    from companion.domain.geodesy import parse_home
    from gcs_tools.export.flight import load_flight
    from gcs_tools.export.mcap_out import write_mcap

    home = parse_home(args.home) if args.home else None
    flight = load_flight(args.run, args.vehicle, home)
    out = args.out or (args.run / f"export.{args.format}" if args.run.is_dir()
                       else args.run.with_suffix(f".{args.format}"))
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        if args.format == "mcap":
            counts = write_mcap(flight, out)
        else:
            flight.write_csv(out)
            counts = {"rows": len(flight.t_s)}
    except OSError as exc:
        raise UserError(f"{out}: cannot write: {exc.strerror or exc}") from None
    result = {"out": str(out), "format": args.format, "source": flight.source, "rows": len(flight.t_s),
              "duration_s": float(flight.t_s[-1] - flight.t_s[0]) if len(flight.t_s) else 0.0,
              "messages": counts, "bytes": out.stat().st_size}
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    print(f"exported {flight.name}: {result['rows']} rows, {result['duration_s']:.1f} s -> {out} "
          f"({result['bytes'] / 1e6:.2f} MB)")
    if args.format == "mcap":
        print("  topics: " + ", ".join(f"{k} ({n})" for k, n in counts.items()))
    return 0

