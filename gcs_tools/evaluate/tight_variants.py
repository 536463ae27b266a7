"""``python -m gcs_tools.evaluate.tight --smartloc INPUT --variants [NAMES] --out DIR``: the tight filter on
variants of a real drive that another receiver or another data set would plausibly bring.

Every variant is a transformation of the parsed drive (``SmartLocInput`` epochs and odometry, and the
truth), never a file written by hand:

* ``gps-only`` keeps GPS satellites alone; ``no-glonass`` drops GLONASS (the same on a GPS + GLONASS drive);
* ``galileo-mix``: GPS satellites of odd PRN relabelled Galileo, ``ISB_M`` later (a third system and clock);
* ``1hz`` keeps the first epoch of every second of the drive (a 1 Hz receiver in place of ~5 Hz);
* ``cn0-6``, ``cn0-3``, ``cn0+3``: every C/N0 offset by that many dB (another receiver's calibration);
* ``cn0-missing``, ``el-missing``: no C/N0, no elevation column (NaN);
* ``var-constant`` (every given pseudorange variance the drive's median), ``var-missing`` (none given);
* ``first-half``, ``second-half``: the drive cut at its middle time (epochs, odometry and truth);
* ``no-odometry``: no wheel speed or yaw rate;
* ``odo-50hz``, ``odo-1hz``: the odometry at 50 Hz (interpolated) or 1 Hz (decimated) instead of 5 Hz;
* ``gap-2s``: no GNSS epoch for 2 s from the drive's middle time;
* ``time-shift``: every time stamp (epochs, odometry, truth) plus ``TIME_SHIFT_S``.

Names joined by ``+`` compose (``1hz+no-odometry``: left to right). Each variant is scored on its own
epochs (horizontal distance to its truth at every epoch time, as ``gcs_tools.evaluate.tight``) and its
rows' median and p95 are given as ratios to that variant's own single-point solution.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from companion.errors import UserError
from companion.gnss.observations import GnssEpoch
from companion.gnss.systems import System
from gcs_tools.gnss.smartloc import SmartLocInput, Truth

Drive = tuple[SmartLocInput, Truth]
ROWS = ("cn0-elevation", "fde", "student-t", "second-order")
TIME_SHIFT_S = 1.0e9  # ~GPS seconds since 1980: stamps of that size instead of seconds from the start
GAP_S = 2.0
ISB_M = 40.0  # galileo-mix: the relabelled satellites' inter-system bias


def _with_epochs(data: SmartLocInput, epochs: Sequence[GnssEpoch], odometry: np.ndarray | None = None
                 ) -> SmartLocInput:
    if not epochs:
        raise UserError("a variant left no GNSS epoch")
    return dataclasses.replace(data, epochs=list(epochs),
                               odometry=data.odometry if odometry is None else odometry)


def keep_systems(drive: Drive, keep: Callable[[np.ndarray], np.ndarray]) -> Drive:
    """Each epoch restricted to the satellites where ``keep(system)``; epochs left empty dropped."""
    data, truth = drive
    eps = [e.select(keep(e.system)) for e in data.epochs]
    return _with_epochs(data, [e for e in eps if e.n]), truth


def gps_only(drive: Drive) -> Drive:
    return keep_systems(drive, lambda s: s == System.GPS)


def no_glonass(drive: Drive) -> Drive:
    return keep_systems(drive, lambda s: s != System.GLONASS)


def relabel_galileo(drive: Drive, isb_m: float = ISB_M) -> Drive:
    """The GPS satellites of odd PRN as Galileo ones, ``isb_m`` later (another system, its own receiver
    clock: a GPS + Galileo + … receiver's mix with the same geometry)."""
    data, truth = drive
    out = []
    for e in data.epochs:
        m = (e.system == System.GPS) & (e.prn % 2 == 1)
        out.append(e.replace(system=np.where(m, np.int8(System.GALILEO), e.system).astype(np.int8),
                             pseudorange_m=e.pseudorange_m + np.where(m, isb_m, 0.0)))
    return _with_epochs(data, out), truth


def decimate(drive: Drive, rate_hz: float = 1.0) -> Drive:
    """The first epoch of every 1/rate_hz interval, counted from the drive's first epoch."""
    data, truth = drive
    t0 = data.epochs[0].t_gps_s
    slot = [math.floor((e.t_gps_s - t0) * rate_hz + 1e-6) for e in data.epochs]
    keep = [e for i, e in enumerate(data.epochs) if i == 0 or slot[i] != slot[i - 1]]
    return _with_epochs(data, keep), truth


def cn0_offset(drive: Drive, offset_db: float) -> Drive:
    data, truth = drive
    return _with_epochs(data, [e.replace(cn0_dbhz=e.cn0_dbhz + offset_db) for e in data.epochs]), truth


def cn0_missing(drive: Drive) -> Drive:
    """No C/N0 reported (NaN): a receiver or format without it."""
    data, truth = drive
    return _with_epochs(data, [e.replace(cn0_dbhz=np.full(e.n, np.nan)) for e in data.epochs]), truth


def elevation_missing(drive: Drive) -> Drive:
    """No elevation column (NaN): the filters must compute their own."""
    data, truth = drive
    return _with_epochs(data, [e.replace(elevation_deg=np.full(e.n, np.nan)) for e in data.epochs]), truth


def variance_constant(drive: Drive) -> Drive:
    """Every given pseudorange variance replaced by the drive's median of them."""
    data, truth = drive
    v = float(np.nanmedian(np.concatenate([e.pseudorange_var_m2 for e in data.epochs])))
    return _with_epochs(data, [e.replace(pseudorange_var_m2=np.full(e.n, v)) for e in data.epochs]), truth


def variance_missing(drive: Drive) -> Drive:
    data, truth = drive
    eps = [e.replace(pseudorange_var_m2=np.full(e.n, np.nan)) for e in data.epochs]
    return _with_epochs(data, eps), truth


def time_window(drive: Drive, t_from_s: float, t_to_s: float) -> Drive:
    """Epochs and odometry in [t_from_s, t_to_s), the truth 1 s beyond either end."""
    data, truth = drive
    eps = [e for e in data.epochs if t_from_s <= e.t_gps_s < t_to_s]
    o = data.odometry
    odo = o[(o[:, 0] >= t_from_s) & (o[:, 0] < t_to_s)]
    m = (truth.t_s >= t_from_s - 1.0) & (truth.t_s < t_to_s + 1.0)
    return _with_epochs(data, eps, odo), Truth(truth.t_s[m], truth.p_ecef_m[m])


def _middle_s(drive: Drive) -> float:
    eps = drive[0].epochs
    return 0.5 * (eps[0].t_gps_s + eps[-1].t_gps_s)


def first_half(drive: Drive) -> Drive:
    return time_window(drive, -math.inf, _middle_s(drive))


def second_half(drive: Drive) -> Drive:
    return time_window(drive, _middle_s(drive), math.inf)


def no_odometry(drive: Drive) -> Drive:
    data, truth = drive
    return _with_epochs(data, data.epochs, np.zeros((0, 3))), truth


def no_speed(drive: Drive) -> Drive:
    """The odometry's yaw rate without its wheel speed (NaN): a car with a gyro and no speed sensor, as
    a drive with imu rows instead of odom3 gives (``gcs_tools.gnss.imu_yaw``)."""
    data, truth = drive
    return _with_epochs(data, data.epochs, data.odometry * [1.0, math.nan, 1.0]), truth


def odometry_rate(drive: Drive, rate_hz: float) -> Drive:
    """The odometry at ``rate_hz``: faster, its speed and yaw rate linearly interpolated onto that grid
    (another car's bus rate, the same signals); slower, the first sample of every 1/rate_hz interval."""
    data, truth = drive
    o = data.odometry
    if len(o) < 2:
        return drive
    t = o[:, 0]
    if rate_hz * float(np.median(np.diff(t))) > 1.0:
        grid = t[0] + np.arange(int(math.floor((t[-1] - t[0]) * rate_hz + 1e-9)) + 1) / rate_hz
        odo = np.column_stack([grid, np.interp(grid, t, o[:, 1]), np.interp(grid, t, o[:, 2])])
    else:
        slot = np.floor((t - t[0]) * rate_hz + 1e-6)
        odo = o[np.r_[True, np.diff(slot) != 0]]
    return _with_epochs(data, data.epochs, odo), truth


def gap(drive: Drive, start_s: float | None = None, length_s: float = GAP_S) -> Drive:
    """No GNSS epoch in [start, start + length) (default start: the drive's middle time)."""
    data, truth = drive
    t = _middle_s(drive) if start_s is None else start_s
    return _with_epochs(data, [e for e in data.epochs if not t <= e.t_gps_s < t + length_s]), truth


def time_shift(drive: Drive, shift_s: float = TIME_SHIFT_S) -> Drive:
    data, truth = drive
    eps = [e.replace(t_gps_s=e.t_gps_s + shift_s) for e in data.epochs]
    odo = data.odometry + np.array([shift_s, 0.0, 0.0])
    return _with_epochs(data, eps, odo), Truth(truth.t_s + shift_s, truth.p_ecef_m)


VARIANTS: dict[str, Callable[[Drive], Drive]] = {
    "baseline": lambda d: d,
    "gps-only": gps_only,
    "no-glonass": no_glonass,
    "galileo-mix": relabel_galileo,
    "1hz": decimate,
    "cn0-6": lambda d: cn0_offset(d, -6.0),  # any cn0±X (dB) is understood; these are the defaults
    "cn0-3": lambda d: cn0_offset(d, -3.0),
    "cn0+3": lambda d: cn0_offset(d, 3.0),
    "cn0-missing": cn0_missing,
    "el-missing": elevation_missing,
    "var-constant": variance_constant,
    "var-missing": variance_missing,
    "first-half": first_half,
    "second-half": second_half,
    "no-odometry": no_odometry,
    "no-speed": no_speed,
    "odo-50hz": lambda d: odometry_rate(d, 50.0),
    "odo-1hz": lambda d: odometry_rate(d, 1.0),
    "gap-2s": gap,
    "time-shift": time_shift,
}
DEFAULT = (*VARIANTS, "1hz+no-odometry", "cn0-6+no-odometry", "cn0+3+no-odometry", "gps-only+no-odometry")


def apply(name: str, drive: Drive) -> Drive:
    """The variant ``name`` (``a+b``: a, then b) of ``drive``; a UserError naming the known ones."""
    for part in parts(name):
        db = _cn0_db(part)
        drive = VARIANTS[part](drive) if db is None else cn0_offset(drive, db)
    return drive


def _cn0_db(part: str) -> float | None:
    """``cn0-6`` -> -6.0 (any signed offset in dB), else None."""
    if part.startswith(("cn0+", "cn0-")):
        try:
            return float(part[3:])
        except ValueError:
            return None
    return None


def parts(name: str) -> list[str]:
    """The variants ``name`` joins with ``+`` (``cn0+3+no-odometry``: [``cn0+3``, ``no-odometry``], the
    offset's sign is no join); a UserError naming the known ones."""
    if name.startswith("cn0+"):
        head, _, rest = name[4:].partition("+")
        out = ["cn0+" + head, *(rest.split("+") if rest else [])]
    else:
        out = name.split("+")
    for part in out:
        if part not in VARIANTS and _cn0_db(part) is None:
            raise UserError(f"unknown variant {part!r}: choose from {', '.join(VARIANTS)} (join with +)")
    return out


def run(input_path: Any, truth_path: Any, names: Sequence[str] = DEFAULT,
        rows: Sequence[str] = ROWS, progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    from companion.gnss.geometry import ecef_to_ned_matrix, geodetic_to_ecef
    from companion.gnss.spp import SppConfig
    from companion.tight import TightConfig
    from gcs_tools.evaluate.tight import _horizontal
    from gcs_tools.gnss import smartloc
    from gcs_tools.gnss import tight_replay as tr
    from gcs_tools.gnss.baseline import solve_series
    from gcs_tools.replay import core

    base = smartloc.read_drive(input_path, truth_path)
    for name in names:  # every name checked before the first replay
        parts(name)
    out: dict[str, Any] = {}
    for name in names:
        if progress is not None:
            progress(name)
        data, truth = apply(name, base)
        t_ep = np.array([e.t_gps_s for e in data.epochs])
        src = tr.SmartLocRawSource(data.epochs, data.odometry, truth.t_s, truth.p_ecef_m)
        home = src.anchor
        lat0, lon0 = math.radians(home.home_lat_deg), math.radians(home.home_lon_deg)
        r_ned = ecef_to_ned_matrix(lat0, lon0)
        p0 = geodetic_to_ecef(lat0, lon0, home.home_alt_m)
        truth_ned = (truth.at(t_ep) - p0) @ r_ned.T
        boot_s = np.array([src.boot_us(t) for t in t_ep]) * 1e-6
        errors: dict[str, np.ndarray] = {}
        series = solve_series(data.epochs, SppConfig())
        errors["spp"] = _horizontal((series.p_ecef_m - p0) @ r_ned.T, truth_ned)
        counts: dict[str, Any] = {}
        for w in rows:
            reader: Any = tr.SmartLocRawSource(data.epochs, data.odometry, truth.t_s, truth.p_ecef_m,
                                               len(data.odometry) > 0)  # (a raw reader: replay's as in tight)
            res = core.replay(input_path, w, home=home, reader=reader,
                              navigator=tr.tight_factory(TightConfig.for_ground_vehicle()), rate_hz=20.0)
            t = res.t_us * 1e-6
            est = np.column_stack([np.interp(boot_s, t, res.table[:, i], left=np.nan) for i in range(2)])
            errors[f"tight-{w}"] = _horizontal(est, truth_ned)
            counts[f"tight-{w}"] = int(res.summary["navigator"].get("gnss_resets", 0))
        ok = np.all([np.isfinite(e) for e in errors.values()], axis=0) & np.isfinite(truth_ned).all(axis=1)
        spp = errors["spp"][ok]
        sm, sp = float(np.median(spp)), float(np.percentile(spp, 95))
        out[name] = {"epochs": int(ok.sum()), "odometry": bool(len(data.odometry)),
                     "duration_s": float(t_ep[-1] - t_ep[0]),
                     "rows": {k: {"median_m": float(np.median(e[ok])),
                                  "p95_m": float(np.percentile(e[ok], 95)),
                                  "max_m": float(e[ok].max()),
                                  "median_ratio": float(np.median(e[ok])) / sm,
                                  "p95_ratio": float(np.percentile(e[ok], 95)) / sp,
                                  "gnss_resets": counts.get(k, 0)}
                              for k, e in errors.items()}}
    return {"data": {"input": Path(input_path).name}, "variants": out}


def markdown(r: dict[str, Any]) -> str:
    from gcs_tools.evaluate.tight import table_lines

    lines = [f"smartLoc {r['data']['input'].rsplit('/', 1)[-1]}: variants of the drive (gcs_tools.evaluate."
             "tight_variants); each scored on its own epochs, ratios to its own SPP.", ""]
    body = []
    for name, v in r["variants"].items():
        for row, s in v["rows"].items():
            body.append((name, str(v["epochs"]), row, f"{s['median_m']:.1f}", f"{s['p95_m']:.1f}",
                         f"{s['max_m']:.1f}", f"{s['median_ratio']:.2f}", f"{s['p95_ratio']:.2f}",
                         str(s["gnss_resets"]) if row != "spp" else ""))
    lines += table_lines(("variant", "epochs", "row", "median (m)", "p95 (m)", "max (m)", "median / SPP",
                          "p95 / SPP", "resets"), body)
    return "\n".join(lines) + "\n"
