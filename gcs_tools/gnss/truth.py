"""Reference trajectories ("truth") in the text formats urban GNSS data sets ship, recognised by content.

* smartLoc ``*_GT.txt``: ``point3 t x y z …`` rows (ECEF; the data set's own seconds), as
  :func:`gcs_tools.gnss.smartloc.read_truth` reads them;
* a NovAtel SPAN / Inertial Explorer text export (e.g. UrbanNav Hong Kong's reference): whitespace-
  separated, a line of column names then a line of units in parentheses; the columns ``Week`` and
  ``GPSTime`` (GPS week, seconds of week) give the time, or, without them, ``UTCTime`` (UTC Unix
  seconds, turned into GPS time with the leap-second table); ``Latitude``, ``Longitude`` in signed
  degrees-minutes-seconds (unit ``(+/-D M S)``: three fields, the sign on the degrees, ``-0 30 00.0``
  is −0.5°) or decimal degrees (``(deg)``), ``H-Ell`` the ellipsoidal height (m); other columns ignored;
* a CSV with a header line naming its columns: the time ``gps_week,gps_tow_s`` or ``t_gps_s`` (GPS
  seconds since 1980-01-06), the position ``lat_deg,lon_deg,h_m`` (WGS84, ellipsoidal height) or
  ``x_m,y_m,z_m`` (ECEF); other columns ignored, ``#`` lines skipped.

Times are GPS time (no leap-second shift), the time scale of RINEX and UBX epochs; the truth is
interpolated at the epochs' times as smartLoc's is. A row that does not parse, holds NaN/inf, lies off
the Earth's surface, does not advance in time, or whose time lies more than ``LONE_STAMP_S`` from its
neighbours is left out and counted in ``Truth.rejected`` (by reason); a file with no recognised header
or fewer than 2 usable rows is a one-line ``UserError``. A SPAN or CSV truth is interpolated across gaps
up to 1.5 of its median step (0.5 s at least), so that a 1 Hz reference covers the epochs between its
rows; smartLoc's keeps 0.5 s.
"""

from __future__ import annotations

import math
import re
from collections import Counter
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from companion.errors import UserError
from companion.gnss.geometry import geodetic_to_ecef
from companion.gnss.timescale import gps_from_week_tow, unix_to_gps_s
from gcs_tools.gnss import smartloc
from gcs_tools.gnss.smartloc import Truth

SPAN_NAMES = ("Latitude", "Longitude", "H-Ell")
CSV_TIMES = (("gps_week", "gps_tow_s"), ("t_gps_s",))
CSV_POSITIONS = (("lat_deg", "lon_deg", "h_m"), ("x_m", "y_m", "z_m"))
EARTH_RADIUS_RANGE_M = (6.0e6, 7.0e6)  # an ECEF position on (or near) the Earth's surface
HEADER_LINES = 50  # a header is looked for in this many first lines


def read(path: str | Path) -> Truth:
    """The truth in ``path``, whichever of the formats above it is (by content)."""
    path = Path(path)
    if not path.is_file():
        raise UserError(f"{path}: no such truth file")
    lines = smartloc._lines(path)
    head = [ln for ln in lines[:HEADER_LINES] if ln.strip()]
    if any(ln.split()[0] == "point3" for ln in head):
        return smartloc.read_truth(path)
    for i, ln in enumerate(lines[:HEADER_LINES]):
        names = ln.split()
        if all(n in names for n in SPAN_NAMES):
            return _span(path, lines, i)
        cols = [c.strip() for c in ln.split(",")]
        if any(all(n in cols for n in t) for t in CSV_TIMES) and any(all(n in cols for n in p)
                                                                      for p in CSV_POSITIONS):
            return _csv(path, lines, i, cols)
    raise UserError(f"{path}: not a truth file: no smartLoc point3 rows, SPAN/Inertial Explorer header "
                    f"(Week GPSTime Latitude Longitude H-Ell) or CSV header (gps_week,gps_tow_s or t_gps_s; "
                    f"lat_deg,lon_deg,h_m or x_m,y_m,z_m) in its first {HEADER_LINES} lines")


def dms_to_deg(d: str, m: str, s: str) -> float:
    """Signed degrees-minutes-seconds (the sign on the degrees, also for ``-0``) -> degrees; ValueError
    for minutes or seconds outside [0, 60)."""
    deg, mins, secs = float(d), float(m), float(s)
    if not (0.0 <= mins < 60.0 and 0.0 <= secs < 60.0):
        raise ValueError(f"minutes {m} or seconds {s} outside [0, 60)")
    value = abs(deg) + mins / 60.0 + secs / 3600.0
    return -value if d.strip().startswith("-") else value


def _span(path: Path, lines: Sequence[str], i: int) -> Truth:
    names = lines[i].split()
    unit_line = next((ln for ln in lines[i + 1:i + 3] if ln.strip()), "")
    units = re.findall(r"\(([^)]*)\)", unit_line)
    if not unit_line.strip().startswith("(") or not units:
        raise UserError(f"{path}: SPAN export without its line of units in parentheses after the column "
                        "names")
    unit = dict(zip(names, units, strict=False))
    if "Week" in names and "GPSTime" in names:
        time_cols: tuple[str, ...] = ("Week", "GPSTime")
    elif "UTCTime" in names:
        time_cols = ("UTCTime",)
    else:
        raise UserError(f"{path}: SPAN export without Week and GPSTime (or UTCTime) columns")
    dms = {n: "D M S" in unit.get(n, "") for n in ("Latitude", "Longitude")}
    for n in ("Latitude", "Longitude"):
        if not dms[n] and unit.get(n, "").strip() != "deg":
            raise UserError(f"{path}: SPAN column {n} in ({unit.get(n, '')}): expected (+/-D M S) or (deg)")
    # a DMS column takes three whitespace-separated fields of a row
    start, at = 0, {}
    for n in names:
        at[n] = start
        start += 3 if dms.get(n, False) else 1

    def parse(parts: list[str]) -> list[float]:
        if "Week" in time_cols:
            t = gps_from_week_tow(int(float(parts[at["Week"]])), float(parts[at["GPSTime"]]))
        else:
            t = unix_to_gps_s(float(parts[at["UTCTime"]]))
        ll = []
        for n in ("Latitude", "Longitude"):
            k = at[n]
            ll.append(dms_to_deg(*parts[k:k + 3]) if dms[n] else float(parts[k]))
        return [t, *ll, float(parts[at["H-Ell"]])]

    need = max(at[n] + (3 if dms.get(n, False) else 1) for n in (*time_cols, *SPAN_NAMES))
    first = i + 1 + lines[i + 1:].index(unit_line) + 1
    return _rows(path, lines[first:], lambda ln: ln.split(), parse, need, geodetic=True,
                 what="SPAN export rows")


def _csv(path: Path, lines: Sequence[str], i: int, cols: list[str]) -> Truth:
    at = {c: k for k, c in enumerate(cols)}
    time_cols = next(t for t in CSV_TIMES if all(n in at for n in t))
    pos_cols = next(p for p in CSV_POSITIONS if all(n in at for n in p))
    geodetic = pos_cols[0] == "lat_deg"

    def parse(parts: list[str]) -> list[float]:
        if len(time_cols) == 2:
            week = float(parts[at["gps_week"]])
            if week != int(week):
                raise ValueError("gps_week not an integer")
            t = gps_from_week_tow(int(week), float(parts[at["gps_tow_s"]]))
        else:
            t = float(parts[at["t_gps_s"]])
        return [t, *(float(parts[at[n]]) for n in pos_cols)]

    need = max(at[n] for n in (*time_cols, *pos_cols)) + 1
    return _rows(path, lines[i + 1:], lambda ln: [p.strip() for p in ln.split(",")], parse, need,
                 geodetic=geodetic, what="CSV rows")


def _rows(path: Path, lines: Sequence[str], split, parse, need: int, geodetic: bool, what: str) -> Truth:
    rejected: Counter[str] = Counter()
    rows: list[list[float]] = []
    for ln in lines:
        if not ln.strip() or ln.lstrip().startswith("#"):
            continue
        parts = split(ln)
        if len(parts) < need:
            rejected["short_row"] += 1
            continue
        try:
            v = parse(parts)
        except (ValueError, IndexError, OverflowError):
            rejected["unparsable"] += 1
            continue
        if not all(math.isfinite(x) for x in v):
            rejected["nonfinite"] += 1
        elif not _on_earth(v[1:4], geodetic):
            rejected["off_earth"] += 1
        else:
            rows.append(v)
    lone = smartloc._lone(np.array([r[0] for r in rows], dtype=float))
    if lone.any():
        rejected["lone_stamp"] += int(lone.sum())
        rows = [r for r, bad in zip(rows, lone, strict=True) if not bad]
    kept: list[list[float]] = []
    for r in rows:
        if kept and r[0] <= kept[-1][0]:
            rejected["time_not_increasing"] += 1
        else:
            kept.append(r)
    if len(kept) < 2:
        raise UserError(f"{path}: fewer than 2 usable {what} (rejected: {dict(rejected) or 'none'})")
    a = np.array(kept)
    p = (geodetic_to_ecef(np.radians(a[:, 1]), np.radians(a[:, 2]), a[:, 3]) if geodetic else a[:, 1:4])
    max_gap = max(0.5, 1.5 * float(np.median(np.diff(a[:, 0]))))
    return Truth(a[:, 0], np.asarray(p, dtype=float).reshape(-1, 3), max_gap_s=max_gap, rejected=rejected,
                 source=what)


def _on_earth(p: list[float], geodetic: bool) -> bool:
    if geodetic:
        return abs(p[0]) <= 90.0 and abs(p[1]) <= 360.0 and abs(p[2]) < 1e5
    return EARTH_RADIUS_RANGE_M[0] < math.hypot(*p) < EARTH_RADIUS_RANGE_M[1]


def check_covers(truth: Truth, t_s: np.ndarray, path: Path) -> None:
    """A ``UserError`` when the truth is known at none of the epochs' times ``t_s`` (most often: another
    time scale, e.g. a GPS-time truth for smartLoc's seconds from the drive's start)."""
    t_s = np.asarray(t_s, dtype=float)
    if len(t_s) and not np.isfinite(truth.at(t_s)).all(axis=1).any():
        raise UserError(f"{path}: the truth ({truth.t_s[0]:.1f} to {truth.t_s[-1]:.1f} s) covers none of the "
                        f"epochs ({t_s[0]:.1f} to {t_s[-1]:.1f} s): another time scale or another drive? "
                        "(RINEX and UBX epochs are in GPS time)")
