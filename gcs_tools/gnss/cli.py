"""``beliefnav gnss spp INPUT``: single-point solutions from raw GNSS, scored against truth.

INPUT is a smartLoc ``*_Input.txt`` (truth: the ``*_GT.txt`` beside it, or ``--truth``: any format
``gcs_tools.gnss.truth`` reads), a RINEX 2, 3 or 4
observation file (with ``--nav``) or a u-blox UBX log. Writes ``fixes.csv``, ``summary.json`` and,
with truth, ``spp_errors.csv`` (``t_s,err_n_m,err_e_m,err_d_m,h_acc_m,v_acc_m``: SPP − truth in the
NED frame at the first truth point, the solution's 1-σ accuracies) to ``--out``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np

from companion.errors import UserError
from companion.gnss.spp import WEIGHTINGS, SppConfig
from companion.gnss.systems import FROM_RINEX_LETTER, RINEX_LETTER, System
from gcs_tools.gnss import baseline
from gcs_tools.gnss.sources import GnssInput, load_input
from gcs_tools.jsonvalues import plain_json

VARIANTS: tuple[tuple[str, dict[str, Any]], ...] = (
    ("uniform", {"weighting": "uniform"}),
    ("uniform + RAIM/FDE", {"weighting": "uniform", "raim": True}),
    ("C/N0+elevation", {"weighting": "cn0-elevation"}),
    ("C/N0+elevation + RAIM/FDE", {"weighting": "cn0-elevation", "raim": True}),
    ("C/N0+elevation, no Earth rotation", {"weighting": "cn0-elevation", "earth_rotation": False}),
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="gnss_command", required=True, metavar="ACTION")
    p = sub.add_parser(
        "spp",
        help="single-point solutions (weighted least squares), errors vs truth",
        description=__doc__.splitlines()[0],
    )
    p.add_argument(
        "input",
        type=Path,
        help="smartLoc *_Input.txt, RINEX 2/3/4 observation file (compressed or not) or UBX log",
    )
    p.add_argument(
        "--nav",
        type=Path,
        action="append",
        default=[],
        help="RINEX 2/3/4 navigation files for a RINEX observation input (repeatable; RINEX 2: one a system)",
    )
    p.add_argument(
        "--truth",
        type=Path,
        default=None,
        help="truth file, recognised by content: smartLoc *_GT.txt (default: the one beside a smartLoc "
        "input), a SPAN/Inertial Explorer text export or a CSV (gps_week,gps_tow_s or t_gps_s; "
        "lat_deg,lon_deg,h_m or x_m,y_m,z_m); GPS time (docs/gnss.md)",
    )
    p.add_argument(
        "--truth-ecef",
        default=None,
        metavar="X,Y,Z",
        help="a static receiver's true ECEF position (m) instead of a truth file",
    )
    p.add_argument(
        "--out", type=Path, default=Path("runs/gnss-spp"), help="output directory (default runs/gnss-spp)"
    )
    p.add_argument(
        "--weighting",
        default="cn0-elevation",
        choices=WEIGHTINGS,
        help="pseudorange σ model (default cn0-elevation)",
    )
    p.add_argument("--raim", action="store_true", help="RAIM/FDE: χ² test, exclude the worst satellite")
    p.add_argument(
        "--no-earth-rotation", action="store_true", help="leave the Sagnac term out (to see what it is worth)"
    )
    p.add_argument("--elevation-mask-deg", type=float, default=SppConfig.elevation_mask_deg,
                   help=f"satellites below this elevation (deg) are not used "
                        f"(default {SppConfig.elevation_mask_deg:g})")
    p.add_argument(
        "--systems",
        default=None,
        metavar="LETTERS",
        help="solve with these constellations only, RINEX letters (e.g. G, GE, G,E,J: GPS, Galileo, "
        "QZSS; C BeiDou, R GLONASS); the others' observations are counted (system_not_selected)",
    )
    p.add_argument(
        "--variants",
        action="store_true",
        help="also solve the weighting on/off x RAIM on/off table (summary.json 'variants')",
    )
    p.add_argument("--json", action="store_true", help="print summary.json")


def run(args: argparse.Namespace) -> int:
    from gcs_tools.outdir import check_out_dir

    if not args.input.is_file():
        raise UserError(f"{args.input}: no such file")
    if not (0.0 <= args.elevation_mask_deg < 90.0):
        raise UserError(f"--elevation-mask-deg {args.elevation_mask_deg}: expected 0 to 90")
    check_out_dir(args.out)
    systems = parse_systems(args.systems) if args.systems is not None else None
    data = load_input(args.input, args.nav, args.truth, args.truth_ecef)
    if systems is not None:
        data = select_systems(data, systems)
    config = SppConfig(
        weighting=args.weighting,
        raim=args.raim,
        earth_rotation=not args.no_earth_rotation,
        elevation_mask_deg=args.elevation_mask_deg,
    )
    summary, series, err = evaluate(data, config)
    if args.variants:
        summary["variants"] = {
            name: evaluate(data, dataclasses.replace(config, **changes))[0]["errors"]
            for name, changes in VARIANTS
        }
    args.out.mkdir(parents=True, exist_ok=True)
    _write_fixes(args.out / "fixes.csv", series, err)
    files = [args.out / "fixes.csv", args.out / "summary.json"]
    if err is not None:
        baseline.write_error_csv(args.out / "spp_errors.csv", series.t_s, err, series.h_acc_m, series.v_acc_m)
        files.append(args.out / "spp_errors.csv")
    (args.out / "summary.json").write_text(json.dumps(plain_json(summary, nan_to_none=True), indent=2) + "\n")
    if args.json:
        print((args.out / "summary.json").read_text(), end="")
        return 0
    print(report(summary))
    print("  wrote " + ", ".join(str(f) for f in files))
    return 0


def parse_systems(text: str) -> tuple[System, ...]:
    """``--systems``: RINEX system letters (``GE``, ``G,E,J``) -> the systems, in the order given."""
    letters = [c for c in text.upper() if c not in ", "]
    unknown = sorted({c for c in letters if c not in FROM_RINEX_LETTER or c == "S"})
    if not letters or unknown:
        raise UserError(
            f"--systems {text!r}: expected RINEX letters G (GPS), E (Galileo), C (BeiDou), J (QZSS), "
            f"R (GLONASS)" + (f"; not one: {', '.join(unknown)}" if unknown else "")
        )
    return tuple(dict.fromkeys(FROM_RINEX_LETTER[c] for c in letters))


def select_systems(data: GnssInput, systems: tuple[System, ...]) -> GnssInput:
    """The input with only these systems' observations; the others counted (``system_not_selected``),
    epochs left empty dropped. A one-line error when nothing is left."""
    keep = np.array([int(s) for s in systems])
    epochs = []
    dropped = 0
    for e in data.epochs:
        m = np.isin(e.system, keep)
        dropped += int((~m).sum())
        if m.any():
            epochs.append(e if m.all() else e.select(m))
    if not epochs:
        names = "".join(RINEX_LETTER[s] for s in systems)
        raise UserError(f"{data.path}: no observation of the systems {names} (--systems)")
    rejected = data.rejected.copy()
    if dropped:
        rejected["system_not_selected"] += dropped
    return dataclasses.replace(data, epochs=epochs, rejected=rejected)


def evaluate(
    data: GnssInput, config: SppConfig
) -> tuple[dict[str, Any], baseline.SppSeries, np.ndarray | None]:
    """Solve every epoch; with truth, the errors and the residuals at the true position."""
    series = baseline.solve_series(data.epochs, config, data.klobuchar)
    summary: dict[str, Any] = {
        "input": str(data.path),
        "format": data.format,
        "config": dataclasses.asdict(config),
        "epochs": len(data.epochs),
        "solutions": int(series.ok.sum()),
        "satellites_used": {
            "median": float(np.median(series.n_used[series.ok])) if series.ok.any() else None
        },
        "raim_exclusions": int(series.n_excluded.sum()),
        "rejected": dict(data.rejected),
        "reasons_no_solution": _reasons(series),
    }
    err = None
    truth = data.truth_at(series.t_s)
    if truth is not None:
        origin = truth[np.isfinite(truth).all(axis=1)][0]
        err = baseline.ned_errors(series.p_ecef_m, truth, origin)
        summary["errors"] = baseline.error_statistics(series.t_s, err, series.h_acc_m, series.v_acc_m)
        summary["residuals_at_truth_m"] = baseline.residuals_at_truth(
            data.epochs, truth, config, data.klobuchar
        )
        summary["truth"] = data.truth_note
        if data.truth is not None and data.truth.rejected:
            summary["truth_rows_rejected"] = dict(data.truth.rejected)
    return summary, series, err


def _reasons(series: baseline.SppSeries) -> dict[str, int]:
    out: dict[str, int] = {}
    for s in series.solutions:
        if not s.ok:
            out[s.reason] = out.get(s.reason, 0) + 1
    return out


def _write_fixes(path: Path, series: baseline.SppSeries, err: np.ndarray | None) -> None:
    from companion.gnss.geometry import ecef_to_geodetic

    lat, lon, h = ecef_to_geodetic(series.p_ecef_m)
    cols = [
        series.t_s,
        series.p_ecef_m[:, 0],
        series.p_ecef_m[:, 1],
        series.p_ecef_m[:, 2],
        np.rad2deg(lat),
        np.rad2deg(lon),
        h,
        series.h_acc_m,
        series.v_acc_m,
        series.hdop,
        series.n_used,
        series.n_excluded,
    ]
    header = (
        "t_s,x_ecef_m,y_ecef_m,z_ecef_m,lat_deg,lon_deg,h_ellipsoid_m,h_acc_m,v_acc_m,hdop,n_used,n_excluded"
    )
    if err is not None:
        cols += [err[:, 0], err[:, 1], err[:, 2]]
        header += ",err_n_m,err_e_m,err_d_m"
    table = np.column_stack(cols)[series.ok]
    np.savetxt(path, table, delimiter=",", fmt="%.10g", header=header, comments="")


def report(s: dict[str, Any]) -> str:
    c = s["config"]
    lines = [
        f"spp on {Path(s['input']).name} ({s['format']}): {s['epochs']} epochs, {s['solutions']} solutions "
        f"(weighting {c['weighting']}, RAIM {'on' if c['raim'] else 'off'}"
        f"{', no Earth rotation' if not c['earth_rotation'] else ''}; "
        f"{s['raim_exclusions']} exclusions)"
    ]
    # input rows skipped while reading (a UBX file's "rejected" are its decoder's counters, decoded included)
    skipped = {k: v for k, v in (s.get("rejected") or {}).items() if v} if s["format"] != "ubx" else {}
    if skipped:
        lines.append("  input rows skipped: " + ", ".join(f"{k} {v}" for k, v in sorted(skipped.items())))
    if s.get("truth_rows_rejected"):
        skipped_truth = sorted(s["truth_rows_rejected"].items())
        lines.append("  truth rows skipped: " + ", ".join(f"{k} {v}" for k, v in skipped_truth))
    e = s.get("errors")
    if e:
        lines.append(_row_text(e))
        ct = e["correlation_time_s"]
        lines.append(
            f"  epoch-to-epoch horizontal step median {e['step_horizontal_m']['median']:.1f} m; "
            f"correlation time N {ct['north']:.1f} s E {ct['east']:.1f} s D {ct['down']:.1f} s; "
            f"mean error NED {', '.join(f'{v:+.1f}' for v in e['mean_ned_m'])} m"
        )
        lines.append(
            f"  actual / reported accuracy (RMS): horizontal {e['accuracy_ratio_horizontal']:.2f}, "
            f"vertical {e['accuracy_ratio_vertical']:.2f}"
        )
        for name, bins in s.get("residuals_at_truth_m", {}).items():
            cells = "  ".join(f"{k} {v['median']:+.1f} (n {v['n']})" for k, v in bins.items() if v["n"])
            lines.append(f"  residual at truth, median m, {name}: {cells}")
    for name, ev in s.get("variants", {}).items():
        lines.append(f"  variant {name:36s}" + _row_text(ev).strip())
    return "\n".join(lines)


def _row_text(e: dict[str, Any]) -> str:
    h = e["horizontal_m"]
    return (
        f"  horizontal error median {h['median']:.1f} m p95 {h['p95']:.1f} m, "
        f"{e['percent_above_5m']:.0f} % > 5 m; vertical |error| median {e['vertical_abs_m']['median']:.1f} m"
    )
