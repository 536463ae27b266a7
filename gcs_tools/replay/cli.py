"""``beliefnav replay FILE --method M --out DIR``: argument parsing and wiring only."""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path
from typing import Any

from companion.domain.geodesy import parse_home
from companion.errors import UserError
from companion.mission import Mission
from companion.telemetry import pubsub as telemetry
from gcs_tools import choices
from gcs_tools.replay import core, gnss_record
from gcs_tools.replay.synthetic_gnss import ACCURACY_MODES, BASES, GnssErrorOptions, velocity_option


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", type=Path, nargs="?",
                        help="log to replay: MAVLink tlog, ArduPilot DataFlash .bin or PX4 ULog .ulg "
                             "(recognised by its first bytes, else by extension), or an ANSFL flight "
                             "(a directory with IMU_1.csv and GT.csv, or its IMU_1.csv); not with --smartloc")
    choices.add_method_argument(parser)
    parser.add_argument("--out", type=Path, default=Path("runs/replay"),
                        help="output directory for estimates.csv, summary.json, track.png, errors.png "
                             "(default runs/replay)")
    parser.add_argument("--json", action="store_true", help="print summary.json instead of the summary lines")
    parser.add_argument("--home", default=None, metavar="LAT,LON,ALT",
                        help="local-frame origin (degrees, degrees, metres); default: the mission's home "
                             "with --mission, else the first good fix")
    parser.add_argument("--mission", default=None, metavar="NAME|PATH",
                        help="take the estimator config (the mission's estimator: section) and home from "
                             "this mission, as the SITL estimator did; default: EstimatorConfig defaults "
                             "(real-log values), home = first good fix")
    parser.add_argument("--rate-hz", type=float, default=20.0,
                        help="at most this many estimate rows per second in estimates.csv (default 20; "
                             "0: one per IMU sample)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--no-figures", action="store_true",
                        help="no track.png and errors.png (the figures of the estimate against the log's "
                             "references)")
    parser.add_argument("--publish", action="store_true",
                        help="publish companion/estimate, belief and health on Zenoh (see README)")
    parser.add_argument("--speed", type=float, default=0.0,
                        help="pace the replay at this many times real time (default 0: as fast as possible)")
    parser.add_argument("--gps-delay-ms", type=float, default=None,
                        help="DataFlash logs: how long before its arrival a fix is valid (default: the log's "
                             "GPS1_DELAY_MS when set, else 120 ms)")
    add_gnss_arguments(parser)
    g = parser.add_argument_group("raw GNSS (docs/gnss.md)")
    g.add_argument("--rinex-obs", type=Path, default=None,
                   help="RINEX 2/3/4 observations (compressed or not): their single-point fixes replace "
                        "the log's (joined to boot time through the log's SYSTEM_TIME / GPS time)")
    g.add_argument("--rinex-nav", type=Path, action="append", default=[],
                   help="RINEX 2/3/4 navigation files for --rinex-obs (repeatable; RINEX 2: one a system)")
    g.add_argument("--ubx", type=Path, default=None, metavar="FILE",
                   help="--coupling tight: a u-blox UBX log (RXM-RAWX, RXM-SFRBX) whose raw epochs replace "
                        "the log's fixes, e.g. a canyon run's receiver.ubx (receiver.json beside it joins "
                        "the clocks and gives the ephemerides); with --mission, the mission's map is the "
                        "belief's line-of-sight prior (docs/replay.md)")
    g.add_argument("--smartloc", type=Path, default=None, metavar="INPUT",
                   help="GNSS-only replay of a smartLoc *_Input.txt (no IMU), scored against its _GT.txt")
    g.add_argument("--truth", type=Path, default=None,
                   help="--smartloc's truth: its *_GT.txt (default: beside --smartloc), or a SPAN/Inertial "
                        "Explorer export or truth CSV on the drive's time scale (docs/gnss.md)")
    g.add_argument("--coupling", default="loose",
                   help="loose: SPP fixes into the estimator (default); tight: pseudoranges (and Doppler) "
                        "into the tightly coupled estimator, --method one of its rows (docs/tight.md)")
    g.add_argument("--no-odometry", action="store_true",
                   help="--smartloc --coupling tight: leave the car's wheel speed and yaw rate out")
    telemetry.add_arguments(parser, publisher=True)
    parser.set_defaults(vehicle_id="replay")


def add_gnss_arguments(parser: argparse.ArgumentParser) -> None:
    """The options that replace the log's GNSS by synthetic fixes (docs/replay.md)."""
    g = parser.add_argument_group("synthetic GNSS (replace the log's fixes; docs/replay.md)")
    g.add_argument("--gnss-errors", default=None, metavar="none|model|SERIES.csv|smartloc-sats:INPUT",
                   help="replace the log's fixes by fixes made from its truth (or --gnss-base log) plus: no "
                        "error, the project's urban GNSS model, or a recorded error series (CSV "
                        "t_s,err_n_m,err_e_m,err_d_m,h_acc_m,v_acc_m); or smartloc-sats:INPUT: a smartLoc "
                        "drive's satellites placed on the log's truth (its single-point fixes, or with "
                        "--coupling tight its raw epochs)")
    # the synthetic GNSS options default to None (their defaults applied in gnss_options) so that one given
    # without --gnss-errors is a one-line error, not silently without effect
    g.add_argument("--gnss-rate-hz", type=float, default=None, help="fixes per second (default 5)")
    g.add_argument("--gnss-accuracy", default=None, choices=ACCURACY_MODES,
                   help="what each fix reports: its accuracy (model or series), nothing, or only an HDOP "
                        "(h_acc / 5 m) (default reported)")
    g.add_argument("--gnss-latency-ms", type=float, default=None,
                   help="fixed latency from validity to arrival (default: the model's latency process, "
                        "0.6 s mean in a canyon)")
    g.add_argument("--gnss-base", default=None, choices=BASES,
                   help="what the errors are added to (default: truth when the log has it, else its own "
                        "fixes)")
    g.add_argument("--gnss-clearance-m", type=float, default=None,
                   help="the model's distance to the nearest building (default 0: a street canyon "
                        "throughout)")
    g.add_argument("--gnss-set", action="append", default=[], metavar="gnss.FIELD=VALUE",
                   help="override a field of the model's GnssConfig (repeatable), e.g. "
                        "gnss.sigma_bias_max_m=5")
    g.add_argument("--gnss-velocity", default=None, metavar="STD_M_S|none",
                   help="the fixes' velocity: the base's plus white noise of this std per axis (default 0.2 "
                        "m/s), or none")
    g.add_argument("--gnss-series-start-s", type=float, default=None,
                   help="error series time of the first fix (default: drawn from --seed)")
    g.add_argument("--seed", type=int, default=None, help="seed of the synthetic GNSS (default 0)")


def gnss_options(args: argparse.Namespace) -> GnssErrorOptions | None:
    """The synthetic GNSS the options ask for (None without --gnss-errors); one-line errors."""
    from gcs_tools.evaluate.tuning import parse_override

    if args.gnss_errors is None:
        given = [name for name in ("gnss_set", "gnss_latency_ms", "gnss_base", "gnss_series_start_s",
                                   "gnss_rate_hz", "gnss_accuracy", "gnss_clearance_m", "gnss_velocity",
                                   "seed")
                 if getattr(args, name) not in (None, [])]
        if given:
            raise UserError(f"--{given[0].replace('_', '-')} needs --gnss-errors")
        return None
    overrides = []
    for text in args.gnss_set:
        key, value = parse_override(text)
        section, _, name = key.partition(".")
        if section != "gnss":
            raise UserError(f"--gnss-set {text!r}: only gnss.FIELD (the GNSS model's fields)")
        overrides.append((name, value))
    errors = args.gnss_errors
    if is_sats(errors):  # the placement takes the series condition's options (seed, latency, velocity, ...)
        if args.gnss_base == "log":
            raise UserError("--gnss-base log: smartloc-sats places the drive's satellites on the log's truth")
        errors = "none"
    elif errors in ("none", "model") and args.gnss_series_start_s is not None:
        raise UserError(f"--gnss-series-start-s goes with an error series or smartloc-sats, not "
                        f"--gnss-errors {errors}")
    velocity = velocity_option("0.2" if args.gnss_velocity is None else args.gnss_velocity)
    opts = GnssErrorOptions(errors, rate_hz=5.0 if args.gnss_rate_hz is None else args.gnss_rate_hz,
                            accuracy=args.gnss_accuracy or "reported",
                            latency_ms=args.gnss_latency_ms, base=args.gnss_base,
                            clearance_m=0.0 if args.gnss_clearance_m is None else args.gnss_clearance_m,
                            model_overrides=tuple(overrides), velocity_std_m_s=velocity,
                            seed=0 if args.seed is None else args.seed,
                            series_start_s=args.gnss_series_start_s)
    opts.check()
    return opts


def run(args: argparse.Namespace) -> int:
    from gcs_tools.outdir import check_out_dir

    if args.coupling == "tight":
        from companion.tight import check_weighting

        check_weighting(args.method)
    else:
        choices.method(args.method)
    sats = is_sats(args.gnss_errors)
    if args.no_odometry and not (args.smartloc is not None and args.coupling == "tight"):
        raise UserError("--no-odometry goes with --smartloc --coupling tight (only the tightly coupled "
                        "filter fuses the car's odometry)")
    if args.coupling == "tight" and args.gnss_errors is not None and not sats:
        raise UserError(f"--coupling tight --gnss-errors {args.gnss_errors}: these are fixes, and fixes "
                        "carry no satellites for the tightly coupled filter (use --gnss-errors "
                        "smartloc-sats:DRIVE_Input.txt, --ubx or --rinex-obs)")
    mission = choices.mission(args.mission) if args.mission is not None else None
    drive = _check_satellites(args, mission) if sats else None
    gnss_reader, gnss_note, navigator = (None, None, None) if sats else _raw_gnss(args, mission)
    if args.smartloc is not None:
        args.file = args.smartloc
    elif args.file is None:
        raise UserError("replay needs a log file (or --smartloc INPUT)")
    if not args.file.exists():
        raise UserError(f"{args.file}: no such file")
    if not (args.file.is_file() or args.file.is_dir()):  # /dev/null, a FIFO: a traceback further on
        raise UserError(f"{args.file}: not a regular file (a log) or a directory (an ANSFL flight)")
    gnss = gnss_options(args)
    check_out_dir(args.out)  # before the replay, not after it (created only once there are results)
    if not 0 <= args.rate_hz < math.inf:  # NaN, negative: not silently one row per IMU sample
        raise UserError(f"--rate-hz {args.rate_hz:g}: expected a rate >= 0 (0: one row per IMU sample)")
    if not 0 <= args.speed < math.inf:  # NaN, negative: not silently as fast as possible
        raise UserError(f"--speed {args.speed:g}: expected a factor >= 0 (0: as fast as possible)")
    if args.gps_delay_ms is not None and not (0 <= args.gps_delay_ms <= 2000):
        raise UserError(f"--gps-delay-ms {args.gps_delay_ms}: expected 0 to 2000 ms")
    home = parse_home(args.home) if args.home else None
    if mission is not None:
        home = home or mission.frame
    bar = None
    if not args.no_progress and sys.stderr.isatty():
        from tqdm import tqdm

        bar = tqdm(total=args.file.stat().st_size if args.file.is_file() else 0, unit="B",
                   unit_scale=True, desc=f"replay {args.method}", leave=False)
    progress = None if bar is None else (lambda pos, size: bar.update(pos - bar.n))
    placed = None
    if drive is not None:
        assert gnss is not None
        gnss_reader, gnss_note, navigator, placed = _satellites(args, drive, gnss)
        home, gnss = placed.frame, None
    pub = telemetry.publisher_from_args(args, "companion") if args.publish else None
    try:
        result = core.replay(args.file, args.method, home=home, mission=mission, rate_hz=args.rate_hz,
                             progress=progress, on_imu=_on_imu(pub, args.speed), out_dir=args.out,
                             gps_delay_ms=args.gps_delay_ms, reader=gnss_reader, gnss=gnss,
                             navigator=navigator)
    finally:
        if bar is not None:
            bar.close()
        if pub is not None:
            pub.close()
    if gnss_note:
        result.summary["raw_gnss"] = gnss_note
    if placed is not None:  # what --gnss-errors SERIES.csv reports, for the placed satellites' fixes
        result.summary["synthetic_gnss"] = placed.fixes.info
        result.summary["errors"]["raw_fixes"] = {"note": core.RAW_FIXES_NOTE, **placed.raw_errors}
    core.write_summary(result, args.out)
    figures = [] if args.no_figures else _figures(result, args)
    if args.no_figures:  # a previous run's figures in the same --out do not show this run's estimates
        for name in ("track.png", "errors.png"):
            (args.out / name).unlink(missing_ok=True)
    if args.json:
        print((args.out / "summary.json").read_text(encoding="utf-8"), end="")
        return 0
    print(report(result.summary, args.file.name))
    if gnss_note and "map" in gnss_note:  # the tight filter's map prior, stated either way
        print(f"  map: {gnss_note['map'] or 'none (no --mission: no line-of-sight prior)'}")
    record = [name for name in (gnss_record.FIX_FILE, gnss_record.EPOCH_FILE) if (args.out / name).is_file()]
    files = ["estimates.csv", *record, "summary.json", *(f.name for f in figures)]
    print(f"  wrote {args.out}/: {', '.join(files)}")  # as fly and sitl
    if pub is not None:
        c = pub.counters()
        print(f"  published {c['published']} telemetry messages as beliefnav/{args.vehicle_id}/companion/*")
    return 0


def _figures(result: core.ReplayResult, args: argparse.Namespace) -> list[Path]:
    """track.png and errors.png from the estimates the replay streamed to estimates.csv."""
    from gcs_tools.replay import figures

    t_s, table = figures.read_estimates(args.out / "estimates.csv")
    return figures.save(args.out, t_s, table, result.tracks, args.file.name, args.method, args.coupling,
                        figures.read_record(args.out))


def is_sats(errors: str | None) -> bool:
    from gcs_tools.gnss.transplant import PREFIX

    return errors is not None and errors.startswith(PREFIX)


def _check_satellites(args: argparse.Namespace, mission: Mission | None) -> Path:
    """``--gnss-errors smartloc-sats:INPUT``: the drive's input, the other options checked (one line)."""
    from gcs_tools.gnss.transplant import check_choice

    other = [name for name, value in (("--rinex-obs", args.rinex_obs), ("--rinex-nav", args.rinex_nav),
                                      ("--ubx", args.ubx), ("--smartloc", args.smartloc),
                                      ("--truth", args.truth)) if value]
    if other:
        raise UserError(f"--gnss-errors smartloc-sats and {other[0]}: both replace the log's GNSS; "
                        "choose one")
    if mission is not None or args.home is not None:
        raise UserError(f"--{'mission' if mission is not None else 'home'} with --gnss-errors smartloc-sats: "
                        "the flight is moved to the drive's first truth point (the satellites' sky), "
                        "where no mission's map or home applies")
    return check_choice(args.gnss_errors, "--gnss-errors")


def _satellites(args: argparse.Namespace, drive: Path, opts: GnssErrorOptions) -> tuple[Any, dict[str, Any],
                                                                                       Any, Any]:
    """The drive's satellites placed on the log's truth (``gcs_tools.gnss.transplant``, as the real-flight
    campaign's ``smartloc-sats`` condition): (reader, summary note, navigator factory, ``SkyOnFlight``).
    Loose: the single-point fixes into the loose estimator; tight: the raw epochs into the tightly coupled
    navigator (``TightConfig()``, no map), each arriving with its fix."""
    from gcs_tools.gnss import transplant
    from gcs_tools.replay.synthetic_gnss import WithSyntheticGnss

    sky = transplant.drive_sky(drive)
    placed = transplant.sky_on_flight(args.file, sky, opts, args.gps_delay_ms)
    log = transplant.on_drive_frame(args.file, args.gps_delay_ms, sky)
    note: dict[str, Any] = {"smartloc_sats": str(drive), "coupling": args.coupling,
                            "epochs": len(placed.placed.epochs),
                            "frame": "the drive's first truth point: the flight's truth moved there"}
    from gcs_tools.gnss.smartloc import rows_rejected

    reader: Any
    if args.coupling == "loose":
        reader, factory = WithSyntheticGnss(log, placed.fixes, placed.frame, placed.raw_errors), None
    else:
        from companion.tight import TightConfig
        from gcs_tools.gnss.tight_replay import tight_factory

        note["map"] = None
        reader, factory = transplant.placed_raw_reader(log, placed, sky.name), tight_factory(TightConfig())
    reader.stats.rejected.update(rows_rejected(dict(sky.rows_rejected)))  # the drive's skipped rows
    return reader, note, factory, placed


def _raw_gnss(args: argparse.Namespace, mission: Mission | None = None
              ) -> tuple[Any, dict[str, Any] | None, Any]:
    """The reader for --rinex-obs / --ubx / --smartloc (None: the log's own), a summary note and the
    navigator factory (None: the loose Navigator)."""
    if args.rinex_obs is None and args.smartloc is None and args.ubx is None:
        if args.rinex_nav or args.coupling != "loose" or args.truth is not None:
            raise UserError("--rinex-nav, --coupling and --truth go with --rinex-obs, --ubx or --smartloc")
        return None, None, None
    if args.truth is not None and args.smartloc is None:  # a flight log is scored against its own truth
        raise UserError("--truth goes with --smartloc (a log replayed with --rinex-obs or --ubx is scored "
                        "against its own truth)")
    if args.ubx is not None and args.coupling != "tight":
        raise UserError("--ubx goes with --coupling tight (loose coupling replays the log's own fixes: "
                        "those of the receiver)")
    from companion.gnss.spp import SppConfig
    from gcs_tools.gnss import replay as gnss_replay

    gnss_replay.check_coupling(args.coupling)
    if args.coupling == "tight":
        return _raw_gnss_tight(args, mission)
    config = SppConfig()
    if args.smartloc is not None:
        if args.file is not None or args.rinex_obs is not None:
            raise UserError("--smartloc replays the smartLoc drive alone: no log file, no --rinex-obs")
        if mission is not None:  # its estimator section is a quadrotor's and its map not Berlin's
            raise UserError("--mission: the smartLoc drive was not flown in a mission (no map of Berlin)")
        if not args.smartloc.is_file():
            raise UserError(f"{args.smartloc}: no such file")
        src = gnss_replay.smartloc_source(args.smartloc, args.truth, config)
        note = {"smartloc": str(args.smartloc), "coupling": args.coupling, "fixes": len(src.fixes),
                "imu": "none: zero acceleration, level attitude (a GNSS-only constant-velocity filter)"}
        return src, note, None
    if args.file is None or not args.file.is_file():
        raise UserError(f"--rinex-obs needs the flight log to replay ({args.file}: no such file)")
    if not args.rinex_nav:
        raise UserError("--rinex-obs needs --rinex-nav (broadcast ephemerides)")
    reader, note = gnss_replay.rinex_log_reader(args.file, args.rinex_obs, args.rinex_nav, config,
                                                args.gps_delay_ms)
    note["coupling"] = args.coupling
    return reader, note, None


def _raw_gnss_tight(args: argparse.Namespace, mission: Mission | None) -> tuple[Any, dict[str, Any], Any]:
    """--coupling tight: raw epochs (and smartLoc's odometry) into the tightly coupled navigator,
    assembled by ``companion.wiring.tight_navigator_for``: with ``mission`` (the log was flown in it) its
    map is the per-satellite belief's line-of-sight prior, else none (the summary says which)."""
    from companion.tight import TightConfig
    from gcs_tools.gnss import tight_replay

    if args.smartloc is not None:
        if args.file is not None or args.rinex_obs is not None or args.ubx is not None:
            raise UserError("--smartloc replays the smartLoc drive alone: no log file, --rinex-obs or --ubx")
        if mission is not None:
            raise UserError("--mission: the smartLoc drive was not flown in a mission (no map of Berlin)")
        if not args.smartloc.is_file():
            raise UserError(f"{args.smartloc}: no such file")
        src = tight_replay.smartloc_raw_source(args.smartloc, args.truth, not args.no_odometry)
        note = {"smartloc": str(args.smartloc), "coupling": "tight", "epochs": len(src.epochs),
                "odometry": not args.no_odometry,
                "motion": "constant velocity (no IMU)"
                + ("" if args.no_odometry else " with wheel speed and yaw rate")}
        note["map"] = None
        return src, note, tight_replay.tight_factory(TightConfig.for_ground_vehicle())
    option = "--ubx" if args.ubx is not None else "--rinex-obs"
    if args.file is None or not args.file.is_file():
        raise UserError(f"{option} needs the flight log to replay ({args.file}: no such file)")
    if args.ubx is not None:
        if args.rinex_obs is not None or args.rinex_nav:
            raise UserError("--ubx or --rinex-obs/--rinex-nav: one raw GNSS source")
        reader, store, note = tight_replay.ubx_raw_log_reader(args.file, args.ubx, args.gps_delay_ms)
    else:
        if not args.rinex_nav:
            raise UserError("--rinex-obs needs --rinex-nav (broadcast ephemerides)")
        reader, store, note = tight_replay.rinex_raw_log_reader(args.file, args.rinex_obs, args.rinex_nav,
                                                                 args.gps_delay_ms)
    note["coupling"] = "tight"
    note["map"] = (f"mission {mission.name}: its buildings' line of sight as the belief's prior"
                   if mission is not None else None)
    return reader, note, tight_replay.tight_factory(TightConfig(), store, mission)


def counts_text(counts: dict[str, Any], none: str = "none") -> str:
    """``{'no_attitude': 1, 'time_backwards': 0}`` as ``no attitude 1`` (zeros left out; nested
    mappings flattened): counters a reader takes in at a glance."""
    flat: dict[str, int] = {}

    def walk(d: dict[str, Any]) -> None:
        for k, v in d.items():
            if isinstance(v, dict):
                walk(v)
            elif v:
                flat[k] = flat.get(k, 0) + int(v)

    walk(counts)
    return ", ".join(f"{k.replace('_', ' ')} {n:,}" for k, n in flat.items()) or none


def report(s: dict[str, Any], name: str) -> str:
    """The printed summary: the navigator's own counters (summed over log restarts)."""
    nav = s["navigator"]
    imu_rejected = {k.removeprefix("imu_rejected_"): v for k, v in nav.items()
                    if k.startswith("imu_rejected_")}
    gnss_rejected = {k.removeprefix("gnss_rejected_"): v for k, v in nav.items()
                     if k.startswith("gnss_rejected_")}
    n_imu_rej, n_gnss_rej = sum(imu_rejected.values()), sum(gnss_rejected.values())
    used = s["samples_used"]
    refused = dict(s["samples_rejected"])
    skipped_bytes = refused.pop("reader_skipped_bytes", 0)
    beta = s["beta"]
    lines = [
        f"replayed {s['duration_s']:.1f} s of {name} ({s['format']}) with {s['method']} "
        f"in {s['wall_s']:.2f} s "
        f"({s['realtime_factor']:.0f}x real time)"
        + (f"; {s['log_restarts']} log restart(s): {len(s['segments'])} segments"
           if s["log_restarts"] else ""),
        f"  read {used.get('imu', 0):,} IMU, {used.get('attitude', 0):,} attitude and "
        f"{used.get('gnss', 0):,} GNSS samples"
        + (f" (the log's {used['gnss_log_fix_replaced']:,} fixes replaced)"
           if used.get("gnss_log_fix_replaced") else "")
        + f"; refused while reading: {counts_text(refused)}"
        + (f" ({skipped_bytes:,} bytes skipped)" if skipped_bytes else ""),
        f"  IMU samples used {nav.get('imu_used', 0):,}, rejected {n_imu_rej:,}"
        + (f" ({counts_text(imu_rejected)})" if n_imu_rej else "")
        + f"; GNSS fixes fused {nav.get('gnss_fused', 0):,}, rejected {n_gnss_rej:,}"
        + (f" ({counts_text(gnss_rejected)})" if n_gnss_rej else ""),
        f"  belief β median {beta.get('median', float('nan')):.3f}, min {beta.get('min', float('nan')):.3f}",
    ]
    labels = (("gnss", "GNSS"), ("autopilot_estimate", "the autopilot's estimate"), ("truth", "truth"))
    for key, label in labels:
        e = s["errors"].get(key)
        if e and e["n"]:
            h = e["error_horizontal_m"]
            lines.append(f"  horizontal distance to {label} ({e['source']}, {e['alignment']}) median "
                         f"{h['median']:.2f} m p95 {h['p95']:.2f} m max {h['max']:.2f} m")
    raw = s["errors"].get("raw_fixes")
    if raw:
        for when in ("at_validity", "at_arrival"):
            h = raw[when]["error_horizontal_m"]
            lines.append(f"  the raw fixes' own horizontal error ({raw['reference']}, "
                         f"{when.replace('_', ' ')}) "
                         f"median {h['median']:.2f} m p95 {h['p95']:.2f} m max {h['max']:.2f} m")
    clock = s.get("clock_alignment")
    if clock:
        lines.append(f"  clock: IMU = truth + {clock['offset_s']:.3f} s (fit residual "
                     f"{clock['residual_rms_m_s2']:.2f} "
                     f"m/s² of {clock['signal_rms_m_s2']:.2f}); IMU heading vs the truth track "
                     f"{-clock['yaw_deg']:+.1f}°")
    return "\n".join(lines)


def _on_imu(pub: telemetry.TelemetryPublisher | None, speed: float) -> core.ImuHook | None:
    """Publish the estimator's topics at their rates and/or pace to ``speed`` x real time."""
    tap = telemetry.EstimatorTelemetry(pub) if pub is not None else None
    if tap is None and speed <= 0:
        return None
    start: list[float] = []  # (wall s, boot s) of the first IMU sample

    def hook(t_us: int, nav: core.NavigatorLike) -> None:
        if speed > 0:
            if not start:
                start.extend((time.monotonic(), t_us * 1e-6))
            lag_s = start[0] + (t_us * 1e-6 - start[1]) / speed - time.monotonic()
            if lag_s > 0.002:
                time.sleep(lag_s)
        if tap is not None:
            tap.update(t_us, nav)

    return hook
