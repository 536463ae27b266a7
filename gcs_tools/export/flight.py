"""One flight as a table, whatever it came from: a run directory, a tlog or a Zenoh recording.

Columns are those of ``timeseries.csv`` (``gcs_tools.fly.output.COLUMNS``: unit in every name)
plus, for logs, the GNSS fix and the autopilot's own estimate in the same local NED frame. A column
the source does not have is NaN. Fixes keep their geodetic coordinates for map views.
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

# position tracks: label -> column prefix (columns <prefix>_n_m, _e_m, _d_m)
TRACKS = {"true": "p_true", "estimated": "p_est", "reference": "p_ref", "gnss": "p_gnss",
          "autopilot": "p_ap"}
AXES = ("n", "e", "d")
COLUMNS = (*[c for cols in FLY_COLUMNS.values() for c in cols],
           *[f"{TRACKS[k]}_{a}_m" for k in ("gnss", "autopilot") for a in AXES])
# scalar columns exported as plottable state (everything that is not a position track)
SCALARS = tuple(c for c in COLUMNS if not any(c.startswith(p + "_") for p in TRACKS.values()))


@dataclass(frozen=True)
class Fix:
    t_s: float  # arrival (release) time, s of boot time
    lat_deg: float
    lon_deg: float
    alt_m: float  # AMSL
    h_acc_m: float  # 1-sigma, NaN when not reported


@dataclass
class Flight:
    """Rows at the estimate's (or the log's) time stamps; every column a float array of one length."""

    name: str
    t_s: np.ndarray
    columns: dict[str, np.ndarray]
    fixes: list[Fix] = field(default_factory=list)
    frame: LocalNedFrame | None = None
    source: str = ""

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

    def write_csv(self, path: Path) -> None:
        """The table with a header row; NaN written as an empty cell (numpy, pandas and Excel read it)."""
        table = np.column_stack([self.columns[c] for c in COLUMNS])
        with path.open("w", encoding="utf-8") as f:
            f.write(",".join(COLUMNS) + "\n")
            for row in table:
                f.write(",".join("" if not math.isfinite(x) else f"{x:.10g}" for x in row) + "\n")


def _set_track(columns: dict[str, np.ndarray], label: str, p_ned_m: np.ndarray) -> None:
    for i, a in enumerate(AXES):
        columns[f"{TRACKS[label]}_{a}_m"] = np.asarray(p_ned_m, dtype=float)[:, i]


def _interp(t_s: np.ndarray, t_src_s: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Linear interpolation of (M, k) values onto t_s; NaN outside the source's span."""
    values = np.asarray(values, dtype=float).reshape(len(t_src_s), -1)
    if len(t_src_s) == 0:
        return np.full((len(t_s), values.shape[1]), np.nan)
    return np.column_stack([np.interp(t_s, t_src_s, values[:, i], left=np.nan, right=np.nan)
                            for i in range(values.shape[1])])


# --- sources ----------------------------------------------------------------------------------------


def load_flight(path: Path, vehicle: str | None = None, home: LocalNedFrame | None = None) -> Flight:
    """A run directory (``timeseries.csv`` of fly/sitl, or ``estimates.csv`` of replay), a ``.tlog``
    or a ``.jsonl`` recording."""
    if path.is_dir() and not (path / "timeseries.csv").is_file() and (path / "estimates.csv").is_file():
        return from_replay_dir(path)
    if path.is_dir():
        return from_run_dir(path)
    if not path.is_file():
        raise UserError(f"{path}: no such file or directory (give a run directory, a .tlog or a .jsonl)")
    if path.suffix == ".tlog":
        return from_tlog(path, home)
    if path.suffix == ".jsonl":
        return from_recording(path, vehicle)
    raise UserError(f"{path}: unknown kind of input {path.suffix!r} (valid: a run directory, .tlog, .jsonl)")


def from_run_dir(run: Path) -> Flight:
    """``timeseries.csv`` of ``fly``/``sitl``; the mission named in ``summary.json`` gives the home."""
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
    frame, name = None, run.name
    summary = run / "summary.json"
    if summary.is_file():
        s = json.loads(summary.read_text(encoding="utf-8"))
        name = f"{s.get('mission', '?')} profile {s.get('profile', '?')}, {s.get('method', '?')}"
        frame = _mission_frame(s.get("mission"))
    return Flight(name, columns["t_s"], columns, frame=frame, source=str(run))


REPLAY_TRACKS = {"estimated": ("p_n_m", "p_e_m", "p_d_m")}
REPLAY_COLUMNS = {"b_n_m": "b_est_n_m", "b_e_m": "b_est_e_m", "b_d_m": "b_est_d_m", "beta": "beta",
                  "nis": "nis"}


def from_replay_dir(run: Path) -> Flight:
    """``beliefnav replay`` output: ``estimates.csv`` (boot time) and, from the log named in
    ``summary.json`` when it is still there, the GNSS fixes (validity time, the same clock)."""
    csv = run / "estimates.csv"
    table = np.genfromtxt(csv, delimiter=",", names=True, ndmin=1)
    names = table.dtype.names or ()
    need = ["t_s", *REPLAY_TRACKS["estimated"], *REPLAY_COLUMNS]
    if any(n not in names for n in need):
        raise UserError(f"{csv}: not a replay table (needs columns {', '.join(need)})")
    t_s = np.asarray(table["t_s"], dtype=float)
    columns = {new: np.asarray(table[old], dtype=float) for old, new in REPLAY_COLUMNS.items()}
    _set_track(columns, "estimated", np.column_stack([table[n] for n in REPLAY_TRACKS["estimated"]]))
    summary = run / "summary.json"
    s = json.loads(summary.read_text(encoding="utf-8")) if summary.is_file() else {}
    h = s.get("home") or {}
    has_home = {"lat_deg", "lon_deg", "alt_m"} <= set(h)
    frame = LocalNedFrame(h["lat_deg"], h["lon_deg"], h["alt_m"]) if has_home else None
    fixes: list[Fix] = []
    log = Path(str(s.get("file", "")))
    if frame is not None and log.suffix == ".tlog" and log.is_file():
        from companion.mavlink import codec
        from companion.mavlink.tlog import read_tlog

        for _, m in read_tlog(log, ["GPS_RAW_INT"]):
            try:
                fix = codec.decode_gnss(m)
            except codec.CodecError:
                continue
            if fix.fix_type >= 3:
                fixes.append(Fix(fix.t_validity_us * 1e-6, fix.lat_deg, fix.lon_deg, fix.alt_m, fix.h_acc_m))
        if fixes:
            lla = np.array([(f.lat_deg, f.lon_deg, f.alt_m) for f in fixes])
            ned = frame.to_ned_m(lla[:, 0], lla[:, 1], lla[:, 2]).T
            _set_track(columns, "gnss", _interp(t_s, np.array([f.t_s for f in fixes]), ned))
    name = f"{run.name} ({s.get('method', '?')} on {log.name or '?'})"
    return Flight(name, t_s, columns, fixes=fixes, frame=frame, source=str(run))


def _mission_frame(mission: object) -> LocalNedFrame | None:
    """The home of a packaged mission by its name (a run of a mission file has none: no map coordinates)."""
    from companion.mission import load_mission
    from companion.mission.loader import BUILTIN_MISSIONS

    for key in BUILTIN_MISSIONS:
        m = load_mission(key)
        if m.name == mission:
            return m.frame
    return None


def from_recording(path: Path, vehicle: str | None) -> Flight:
    from gcs_tools.recorder.recording import read_recording, series

    rec = read_recording(path)
    if vehicle is None:
        vehicle = rec.vehicles[0]
    elif vehicle not in rec.vehicles:
        raise UserError(f"{path}: no vehicle {vehicle!r} (valid: {', '.join(rec.vehicles)})")
    s = series(rec, vehicle)
    columns: dict[str, np.ndarray] = {}
    for key, cols in FLY_COLUMNS.items():
        values = np.asarray(s[key], dtype=float).reshape(len(s["t_s"]), -1)
        for i, c in enumerate(cols):
            columns[c] = values[:, i]
    gnss = sorted(rec.messages[vehicle].get("gnss", []), key=lambda g: g.t_us)
    fixes = [Fix(g.t_us * 1e-6, g.fix.lat_deg, g.fix.lon_deg, g.fix.alt_m, g.fix.h_acc_m) for g in gnss]
    return Flight(f"{path.stem} {vehicle}", s["t_s"], columns, fixes=fixes, source=str(path))


def from_tlog(path: Path, home: LocalNedFrame | None) -> Flight:
    """What was on the wire: ODOMETRY (the companion), SIM_STATE (truth), GPS_RAW_INT, the autopilot's
    GLOBAL_POSITION_INT, setpoints, the belief's NAMED_VALUE_FLOATs and the bias DEBUG_VECT, on the
    estimate's time base (the autopilot's or the fixes' when the log has no ODOMETRY). Times are the
    log's arrival stamps relative to its first message; positions are NED about ``home`` (default: the
    first 3-D fix)."""
    from companion.mavlink import codec
    from companion.mavlink.tlog import read_tlog

    kinds = ["ODOMETRY", "SIM_STATE", "GPS_RAW_INT", "GLOBAL_POSITION_INT", "SET_POSITION_TARGET_LOCAL_NED",
             "NAMED_VALUE_FLOAT", "DEBUG_VECT"]
    raw: dict[str, list[tuple[float, Any]]] = {
        k: [] for k in ("est", "true", "gnss", "ap", "ref", "beta", "nis", "bias")}
    fixes: list[Fix] = []
    t0_us: int | None = None
    geo: dict[str, list[tuple[float, float, float, float]]] = {"true": [], "gnss": [], "ap": []}
    try:
        reader = read_tlog(path, kinds)
        for stamp_us, m in reader:
            t0_us = stamp_us if t0_us is None else t0_us
            t = (stamp_us - t0_us) * 1e-6
            kind = m.get_type()
            try:
                if kind == "ODOMETRY":
                    e = codec.decode_odometry(m)
                    raw["est"].append((t, tuple(e.p_ned_m)))
                elif kind == "SIM_STATE":
                    geo["true"].append((t, float(m.lat), float(m.lon), float(m.alt)))
                elif kind == "GPS_RAW_INT":
                    fix = codec.decode_gnss(m)
                    if fix.fix_type >= 3:
                        fixes.append(Fix(t, fix.lat_deg, fix.lon_deg, fix.alt_m, fix.h_acc_m))
                        geo["gnss"].append((t, fix.lat_deg, fix.lon_deg, fix.alt_m))
                elif kind == "GLOBAL_POSITION_INT":
                    geo["ap"].append((t, m.lat * 1e-7, m.lon * 1e-7, m.alt * 1e-3))
                elif kind == "SET_POSITION_TARGET_LOCAL_NED":
                    raw["ref"].append((t, tuple(codec.decode_setpoint(m).p_ned_m)))
                elif kind == "NAMED_VALUE_FLOAT":
                    v = codec.decode_named_value(m)
                    if v.name == codec.BELIEF_NAME:
                        raw["beta"].append((t, (v.value,)))
                    elif v.name == codec.NIS_NAME:
                        raw["nis"].append((t, (v.value,)))
                elif kind == "DEBUG_VECT":
                    raw["bias"].append((t, tuple(codec.decode_bias(m)[1])))
            except codec.CodecError:
                continue  # a damaged message is skipped here; `beliefnav replay` counts them by reason
    except FileNotFoundError:
        raise UserError(f"{path}: no such file") from None
    if t0_us is None:
        raise UserError(f"{path}: no position, estimate or GNSS message in this tlog")
    frame = home
    if frame is None and fixes:
        frame = LocalNedFrame(fixes[0].lat_deg, fixes[0].lon_deg, fixes[0].alt_m)
    if frame is not None:
        for label, rows in geo.items():
            if rows:
                lla = np.array(rows)
                ned = frame.to_ned_m(lla[:, 1], lla[:, 2], lla[:, 3]).T
                raw[label] = list(zip(lla[:, 0], ned, strict=True))
    base = next((raw[k] for k in ("est", "ap", "gnss", "true") if raw[k]), None)
    if base is None:
        raise UserError(f"{path}: no position, estimate or GNSS message in this tlog")
    t_s = np.array([r[0] for r in base])
    columns: dict[str, np.ndarray] = {}
    for label, key in (("estimated", "est"), ("true", "true"), ("gnss", "gnss"), ("autopilot", "ap"),
                       ("reference", "ref")):
        if raw[key]:
            src = np.array([r[0] for r in raw[key]])
            _set_track(columns, label, _interp(t_s, src, np.array([r[1] for r in raw[key]])))
    for key in ("beta", "nis"):
        if raw[key]:
            src = np.array([r[0] for r in raw[key]])
            columns[key] = _interp(t_s, src, np.array([r[1] for r in raw[key]]))[:, 0]
    if raw["bias"]:
        b = _interp(t_s, np.array([r[0] for r in raw["bias"]]), np.array([r[1] for r in raw["bias"]]))
        for i, a in enumerate(AXES):
            columns[f"b_est_{a}_m"] = b[:, i]
    if raw["est"] and raw["true"]:
        columns["est_error_m"] = np.linalg.norm(
            np.column_stack([columns[f"p_est_{a}_m"] for a in AXES])
            - np.column_stack([columns[f"p_true_{a}_m"] for a in AXES]), axis=1)
    return Flight(path.stem, t_s, columns, fixes=fixes, frame=frame, source=str(path))

