"""The smartLoc data set's text format (TU Chemnitz; CC BY-SA 4.0): pseudoranges and truth.

``*_Input.txt`` rows ``pseudorange3 t pr var x y z id system el cn0`` (pseudoranges with satellite
clock and atmosphere already removed, satellite ECEF positions at transmission) and ``odom3``
rows (speed, yaw rate), or instead ``imu`` rows ``imu t fx fy fz wx wy wz …`` (specific force m/s² and
body rate rad/s in the sensor's axes: the UrbanNav data set as TU Chemnitz formats it), of which the
yaw rate about up is kept as odometry without a speed (``gcs_tools.gnss.imu_yaw``); ``*_GT.txt`` rows
``point3 t x y z …`` (truth in ECEF at 5 Hz). Times are
the data set's own seconds from the drive's start (no GPS time is given), so epochs carry
``time_base="dataset"``. smartLoc system codes: 1 GPS, 2 SBAS, 4 GLONASS, 8 Galileo, 16 QZSS,
32 BeiDou; GLONASS ids are 300 + slot.

A row that does not parse, holds NaN/inf, names an unknown system or holds a range, satellite
position, variance or C/N0 no satellite and receiver give (``out_of_range``) is skipped and counted in
``rejected`` (by reason), as is a row whose time lies more than ``LONE_STAMP_S`` from both of its
neighbours in the file (``lone_stamp``: a damaged stamp; the rows are in time order); a file with no
usable epoch is a ``UserError``. A truth row with such a time is a ``UserError`` naming its line.

``write_input`` / ``write_truth`` are the inverse (``gcs_tools.evaluate.smartloc_export`` writes the
simulator's flights with them): every number in ``DIGITS`` significant digits (the data set's files
carry 14), the odometry's covariance columns ``ODOM_COV`` (the data set's constants).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from companion.errors import UserError
from companion.gnss.observations import GnssEpoch, make_epoch
from companion.gnss.systems import System
from gcs_tools.gnss.imu_yaw import YawRate, yaw_rate_from_imu

SYSTEMS = {
    1: System.GPS,
    2: System.SBAS,
    4: System.GLONASS,
    8: System.GALILEO,
    16: System.QZSS,
    32: System.BEIDOU,
}
EPOCH_GAP_S = 1e-6  # rows with stamps closer than this belong to one epoch
# a row whose time is further than this from the rows before and after it in the file (which agree) is a
# damaged stamp, not a new epoch: one such row at 1e6 s made a tight replay synthesise 50 M IMU samples
LONE_STAMP_S = 10.0
CODES = {v: k for k, v in SYSTEMS.items()}
GLONASS_ID_OFFSET = 300
DIGITS = 15
# odom3 covariances (vx, vy, vz, ωx, ωy, ωz), as smartLoc Berlin Potsdamer Platz states them on every row
ODOM_COV = (0.0025, 0.0009, 0.0009, 4e-06, 4e-06, 4e-06)
# imu rows beyond any MEMS IMU's full scale (16 g, 2000 °/s)
IMU_MAX_M_S2 = 16 * 9.80665
IMU_MAX_RAD_S = math.radians(2000.0)


@dataclass
class SmartLocInput:
    epochs: list[GnssEpoch]
    odometry: np.ndarray  # (m, 3): t_s, forward speed m/s (NaN: none, a gyro alone), yaw rate rad/s
    rejected: Counter[str] = field(default_factory=Counter)
    rows: int = 0
    # where the odometry came from: "odom3" (wheel speed and yaw rate), "imu" (the yaw rate about up of
    # the imu rows, no speed: ``gcs_tools.gnss.imu_yaw``) or "none"
    odometry_source: str = "none"
    imu: YawRate | None = None  # the imu rows' yaw rate, when odometry_source is "imu"


@dataclass
class Truth:
    t_s: np.ndarray  # (n,)
    p_ecef_m: np.ndarray  # (n, 3)
    max_gap_s: float = 0.5  # not interpolated across a longer gap between rows
    rejected: Counter[str] = field(default_factory=Counter)  # rows left out, by reason
    source: str = "smartLoc point3 rows"

    def at(self, t_s: np.ndarray, max_gap_s: float | None = None) -> np.ndarray:
        """Truth linearly interpolated at ``t_s`` (k, 3); NaN outside or across a gap > max_gap_s
        (default: the truth's own ``max_gap_s``)."""
        max_gap_s = self.max_gap_s if max_gap_s is None else max_gap_s
        t_s = np.asarray(t_s, dtype=float)
        out = np.column_stack([np.interp(t_s, self.t_s, self.p_ecef_m[:, i]) for i in range(3)])
        j = np.clip(np.searchsorted(self.t_s, t_s), 1, len(self.t_s) - 1)
        bad = (
            (t_s < self.t_s[0] - 1e-6)
            | (t_s > self.t_s[-1] + 1e-6)
            | (self.t_s[j] - self.t_s[j - 1] > max_gap_s)
        )
        out[bad] = np.nan
        return out


def _lines(path: Path) -> list[str]:
    try:
        return path.read_text(encoding="ascii", errors="replace").splitlines()
    except OSError as exc:
        raise UserError(f"{path}: cannot read: {exc.strerror or exc}") from None


def read_input(path: str | Path) -> SmartLocInput:
    path = Path(path)
    rejected: Counter[str] = Counter()
    pr_rows: list[list[float]] = []
    odo: list[list[float]] = []
    imu: list[list[float]] = []
    n = 0
    for line in _lines(path):
        parts = line.split()
        if not parts:
            continue
        n += 1
        tag = parts[0]
        if tag == "pseudorange3":
            row = _checked(parts, 10, rejected, _pseudorange_problem)
            if row is not None:
                pr_rows.append(row)
        elif tag == "imu":
            row = _checked(parts, 7, rejected, _imu_problem)
            if row is not None:
                imu.append(row)
        elif tag == "odom3":
            try:
                v = [float(parts[1]), float(parts[2]), float(parts[7])]
            except (ValueError, IndexError):
                rejected["unparsable"] += 1
                continue
            if all(math.isfinite(x) for x in v):
                odo.append(v)
            else:
                rejected["nonfinite"] += 1
        else:
            rejected["unknown_row_type"] += 1
    pr_rows = _drop_lone_stamps(pr_rows, rejected)
    odo = _drop_lone_stamps(odo, rejected)
    imu = _drop_lone_stamps(imu, rejected)
    if not pr_rows:
        raise UserError(
            f"{path}: no usable smartLoc pseudorange3 rows in {n} lines "
            f"(rejected: {dict(rejected) or 'none'})"
        )
    a = np.array(pr_rows)
    order = np.argsort(a[:, 0], kind="stable")
    a = a[order]
    starts = np.r_[0, np.nonzero(np.diff(a[:, 0]) > EPOCH_GAP_S)[0] + 1, len(a)]
    epochs = []
    for i0, i1 in zip(starts[:-1], starts[1:], strict=True):
        r = a[i0:i1]
        system = np.array([SYSTEMS[int(c)] for c in r[:, 7]], dtype=np.int8)
        ident = r[:, 6].astype(int)
        glo = (system == System.GLONASS) & (ident > GLONASS_ID_OFFSET)
        prn = np.where(glo, ident - GLONASS_ID_OFFSET, ident)
        epochs.append(
            make_epoch(
                r[0, 0],
                system,
                prn,
                r[:, 1],
                pseudorange_var_m2=r[:, 2],
                sat_pos_ecef_m=r[:, 3:6],
                elevation_deg=r[:, 8],
                cn0_dbhz=r[:, 9],
                corrected=True,
                time_base="dataset",
            )
        )
    if odo:
        return SmartLocInput(epochs, np.array(odo).reshape(-1, 3), rejected, n, "odom3")
    if len(imu) >= 2:  # a drive with an IMU instead of odometry: its yaw rate, the speed unknown
        a = np.array(imu)
        a = a[np.argsort(a[:, 0], kind="stable")]
        yaw = yaw_rate_from_imu(a[:, 0], a[:, 1:4], a[:, 4:7])
        rows = np.column_stack([yaw.t_s, np.full(len(yaw.t_s), np.nan), yaw.yaw_rate_ccw_rad_s])
        return SmartLocInput(epochs, rows, rejected, n, "imu", yaw)
    return SmartLocInput(epochs, np.zeros((0, 3)), rejected, n)


def _checked(parts: list[str], n: int, rejected: Counter[str], problem: Callable[[list[float]], str]
             ) -> list[float] | None:
    """A row's first ``n`` numbers after its tag, or None with the reason counted in ``rejected``."""
    try:
        vals = [float(v) for v in parts[1:n + 1]]
    except ValueError:
        rejected["unparsable"] += 1
        return None
    reason = ("short_row" if len(vals) < n else "nonfinite" if not all(math.isfinite(v) for v in vals)
              else problem(vals))
    if reason:
        rejected[reason] += 1
        return None
    return vals


def _pseudorange_problem(vals: list[float]) -> str:
    return "unknown_system" if int(vals[7]) not in SYSTEMS else "" if _plausible(vals) else "out_of_range"


def _imu_problem(vals: list[float]) -> str:
    """Beyond any MEMS IMU's full scale: a damaged row, not a car's motion."""
    wild = max(map(abs, vals[1:4])) > IMU_MAX_M_S2 or max(map(abs, vals[4:7])) > IMU_MAX_RAD_S
    return "out_of_range" if wild else ""


def _plausible(vals: list[float]) -> bool:
    """A pseudorange row's range (m), satellite distance from the Earth's centre (m), variance and C/N0
    (dB-Hz) are values a satellite and receiver give (a finite 1e308 overflowed the solver)."""
    sat_m = math.hypot(vals[3], vals[4], vals[5])
    return 1.0e7 < vals[1] < 5.0e7 and 2.0e7 < sat_m < 5.0e7 and vals[2] >= 0.0 and 0.0 <= vals[9] < 100.0


def _lone(t: np.ndarray) -> np.ndarray:
    """Rows (in file order) whose time is more than ``LONE_STAMP_S`` from each neighbour's (at the ends:
    from its one neighbour) while those neighbours agree with each other."""
    n = len(t)
    if n < 3:
        return np.zeros(n, dtype=bool)
    far_prev = np.r_[True, np.abs(np.diff(t)) > LONE_STAMP_S]
    far_next = np.r_[np.abs(np.diff(t)) > LONE_STAMP_S, True]
    around = np.r_[False, np.abs(t[2:] - t[:-2]) <= LONE_STAMP_S, False]
    around[0], around[-1] = True, True  # the first and last rows have one neighbour
    return far_prev & far_next & around


def _drop_lone_stamps(rows: list[list[float]], rejected: Counter[str]) -> list[list[float]]:
    lone = _lone(np.array([r[0] for r in rows], dtype=float))
    if lone.any():
        rejected["lone_stamp"] += int(lone.sum())
        rows = [r for r, bad in zip(rows, lone, strict=True) if not bad]
    return rows


def rows_rejected(rejected: Counter[str] | dict[str, int], prefix: str = "smartloc_row") -> dict[str, int]:
    """The input's (or, ``prefix="truth_row"``, the truth's) skipped rows as a replay reader's
    ``samples_rejected`` counters (``smartloc_row_<reason>``), so that a replay says how many rows it left
    out."""
    return {f"{prefix}_{reason}": n for reason, n in rejected.items()}


def read_truth(path: str | Path) -> Truth:
    path = Path(path)
    rows: list[list[float]] = []
    for line in _lines(path):
        parts = line.split()
        if len(parts) >= 5 and parts[0] == "point3":
            try:
                v = [float(x) for x in parts[1:5]]
            except ValueError:
                continue
            if all(math.isfinite(x) for x in v):
                rows.append(v)
    if len(rows) < 2:
        raise UserError(f"{path}: fewer than 2 usable smartLoc point3 (truth) rows")
    lone = _lone(np.array([r[0] for r in rows]))
    if lone.any():
        k = int(np.flatnonzero(lone)[0])
        raise UserError(f"{path}: point3 row {k + 1} at {rows[k][0]:g} s lies more than {LONE_STAMP_S:g} s "
                        "from the rows around it (a damaged time)")
    a = np.array(rows)
    a = a[np.argsort(a[:, 0], kind="stable")]
    return Truth(a[:, 0], a[:, 1:4])


def truth_label(truth: Truth) -> str:
    """A replay's name for the truth reference: ``smartLoc point3``, or the other format's rows."""
    return "smartLoc point3" if truth.source == Truth.source else truth.source


def default_truth_path(input_path: Path) -> Path | None:
    """``X_Input.txt`` -> ``X_GT.txt`` when that file exists."""
    name = input_path.name
    if "_Input" in name:
        cand = input_path.with_name(name.replace("_Input", "_GT"))
        if cand.is_file():
            return cand
    return None


def read_drive(input_path: Path, truth_path: Path | None = None) -> tuple[SmartLocInput, Truth]:
    """A drive's input and its truth (``truth_path`` in any format :mod:`gcs_tools.gnss.truth` reads, on the
    drive's time scale; else the ``*_GT.txt`` beside the input; a ``UserError`` naming ``--truth`` when
    there is none or it covers none of the epochs)."""
    from gcs_tools.gnss import truth as truth_formats

    data = read_input(input_path)
    truth_path = truth_path or default_truth_path(input_path)
    if truth_path is None:
        raise UserError(f"{input_path}: no *_GT.txt truth beside it; give --truth")
    truth = truth_formats.read(truth_path)
    truth_formats.check_covers(truth, np.array([e.t_gps_s for e in data.epochs]), truth_path)
    return data, truth


def _num(v: float) -> str:
    return f"{v:.{DIGITS}g}"


def write_input(path: str | Path, epochs: list[GnssEpoch], odometry: np.ndarray) -> None:
    """``epochs`` (pre-corrected pseudoranges with satellite positions, ``t_gps_s`` the file's time) and
    ``odometry`` ((m, 3): t_s, forward speed m/s, yaw rate rad/s counter-clockwise) as a smartLoc
    ``*_Input.txt``: the ``odom3`` rows, then the ``pseudorange3`` rows, in time order (the data set's
    layout). An observation with a value that is not finite is left out (the reader would reject it)."""
    lines = []
    for t, v, w in np.asarray(odometry, dtype=float).reshape(-1, 3):
        lines.append(" ".join(["odom3", _num(t), _num(v), "0", "0", "0", "0", _num(w),
                               *(f"{c:g}" for c in ODOM_COV)]))
    for e in epochs:
        if not e.corrected:
            raise ValueError("write_input: smartLoc pseudoranges are corrected (satellite clock, atmosphere)")
        for i in range(e.n):
            system = System(int(e.system[i]))
            ident = int(e.prn[i]) + (GLONASS_ID_OFFSET if system == System.GLONASS else 0)
            measured = (e.pseudorange_m[i], e.pseudorange_var_m2[i], *e.sat_pos_ecef_m[i])
            sky = (e.elevation_deg[i], e.cn0_dbhz[i])
            if not all(math.isfinite(float(x)) for x in (*measured, *sky)):
                continue
            lines.append(" ".join(["pseudorange3", _num(e.t_gps_s), *map(_num, measured), str(ident),
                                   str(CODES[system]), *map(_num, sky)]))
    Path(path).write_text("\n".join(lines) + "\n", encoding="ascii")


def write_truth(path: str | Path, t_s: np.ndarray, p_ecef_m: np.ndarray) -> None:
    """Truth positions (ECEF) as a smartLoc ``*_GT.txt`` (``point3`` rows, the covariance zeros)."""
    rows = (" ".join(["point3", _num(t), *(_num(x) for x in p), *("0" * 9)])
            for t, p in zip(np.asarray(t_s, dtype=float), np.asarray(p_ecef_m, dtype=float), strict=True))
    Path(path).write_text("\n".join(rows) + "\n", encoding="ascii")


def is_smartloc(path: Path) -> bool:
    with open(path, "rb") as f:
        head = f.read(64).lstrip()
    return head.startswith((b"pseudorange3", b"odom3", b"point3"))
