"""ANSFL quadrotor flights -> replay events: a real IMU and its RTK truth, no GNSS of its own.

Data set: *Quadrotor Dead Reckoning with Multiple Inertial Sensors* (D. Hurwitz and I. Klein,
ANSFL, University of Haifa), licence CC BY 4.0. A flight is a directory holding ``IMU_1.csv``
(an Xsens DOT unit on a DJI Phantom 4) and ``GT.csv`` (the drone's RTK log); ``replay`` takes
the directory or the IMU file itself (any ``IMU_<k>.csv`` with ``GT.csv`` beside it).

Frames and units as read:

- ``IMU_1.csv``: ``time`` [s] at 120 Hz; ``Euler_X/Y/Z`` [deg] = roll, pitch, yaw of the sensor
  frame with respect to ENU (intrinsic Z-Y-X: ``R_enu_sensor = Rz(yaw) Ry(pitch) Rx(roll)``);
  ``Acc_X/Y/Z`` = specific force [m/s²] in the sensor frame (z up, +9.8 at rest);
  ``Gyr_X/Y/Z`` [deg/s] in the sensor frame. Body FRD = sensor (x, −y, −z), so
  ``R_ned_frd = C · R_enu_sensor · diag(1, −1, −1)`` with ``C`` the ENU→NED swap, and the
  specific force and rates in FRD are (x, −y, −z) of the sensor's.
- ``GT.csv``: ``time`` [s] at 10 Hz; ``North``, ``East``, ``Down`` [m] in a local frame about the
  flight's first truth point (Down is quantised to 0.1 m).

The two clocks differ: the IMU time is the truth's plus an offset of 0.1–0.8 s that changes
from flight to flight; it is fitted per flight (:mod:`gcs_tools.replay.clockfit`: the IMU's
specific force rotated to NED against the truth's second difference) and the truth is moved to
the IMU's clock. The fit also measures the IMU heading's error against the truth track
(``clock.yaw_deg``); the attitude is used as recorded (an autopilot's heading is not perfect
either). The data set gives no geodetic position: the local frame is anchored at
:data:`NOMINAL_HOME` (or ``--home``); every comparison is made in that frame.

Events: per IMU row an ``AttitudeSample`` then an ``ImuSample`` (IMU time), and the truth as
``LocalReference`` positions in the replay's frame, in time order. No ``GnssFix``: a replay
makes them (``--gnss-errors``, :mod:`gcs_tools.replay.synthetic_gnss`).
"""

from __future__ import annotations

import functools
import math
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from companion.domain.geodesy import LocalNedFrame
from companion.domain.samples import AttitudeSample, ImuSample
from companion.errors import UserError
from companion.mavlink.codec import LIMITS
from gcs_tools.replay.clockfit import ClockFit, fit_clock_offset
from gcs_tools.replay.events import TRUTH, Event, LocalReference, ReaderStats, ReferenceInfo

IMU_FILE = "IMU_1.csv"
TRUTH_FILE = "GT.csv"
IMU_COLUMNS = ("time", "Euler_X", "Euler_Y", "Euler_Z", "Acc_X", "Acc_Y", "Acc_Z", "Gyr_X", "Gyr_Y", "Gyr_Z")
TRUTH_COLUMNS = ("time", "North", "East", "Down")
# The data set has no geodetic position; this anchor (Haifa) only names the fixes' lat/lon.
NOMINAL_HOME = (32.7614, 35.0195, 0.0)
GRAVITY_M_S2 = 9.80665
# ENU -> NED (x↔y, z → −z) and sensor -> FRD (y, z flipped): both 180° rotations
C_NED_ENU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
F_SENSOR_FRD = np.diag([1.0, -1.0, -1.0])
TRUTH_INFO = ReferenceInfo(
    "GT.csv", "geodetic",
    "estimated position vs the RTK truth (GT.csv North/East/Down about the flight's first truth point, "
    "the replay's home), moved to the IMU's clock by the fitted offset")


def flight_files(path: Path) -> tuple[Path, Path] | None:
    """(IMU file, truth file) when ``path`` is an ANSFL flight directory or its IMU file; else None."""
    if path.is_dir():
        imu, gt = path / IMU_FILE, path / TRUTH_FILE
    elif path.name.startswith("IMU_") and path.suffix.lower() == ".csv":
        imu, gt = path, path.parent / TRUTH_FILE
    else:
        return None
    return (imu, gt) if imu.is_file() and gt.is_file() else None


@dataclass(frozen=True)
class AnsflFlight:
    """One flight, every time on the IMU's clock (s)."""

    t_s: np.ndarray  # (n,) IMU time
    q_ned_frd: np.ndarray  # (n, 4) w, x, y, z
    acc_frd_m_s2: np.ndarray  # (n, 3) specific force
    gyro_frd_rad_s: np.ndarray  # (n, 3)
    t_truth_s: np.ndarray  # (m,) truth time moved to the IMU clock (truth clock + clock.offset_s)
    p_truth_ned_m: np.ndarray  # (m, 3)
    clock: ClockFit
    dropped_imu_rows: int  # non-finite or not after the previous row
    dropped_truth_rows: int

    def a_ned_m_s2(self) -> np.ndarray:
        """The IMU's acceleration in NED: specific force rotated + gravity."""
        return rotate(self.q_ned_frd, self.acc_frd_m_s2) + np.array([0.0, 0.0, GRAVITY_M_S2])


def rotate(q_ned_frd: np.ndarray, v_frd: np.ndarray) -> np.ndarray:
    """(n, 3) FRD vectors in NED."""
    from scipy.spatial.transform import Rotation

    # copies: scipy's Rotation wants writable buffers, and the cached flight's arrays are read-only
    return Rotation.from_quat(np.array(q_ned_frd)[:, [1, 2, 3, 0]]).apply(np.array(v_frd, dtype=float))


def attitude_ned_frd(roll_deg: np.ndarray, pitch_deg: np.ndarray, yaw_enu_deg: np.ndarray) -> np.ndarray:
    """(n, 4) quaternions (w, x, y, z) of body FRD -> NED from the sensor's Euler angles w.r.t. ENU."""
    from scipy.spatial.transform import Rotation

    ypr = np.column_stack((yaw_enu_deg, pitch_deg, roll_deg))
    r_enu_sensor = Rotation.from_euler("ZYX", ypr, degrees=True)
    r = Rotation.from_matrix(C_NED_ENU) * r_enu_sensor * Rotation.from_matrix(F_SENSOR_FRD)
    xyzw = r.as_quat()
    return xyzw[:, [3, 0, 1, 2]]


def _read_csv(path: Path, columns: tuple[str, ...]) -> np.ndarray:
    """The named columns (in ``columns`` order) of a CSV with a header line; one-line errors."""
    try:
        with open(path, encoding="utf-8") as f:
            header = [h.strip() for h in f.readline().strip().split(",")]
            missing = [c for c in columns if c not in header]
            if missing:
                raise UserError(f"{path}: no column {missing[0]} (its columns: {','.join(header)})")
            idx = [header.index(c) for c in columns]
            with warnings.catch_warnings():  # a file with a header and no rows: the caller's one line
                warnings.simplefilter("ignore", UserWarning)
                data = np.loadtxt(f, delimiter=",", usecols=idx, ndmin=2)
    except OSError as exc:
        raise UserError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise UserError(f"{path}: not UTF-8 text") from None
    except ValueError as exc:
        raise UserError(f"{path}: {_bad_line(path, idx, len(header)) or str(exc).splitlines()[0]}") from None
    return data


def _bad_line(path: Path, idx: list[int], n_header: int) -> str | None:
    """The first row ``np.loadtxt`` could not read, named by its line in the file (numpy's own row
    numbers count differently per error), e.g. a truncated last line or a text line."""
    with open(path, encoding="utf-8") as f:
        for number, line in enumerate(f, start=1):
            if number == 1 or not line.strip():
                continue
            fields = line.rstrip("\r\n").split(",")
            if len(fields) <= max(idx):
                return (f"line {number} has {len(fields)} columns, the header {n_header} "
                        "(a truncated or malformed row)")
            for k in idx:
                try:
                    float(fields[k])
                except ValueError:
                    return f"line {number}, column {k + 1}: {fields[k].strip()!r} is not a number"
    return None


LONE_STAMP_S = 1.0  # a row this far in time from both neighbours (which agree) has a damaged time


def _clean(t: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Rows to keep: finite, not a lone damaged time (more than ``LONE_STAMP_S`` from the rows before
    and after it, which agree: one such row far ahead dropped every row after it), and later than
    every kept row before them."""
    ok = np.isfinite(values).all(axis=1) & np.isfinite(t)
    if len(t) >= 3:
        gap = np.abs(np.diff(t))
        around = np.r_[True, np.abs(t[2:] - t[:-2]) <= LONE_STAMP_S, True]
        ok &= ~(np.r_[True, gap > LONE_STAMP_S] & np.r_[gap > LONE_STAMP_S, True] & around)
    later = np.zeros_like(ok)
    last = -math.inf
    for i in np.flatnonzero(ok).tolist():
        if t[i] > last:
            later[i], last = True, t[i]
    return later


def load_flight(imu_path: Path, truth_path: Path) -> AnsflFlight:
    """The flight of these two files (read and fitted once per process while they are unchanged:
    a campaign replays each flight many times)."""
    stamp = tuple((p.stat().st_mtime_ns, p.stat().st_size) for p in (imu_path, truth_path))
    return _load_flight(imu_path.resolve(), truth_path.resolve(), stamp)


@functools.lru_cache(maxsize=16)
def _load_flight(imu_path: Path, truth_path: Path, stamp: tuple[tuple[int, int], ...]) -> AnsflFlight:
    imu = _read_csv(imu_path, IMU_COLUMNS)
    gt = _read_csv(truth_path, TRUTH_COLUMNS)
    keep_imu, keep_gt = _clean(imu[:, 0], imu), _clean(gt[:, 0], gt)
    imu, dropped_imu = imu[keep_imu], int((~keep_imu).sum())
    gt, dropped_gt = gt[keep_gt], int((~keep_gt).sum())
    if len(imu) < 2 or len(gt) < 3:
        raise UserError(f"{imu_path.parent}: {len(imu)} usable IMU rows and {len(gt)} truth rows; "
                        "an ANSFL flight needs both")
    q = attitude_ned_frd(imu[:, 1], imu[:, 2], imu[:, 3])
    flip = np.array([1.0, -1.0, -1.0])
    acc = imu[:, 4:7] * flip
    gyro = np.radians(imu[:, 7:10]) * flip
    t = imu[:, 0]
    a_ned = rotate(q, acc) + np.array([0.0, 0.0, GRAVITY_M_S2])
    try:
        clock = fit_clock_offset(t, a_ned, gt[:, 0], gt[:, 1:4])
    except UserError as exc:
        raise UserError(f"{imu_path.parent}: {exc}") from None
    arrays = (t, q, acc, gyro, gt[:, 0] + clock.offset_s, gt[:, 1:4].copy())
    for a in arrays:
        a.setflags(write=False)  # shared by every replay of the flight
    return AnsflFlight(*arrays, clock, dropped_imu, dropped_gt)


def _us(t_s: np.ndarray) -> list[int]:
    return np.rint(np.asarray(t_s) * 1e6).astype(np.int64).tolist()


class AnsflSource:
    """LogReader of one ANSFL flight (see the module doc)."""

    format = "ansfl"

    def __init__(self, path: Path, home: LocalNedFrame | None = None) -> None:
        files = flight_files(path)
        if files is None:
            raise UserError(f"{path}: not an ANSFL flight (a directory with {IMU_FILE} and {TRUTH_FILE}, "
                            f"or an IMU_<k>.csv with {TRUTH_FILE} beside it)")
        self.path = path
        self.imu_path, self.truth_path = files
        self.stats = ReaderStats()
        self.sources: dict[str, str | None] = {
            "imu": f"{self.imu_path.name} Acc/Gyr", "attitude": f"{self.imu_path.name} Euler_X/Y/Z",
            "gnss": None}
        self.references: dict[str, ReferenceInfo] = {TRUTH: TRUTH_INFO}
        self.anchor = home if home is not None else LocalNedFrame(*NOMINAL_HOME)
        self.flight = load_flight(self.imu_path, self.truth_path)
        self.clock = self.flight.clock.as_dict()

    def first_fix(self) -> None:
        return None

    def describe_empty(self) -> str:
        return "an ANSFL flight has no GNSS of its own: give --gnss-errors (none, model or an error series)"

    def __iter__(self) -> Iterator[Event]:
        fl, st = self.flight, self.stats
        st.size = self.imu_path.stat().st_size + self.truth_path.stat().st_size
        st.skipped_bytes = 0
        st.rejected["imu_row_dropped"] = fl.dropped_imu_rows
        st.rejected["truth_row_dropped"] = fl.dropped_truth_rows
        t_imu, t_truth = _us(fl.t_s), _us(fl.t_truth_s)
        truth = fl.p_truth_ned_m.tolist()
        # beyond the MAVLink codec's full scale (a 1e30 m/s² row was fused: the track went to 1e27 m): counted
        within = ((np.abs(fl.acc_frd_m_s2) <= LIMITS.max_specific_force_m_s2).all(axis=1)
                  & (np.abs(fl.gyro_frd_rad_s) <= LIMITS.max_rate_rad_s).all(axis=1)).tolist()
        j, m = 0, len(t_truth)
        for i, t in enumerate(t_imu):
            while j < m and t_truth[j] <= t:
                yield LocalReference(TRUTH, t_truth[j], tuple(truth[j]), TRUTH_FILE)
                j += 1
            st.records += 1
            st.decoded["attitude"] += 1
            yield AttitudeSample(t, fl.q_ned_frd[i])
            if not within[i]:
                st.rejected["imu_out_of_range"] += 1
                continue
            st.decoded["imu"] += 1
            yield ImuSample(t, fl.acc_frd_m_s2[i], fl.gyro_frd_rad_s[i])
        for k in range(j, m):
            yield LocalReference(TRUTH, t_truth[k], tuple(truth[k]), TRUTH_FILE)
        st.position = st.size
