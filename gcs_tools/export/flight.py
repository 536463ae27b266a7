"""One flight as a table, whatever it came from: a run directory, a replay's output, a tlog or a
Zenoh recording.

Columns are those of ``timeseries.csv`` (``gcs_tools.fly.output.COLUMNS``: unit in every name)
plus the GNSS fix (the last one received at or before each row) and the autopilot's own estimate in
the same local NED frame. A column the source does not have is NaN. Besides the table a flight has
every GNSS fix (geodetic, with its validity time and the gate's verdict when known), its local
frame and where that came from, the wall clock of its time base, the attitude of each track
that has one, the buildings, and a metadata record (mission, method, seed, versions).

Times ``t_s`` are the source's own clock: simulated time for ``fly``/``sitl``, the log's boot
time for a replay or a tlog, the estimate's time for a recording; ``epoch_unix_s`` is the UNIX time
of ``t_s = 0`` when the source tells it (``None``: unknown, the export then says so).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from companion.domain.geodesy import LocalNedFrame
from companion.errors import UserError
from gcs_tools.fly.output import COLUMNS as FLY_COLUMNS
from gcs_tools.fly.output import GNSS_FILE, OPTIONAL_COLUMNS

# position tracks: label -> column prefix (columns <prefix>_n_m, _e_m, _d_m)
TRACKS = {"true": "p_true", "estimated": "p_est", "reference": "p_ref", "gnss": "p_gnss",
          "autopilot": "p_autopilot"}
AXES = ("n", "e", "d")
QUATERNION = ("w", "x", "y", "z")
# what a timeseries.csv may hold, then the GNSS track (every source) and the autopilot's (logs)
TIMESERIES = (*[c for cols in FLY_COLUMNS.values() for c in cols],
              *[c for cols in OPTIONAL_COLUMNS.values() for c in cols])
COLUMNS = (*TIMESERIES, *[f"{TRACKS[k]}_{a}_m" for k in ("gnss", "autopilot") for a in AXES
                          if f"{TRACKS[k]}_{a}_m" not in TIMESERIES])
# scalar columns exported as plottable state (everything that is not a position track or attitude)
SCALARS = tuple(c for c in COLUMNS if not c.startswith(tuple(p + "_" for p in (*TRACKS.values(), "q_true"))))
MAX_HOME_DISTANCE_M = 50_000.0  # a --home farther than this from the flight is refused (the wire limit)
HOME_MISMATCH_M = 1.0  # a --home farther than this from the log's own origin is warned about


@dataclass(frozen=True)
class Fix:
    t_s: float  # arrival at the filter (the flight's clock); the validity time when unknown
    t_validity_s: float  # when the position was true (NaN: unknown)
    lat_deg: float
    lon_deg: float
    alt_m: float  # AMSL
    h_acc_m: float  # 1-sigma, NaN when not reported
    rejected: float = math.nan  # 1: refused by the filter's innovation gate, 0: not, NaN: not known


@dataclass
class Flight:
    """Rows at the estimate's (or the log's) time stamps; every column a float array of one length."""

    name: str
    t_s: np.ndarray
    columns: dict[str, np.ndarray]
    fixes: list[Fix] = field(default_factory=list)
    frame: LocalNedFrame | None = None
    source: str = ""
    kind: str = ""  # run directory, replay, tlog, recording
    home_source: str = ""  # where the frame came from (said in the metadata)
    epoch_unix_s: float | None = None  # UNIX time of t_s = 0 (None: not known)
    clock: str = ""  # what t_s is and how the wall clock was found
    attitude: dict[str, np.ndarray] = field(default_factory=dict)  # track -> (N, 4) q_ned_frd (NaN: none)
    buildings: list[tuple[float, float, float, float, float]] = field(default_factory=list)  # n0 e0 n1 e1 h
    info: dict[str, Any] = field(default_factory=dict)  # mission, profile, method, seed, scenario, versions
    warnings: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        n = len(self.t_s)
        for c in COLUMNS:
            self.columns.setdefault(c, np.full(n, np.nan))
        self.columns["t_s"] = np.asarray(self.t_s, dtype=float)
        bad = [c for c, v in self.columns.items() if len(v) != n]
        if bad:
            raise ValueError(f"column {bad[0]} has {len(self.columns[bad[0]])} rows, not {n}")

    def track(self, label: str) -> np.ndarray:
        """(N, 3) NED positions of one track [m]."""
        prefix = TRACKS[label]
        return np.column_stack([self.columns[f"{prefix}_{a}_m"] for a in AXES])

    def has(self, column: str) -> bool:
        return bool(np.isfinite(self.columns[column]).any())

    def fixes_ned_m(self) -> np.ndarray:
        """(K, 3) the fixes in the flight's frame (NaN without a frame)."""
        if self.frame is None or not self.fixes:
            return np.full((len(self.fixes), 3), np.nan)
        lla = np.array([(f.lat_deg, f.lon_deg, f.alt_m) for f in self.fixes])
        return np.asarray(self.frame.to_ned_m(lla[:, 0], lla[:, 1], lla[:, 2]), dtype=float).T.reshape(-1, 3)

    def set_fix_columns(self) -> None:
        """``p_gnss_*``: the last fix received at or before each row (held, never interpolated)."""
        if not self.fixes or self.frame is None:
            return
        t_fix = np.array([f.t_s for f in self.fixes])
        order = np.argsort(t_fix, kind="stable")
        ned = self.fixes_ned_m()[order]
        idx = np.searchsorted(t_fix[order], self.t_s, side="right") - 1
        held = np.where((idx >= 0)[:, None], ned[np.clip(idx, 0, None)], np.nan)
        set_track(self.columns, "gnss", held)

    def write_csv(self, path: Path) -> None:
        """The table with a header row and ``t_unix_s`` (the wall clock, empty when unknown); NaN
        written as an empty cell (numpy, pandas and Excel read it)."""
        epoch = math.nan if self.epoch_unix_s is None else self.epoch_unix_s
        names = (*COLUMNS, "t_unix_s")
        table = np.column_stack([*(self.columns[c] for c in COLUMNS), self.t_s + epoch])
        with path.open("w", encoding="utf-8") as f:
            f.write(",".join(names) + "\n")
            for row in table:
                f.write(",".join("" if not math.isfinite(x) else f"{x:.10g}" for x in row[:-1]))
                f.write("," + ("" if not math.isfinite(row[-1]) else f"{row[-1]:.6f}") + "\n")


def ned_to_lla(frame: LocalNedFrame, p_ned_m: np.ndarray) -> np.ndarray:
    """(N, 3) NED positions about ``frame`` as (N, 3) latitude, longitude [deg], altitude AMSL [m]."""
    import pymap3d

    p = np.asarray(p_ned_m, dtype=float).reshape(-1, 3)
    lat, lon, alt = pymap3d.ned2geodetic(p[:, 0], p[:, 1], p[:, 2], frame.home_lat_deg, frame.home_lon_deg,
                                         frame.home_alt_m)
    return np.column_stack([lat, lon, alt]).reshape(-1, 3)


def reframe(p_ned_m: np.ndarray, src: LocalNedFrame, dst: LocalNedFrame) -> np.ndarray:
    """(N, 3) positions about ``src`` as positions about ``dst`` (through WGS-84)."""
    if src == dst:
        return np.asarray(p_ned_m, dtype=float)
    lla = ned_to_lla(src, p_ned_m)
    return np.asarray(dst.to_ned_m(lla[:, 0], lla[:, 1], lla[:, 2]), dtype=float).T.reshape(-1, 3)


def set_track(columns: dict[str, np.ndarray], label: str, p_ned_m: np.ndarray) -> None:
    for i, a in enumerate(AXES):
        columns[f"{TRACKS[label]}_{a}_m"] = np.asarray(p_ned_m, dtype=float)[:, i]


def interp(t_s: np.ndarray, t_src_s: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Linear interpolation of (M, k) values onto t_s; NaN outside the source's span."""
    values = np.asarray(values, dtype=float).reshape(len(t_src_s), -1)
    if len(t_src_s) == 0:
        return np.full((len(t_s), values.shape[1]), np.nan)
    return np.column_stack([np.interp(t_s, t_src_s, values[:, i], left=np.nan, right=np.nan)
                            for i in range(values.shape[1])])


def nearest(t_s: np.ndarray, t_src_s: np.ndarray, values: np.ndarray, max_gap_s: float) -> np.ndarray:
    """The source row nearest in time to each of ``t_s`` (quaternions are not interpolated
    componentwise); NaN farther than ``max_gap_s``."""
    values = np.asarray(values, dtype=float).reshape(len(t_src_s), -1)
    out = np.full((len(t_s), values.shape[1]), np.nan)
    if len(t_src_s) == 0:
        return out
    i = np.clip(np.searchsorted(t_src_s, t_s), 1, max(len(t_src_s) - 1, 1))
    j = np.where(np.abs(t_src_s[i - 1] - t_s) <= np.abs(t_src_s[np.minimum(i, len(t_src_s) - 1)] - t_s),
                 i - 1, np.minimum(i, len(t_src_s) - 1))
    ok = np.abs(t_src_s[j] - t_s) <= max_gap_s
    out[ok] = values[j[ok]]
    return out


# --- home ---------------------------------------------------------------------------------------------


def choose_home(given: LocalNedFrame | None, own: LocalNedFrame | None, own_source: str,
                near_lla: tuple[float, float, float] | None,
                warnings: list[str]) -> tuple[LocalNedFrame | None, str]:
    """The frame to export in: ``--home`` (checked against the flight) or the source's own.

    A ``--home`` farther than ``MAX_HOME_DISTANCE_M`` from the flight (``near_lla``: its first fix
    or origin) is refused (one line); one that differs from the source's own origin by more than
    ``HOME_MISMATCH_M`` is used with a warning naming the distance."""
    if given is None:
        return own, own_source
    ref = near_lla if near_lla is not None else (
        (own.home_lat_deg, own.home_lon_deg, own.home_alt_m) if own is not None else None)
    if ref is not None:
        d_m = float(np.linalg.norm(given.to_ned_m(*ref)))
        if not d_m <= MAX_HOME_DISTANCE_M:
            raise UserError(f"--home {given.home_lat_deg:g},{given.home_lon_deg:g},{given.home_alt_m:g}: "
                            f"{d_m / 1000:.0f} km from the flight (at {ref[0]:.6f},{ref[1]:.6f}): "
                            "not this flight's home (leave --home out to use the log's)")
    if own is not None:
        d_m = float(np.linalg.norm(given.to_ned_m(own.home_lat_deg, own.home_lon_deg, own.home_alt_m)))
        if d_m > HOME_MISMATCH_M:
            warnings.append(f"--home is {d_m:.1f} m from the flight's own origin ({own_source}: "
                            f"{own.home_lat_deg:.7f},{own.home_lon_deg:.7f},{own.home_alt_m:.2f}); "
                            "positions are exported about --home")
    return given, "--home"


# --- sources ----------------------------------------------------------------------------------------


def load_flight(path: Path, vehicle: str | None = None, home: LocalNedFrame | None = None) -> Flight:
    """A run directory (``timeseries.csv`` of fly/sitl, or ``estimates.csv`` of replay), a ``.tlog``
    or a ``.jsonl`` recording; ``home``: ``--home`` (checked against the flight)."""
    from gcs_tools.export import tlog_flight

    if path.is_dir() and not (path / "timeseries.csv").is_file() and (path / "estimates.csv").is_file():
        return from_replay_dir(path, home)
    if path.is_dir():
        return from_run_dir(path, home)
    if not path.is_file():
        raise UserError(f"{path}: no such file or directory (give a run directory, a .tlog or a .jsonl)")
    if path.suffix == ".tlog":
        return tlog_flight.from_tlog(path, home)
    if path.suffix == ".jsonl":
        return from_recording(path, vehicle, home)
    raise UserError(f"{path}: unknown kind of input {path.suffix!r} (valid: a run directory, .tlog, .jsonl)")


def read_summary(run: Path) -> dict[str, Any]:
    summary = run / "summary.json"
    if not summary.is_file():
        return {}
    try:
        data = json.loads(summary.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise UserError(f"{summary}: not readable JSON: {exc}") from None
    return data if isinstance(data, dict) else {}


def run_mission(summary: dict[str, Any]) -> Any:
    """The mission a run flew: the name or file it was given (``mission_source``) when it still
    loads, else a packaged mission of the same name; None when neither is found."""
    from companion.mission import load_mission
    from companion.mission.loader import BUILTIN_MISSIONS

    given = summary.get("mission_source")
    if isinstance(given, str) and (given in BUILTIN_MISSIONS or Path(given).is_file()):
        try:
            return load_mission(given)
        except UserError:
            pass
    for key in BUILTIN_MISSIONS:
        m = load_mission(key)
        if m.name == summary.get("mission"):
            return m
    return None


def mission_buildings(mission: Any) -> list[tuple[float, float, float, float, float]]:
    return [(b.north_min_m, b.east_min_m, b.north_max_m, b.east_max_m, b.height_m)
            for b in mission.world.config.buildings]


def run_info(summary: dict[str, Any]) -> dict[str, Any]:
    """What a run says about itself: mission, profile, method, seed, scenario, version."""
    keys = ("mission", "mission_source", "profile", "method", "seed", "scenario", "beliefnav_version")
    return {k: summary[k] for k in keys if summary.get(k) is not None}


def from_run_dir(run: Path, home: LocalNedFrame | None = None) -> Flight:
    """``timeseries.csv`` of ``fly``/``sitl``, the fixes of ``gnss.csv`` (else of ``run.tlog``), the
    mission of ``summary.json`` (frame, buildings) and its start time (else ``run.tlog``'s clock)."""
    from gcs_tools.export import tlog_flight

    csv = run / "timeseries.csv"
    if not csv.is_file():
        raise UserError(f"{run}: not a run directory (no timeseries.csv; `beliefnav fly` or `sitl` "
                        "writes one)")
    with csv.open(encoding="utf-8") as f:
        header = f.readline().strip().split(",")
    unknown = sorted(set(header) - set(COLUMNS))
    if unknown or "t_s" not in header:
        raise UserError(f"{csv}: unexpected column {(unknown or ['(no t_s)'])[0]!r}")
    try:
        table = np.loadtxt(csv, delimiter=",", skiprows=1, ndmin=2)
    except ValueError as exc:
        raise UserError(f"{csv}: not a numeric table: {exc}") from None
    columns = {c: table[:, i] for i, c in enumerate(header)}
    s = read_summary(run)
    mission = run_mission(s) if s else None
    name = (f"{s.get('mission', '?')} profile {s.get('profile', '?')}, {s.get('method', '?')}" if s
            else run.name)
    warnings: list[str] = []
    if s and mission is None:
        warnings.append(f"the run's mission {s.get('mission')!r} was not found: no map coordinates, "
                        "no buildings")
    own = mission.frame if mission is not None else None
    tlog = run / "run.tlog"
    fixes = _run_dir_fixes(run, own)
    if not fixes and tlog.is_file() and own is not None:
        fixes = tlog_flight.read_fixes(tlog, tlog_flight.tlog_epoch(tlog))
    near = (fixes[0].lat_deg, fixes[0].lon_deg, fixes[0].alt_m) if fixes else None
    frame, home_source = choose_home(home, own, f"the mission {s.get('mission')!r}" if own else "", near,
                                     warnings)
    if frame is not None and own is not None and frame != own:
        for label in ("true", "estimated", "reference", "autopilot"):  # the table is about the mission's home
            if f"{TRACKS[label]}_n_m" in columns:
                p = np.column_stack([columns[f"{TRACKS[label]}_{a}_m"] for a in AXES])
                set_track(columns, label, reframe(p, own, frame))
    start = s.get("start_unix_s")
    epoch, clock = (float(start), "simulated time; the wall clock of the run's start (summary.json)") \
        if isinstance(start, (int, float)) else (None, "simulated time (the run did not record its start)")
    if epoch is None and tlog.is_file():
        epoch = tlog_flight.tlog_epoch(tlog)
        if epoch is not None:
            clock = "simulated time; the wall clock of run.tlog's SYSTEM_TIME"
    attitude: dict[str, np.ndarray] = {}
    if "q_true_w" in columns:
        q = np.column_stack([columns[f"q_true_{c}"] for c in QUATERNION])
        attitude = {"true": q, "estimated": q}  # the companion flies on the vehicle's attitude
    flight = Flight(name, columns["t_s"], columns, fixes=fixes, frame=frame, source=str(run),
                    kind="run directory", home_source=home_source, epoch_unix_s=epoch, clock=clock,
                    attitude=attitude, buildings=mission_buildings(mission) if mission is not None else [],
                    info=run_info(s), warnings=warnings)
    flight.set_fix_columns()
    return flight


def _run_dir_fixes(run: Path, frame: LocalNedFrame | None) -> list[Fix]:
    """``gnss.csv`` (NED in the mission frame) as geodetic fixes; [] without it or a frame."""
    path = run / GNSS_FILE
    if frame is None or not path.is_file():
        return []
    t = np.genfromtxt(path, delimiter=",", names=True, ndmin=1)
    names = t.dtype.names or ()
    if not {"t_s", "t_validity_s", "p_n_m", "p_e_m", "p_d_m"} <= set(names):
        raise UserError(f"{path}: not a gnss.csv (needs t_s, t_validity_s, p_n_m, p_e_m, p_d_m)")
    lla = ned_to_lla(frame, np.column_stack([t["p_n_m"], t["p_e_m"], t["p_d_m"]]))
    h_acc = t["h_acc_m"] if "h_acc_m" in names else np.full(len(t), np.nan)
    rej = t["rejected"] if "rejected" in names else np.full(len(t), np.nan)
    return [Fix(float(t["t_s"][i]), float(t["t_validity_s"][i]), float(lla[i, 0]), float(lla[i, 1]),
                float(lla[i, 2]), float(h_acc[i]), float(rej[i])) for i in range(len(t))]


REPLAY_TRACKS = {"estimated": ("p_n_m", "p_e_m", "p_d_m")}
REPLAY_COLUMNS = {"b_n_m": "b_est_n_m", "b_e_m": "b_est_e_m", "b_d_m": "b_est_d_m", "beta": "beta",
                  "nis": "nis"}


def from_replay_dir(run: Path, home: LocalNedFrame | None = None) -> Flight:
    """``beliefnav replay`` output: ``estimates.csv`` (the log's boot time) and, from the log named
    in ``summary.json`` when it is still there, every GNSS fix and the attitude the estimator was
    given (the same clock) and the log's wall clock."""
    from gcs_tools.export import tlog_flight

    csv = run / "estimates.csv"
    table = np.genfromtxt(csv, delimiter=",", names=True, ndmin=1)
    names = table.dtype.names or ()
    need = ["t_s", *REPLAY_TRACKS["estimated"], *REPLAY_COLUMNS]
    if any(n not in names for n in need):
        raise UserError(f"{csv}: not a replay table (needs columns {', '.join(need)})")
    t_s = np.asarray(table["t_s"], dtype=float)
    columns = {new: np.asarray(table[old], dtype=float) for old, new in REPLAY_COLUMNS.items()}
    s = read_summary(run)
    h = s.get("home") or {}
    own = (LocalNedFrame(h["lat_deg"], h["lon_deg"], h["alt_m"])
           if {"lat_deg", "lon_deg", "alt_m"} <= set(h) else None)
    log = Path(str(s.get("file", "")))
    warnings: list[str] = []
    fixes: list[Fix] = []
    attitude: dict[str, np.ndarray] = {}
    epoch, clock = None, "the log's boot time (no wall clock found)"
    # the estimator's fixes were not the log's own (--gnss-errors, RINEX, UBX, smartLoc): those the log
    # holds would be exported as if they were (the replay's own are in its gnss_fixes.csv)
    replaced = "synthetic_gnss" in s or "raw_gnss" in s
    if s.get("format") == "smartloc":  # the drive's pseudoranges: no log to read fixes or attitude from
        warnings.append("a smartLoc replay: no log fixes or attitude to export")
    elif log.is_dir():
        warnings.append(f"the replayed log {log} is an ANSFL flight (no GNSS of its own): no fixes, "
                        "no attitude")
    elif log.is_file():
        fixes, att_t_s, att_q = _log_samples(log)
        if replaced:
            fixes = []
            warnings.append("the replay's GNSS was not the log's own (--gnss-errors or raw GNSS): the "
                            "log's attitude, no fixes")
        if len(att_t_s):
            q = nearest(t_s, att_t_s, att_q, max_gap_s=0.2)
            attitude = {"estimated": q}
        if log.suffix == ".tlog":
            epoch = tlog_flight.tlog_epoch(log)
            if epoch is not None:
                clock = "the log's boot time; the wall clock of its SYSTEM_TIME"
    elif s.get("file"):
        warnings.append(f"the replayed log {log} is not there any more (or not from this directory: "
                        "summary.json names it as given): no fixes, no attitude")
    near = (fixes[0].lat_deg, fixes[0].lon_deg, fixes[0].alt_m) if fixes else None
    frame, home_source = choose_home(home, own, "the replay's home", near, warnings)
    p = np.column_stack([table[n] for n in REPLAY_TRACKS["estimated"]])
    if frame is not None and own is not None:
        p = reframe(p, own, frame)
    set_track(columns, "estimated", p)
    name = f"{run.name} ({s.get('method', '?')} on {log.name or '?'})"
    info = {"method": s.get("method"), "log": str(log), "log_format": s.get("format")}
    flight = Flight(name, t_s, columns, fixes=fixes, frame=frame, source=str(run), kind="replay",
                    home_source=home_source, epoch_unix_s=epoch, clock=clock, attitude=attitude,
                    info={k: v for k, v in info.items() if v}, warnings=warnings)
    flight.set_fix_columns()
    return flight


def _log_samples(log: Path) -> tuple[list[Fix], np.ndarray, np.ndarray]:
    """Every fix (3-D or better; validity-stamped) and attitude sample of a log, by the replay's readers."""
    from companion.domain.samples import AttitudeSample, GnssFix
    from gcs_tools.replay.logs import open_log

    fixes: list[Fix] = []
    att_t: list[float] = []
    att_q: list[np.ndarray] = []
    for sample in open_log(log):
        if isinstance(sample, GnssFix) and sample.fix_type >= 3:
            t = sample.t_validity_us * 1e-6
            fixes.append(Fix(t, t, sample.lat_deg, sample.lon_deg, sample.alt_m, sample.h_acc_m))
        elif isinstance(sample, AttitudeSample):
            att_t.append(sample.t_us * 1e-6)
            att_q.append(sample.q_ned_frd)
    order = np.argsort(att_t, kind="stable")
    return fixes, np.asarray(att_t)[order], np.asarray(att_q).reshape(-1, 4)[order]


def from_recording(path: Path, vehicle: str | None, home: LocalNedFrame | None = None) -> Flight:
    """A ``beliefnav record`` file: the vehicle's estimates, truth, setpoints and fixes; the frame of
    its route's ``home_lla`` (else of the packaged mission the route names, else the first fix's
    position, with a warning); the wall clock from the publishers' stamps."""
    from gcs_tools.recorder.recording import iter_lines, read_recording, recorded_vehicle, series

    rec = read_recording(path)
    vehicle = rec.vehicles[0] if vehicle is None else recorded_vehicle(rec, vehicle, path)
    s = series(rec, vehicle)
    columns: dict[str, np.ndarray] = {}
    for key, cols in FLY_COLUMNS.items():
        values = np.asarray(s[key], dtype=float).reshape(len(s["t_s"]), -1)
        for i, c in enumerate(cols):
            columns[c] = values[:, i]
    by = rec.messages[vehicle]
    gnss = sorted(by.get("gnss", []), key=lambda g: g.t_us)
    fixes = [Fix(g.t_us * 1e-6, g.fix.t_validity_us * 1e-6, g.fix.lat_deg, g.fix.lon_deg, g.fix.alt_m,
                 g.fix.h_acc_m) for g in gnss if g.fix.fix_type >= 3]
    routes = by.get("route", [])
    warnings: list[str] = []
    own, own_source, buildings, info = None, "", [], {"vehicle": vehicle}
    if routes:
        r = routes[-1]
        if r.mission:  # (a companion beside an autopilot flies no mission: its route is only its home)
            info |= {"mission": r.mission, "profile": r.profile}
        if np.isfinite(r.home_lla).all():  # the frame the publisher's positions are about
            own, own_source = LocalNedFrame(*(float(x) for x in r.home_lla)), "the route's home"
        else:
            mission = run_mission({"mission": r.mission})
            if mission is not None:
                own, own_source = mission.frame, f"the mission {r.mission!r}"
        buildings = [(float(b[0]), float(b[1]), float(b[2]), float(b[3]), math.nan) for b in r.buildings_ne_m]
    if own is None and fixes and home is None:
        f0 = fixes[0]
        own, own_source = LocalNedFrame(f0.lat_deg, f0.lon_deg, f0.alt_m), "the first fix"
        warnings.append("the recording has no route with a home and names no known mission: the local frame "
                        "is about its first fix, so truth and estimate may be offset from the fixes")
    near = (fixes[0].lat_deg, fixes[0].lon_deg, fixes[0].alt_m) if fixes else None
    frame, home_source = choose_home(home, own, own_source, near, warnings)
    truth = sorted(by.get("truth", []), key=lambda o: o.t_us)
    attitude: dict[str, np.ndarray] = {}
    if truth:
        q = nearest(s["t_s"], np.array([o.t_us for o in truth]) * 1e-6,
                    np.array([o.q_ned_frd for o in truth]), max_gap_s=0.1)
        attitude = {"true": q, "estimated": q}
    est = by.get("estimate", [])
    if est:
        info["method"] = est[-1].method
    epoch = _recording_epoch(iter_lines(path), vehicle)
    flight = Flight(f"{path.stem} {vehicle}", s["t_s"], columns, fixes=fixes, frame=frame, source=str(path),
                    kind="recording", home_source=home_source, epoch_unix_s=epoch,
                    clock=("the vehicle's boot time; the wall clock of the publishers' stamps"
                           if epoch is not None else "the vehicle's boot time (no wall clock found)"),
                    attitude=attitude,
                    buildings=buildings, info=info, warnings=warnings)
    flight.set_fix_columns()
    return flight


def _recording_epoch(lines: Any, vehicle: str) -> float | None:
    """UNIX time of boot time 0: the median of (publisher's ``sent_unix_ns`` - ``t_us``) over the
    vehicle's estimates (a publisher stamps as it sends, microseconds after the estimate)."""
    offsets = []
    prefix = f"beliefnav/{vehicle}/companion/estimate"
    for _, d in lines:
        if d is None or d.get("key") != prefix:
            continue
        p = d.get("payload")
        sent, t_us = (p.get("sent_unix_ns"), p.get("t_us")) if isinstance(p, dict) else (None, None)
        if isinstance(sent, int) and isinstance(t_us, int) and sent > 0:
            offsets.append(sent * 1e-9 - t_us * 1e-6)
    return float(np.median(offsets)) if offsets else None
