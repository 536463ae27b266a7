"""The single-point baseline against truth: per-epoch solutions, errors in a local NED frame and
the statistics that characterise real urban GNSS (distribution, steps, correlation time, residuals
at the true position by elevation and system, reported vs actual accuracy). Pure numpy on arrays;
the CSV writer is the only I/O."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from companion.domain.statistics import describe
from companion.gnss.constants import C_M_S
from companion.gnss.geometry import ecef_to_geodetic, ecef_to_ned_matrix
from companion.gnss.observations import GnssEpoch
from companion.gnss.spp import SppConfig, SppSolution, geometry_at, sigma_model_m, solve_position
from companion.gnss.systems import SHORT_NAME, System

ERROR_CSV_HEADER = "t_s,err_n_m,err_e_m,err_d_m,h_acc_m,v_acc_m"
ELEVATION_BINS_DEG = (0.0, 15.0, 30.0, 50.0, 90.01)
THRESHOLD_M = 5.0
ACF_GRID_S = 0.1


@dataclass
class SppSeries:
    """Solutions of a sequence of epochs (all epochs; ``ok`` marks those with a solution)."""

    t_s: np.ndarray  # (n,) epoch times (the epochs' own time base)
    p_ecef_m: np.ndarray  # (n, 3) NaN without a solution
    h_acc_m: np.ndarray  # (n,)
    v_acc_m: np.ndarray
    ok: np.ndarray  # (n,) bool
    n_used: np.ndarray  # (n,) int
    n_excluded: np.ndarray  # (n,) RAIM exclusions
    hdop: np.ndarray
    solutions: list[SppSolution]


def solve_series(
    epochs: Sequence[GnssEpoch], config: SppConfig, klobuchar: tuple[np.ndarray, np.ndarray] | None = None
) -> SppSeries:
    """Solve every epoch, each starting from the previous solution (the Earth's centre at first)."""
    sols: list[SppSolution] = []
    prev: np.ndarray | None = None
    for e in epochs:
        s = solve_position(e, config, p0_ecef_m=prev, klobuchar=klobuchar)
        if s.ok:
            prev = s.p_ecef_m
        sols.append(s)
    return SppSeries(
        np.array([s.t_gps_s for s in sols]),
        np.array([s.p_ecef_m for s in sols]).reshape(-1, 3),
        np.array([s.h_acc_m for s in sols]),
        np.array([s.v_acc_m for s in sols]),
        np.array([s.ok for s in sols], dtype=bool),
        np.array([s.n_used for s in sols]),
        np.array([int(s.excluded.sum()) for s in sols]),
        np.array([s.dops.hdop for s in sols]),
        sols,
    )


def ned_errors(p_ecef_m: np.ndarray, truth_ecef_m: np.ndarray, origin_ecef_m: np.ndarray) -> np.ndarray:
    """(n, 3) position − truth in the NED frame tangent at ``origin_ecef_m``."""
    lat, lon, _ = (float(v) for v in ecef_to_geodetic(origin_ecef_m))
    return (p_ecef_m - truth_ecef_m) @ ecef_to_ned_matrix(lat, lon).T


def correlation_time_s(t_s: np.ndarray, x: np.ndarray, max_lag_s: float = 60.0) -> float:
    """Lag (s) where the autocorrelation of the demeaned series, resampled on a 0.1 s grid, first
    falls below 1/e (NaN if it never does within ``max_lag_s``)."""
    ok = np.isfinite(x)
    t, x = t_s[ok], x[ok]
    if len(t) < 10:
        return math.nan
    grid = np.arange(t[0], t[-1], ACF_GRID_S)
    y = np.interp(grid, t, x)
    y = y - y.mean()
    var = float(np.dot(y, y))
    if var <= 0:
        return math.nan
    n = len(y)
    f = np.fft.rfft(y, 2 * n)
    acf = np.fft.irfft(f * np.conj(f))[:n] / var
    below = np.nonzero(acf[: int(max_lag_s / ACF_GRID_S)] < math.exp(-1.0))[0]
    return float(below[0] * ACF_GRID_S) if len(below) else math.nan


def _quantiles(v: np.ndarray) -> dict[str, float]:
    return describe(v, ("median", "p95", "mean", "n"))


def error_statistics(
    t_s: np.ndarray, err_ned_m: np.ndarray, h_acc_m: np.ndarray, v_acc_m: np.ndarray
) -> dict[str, object]:
    """Horizontal/vertical error distribution, % above 5 m, epoch-to-epoch steps, correlation
    times and reported vs actual accuracy (RMS actual / RMS reported; > 1 = optimistic)."""
    ok = np.isfinite(err_ned_m).all(axis=1)
    e, t = err_ned_m[ok], t_s[ok]
    h = np.hypot(e[:, 0], e[:, 1])
    steps = np.hypot(*np.diff(e[:, :2], axis=0).T) if len(e) > 1 else np.zeros(0)
    ha, va = h_acc_m[ok], v_acc_m[ok]
    good = np.isfinite(ha) & (ha > 0)
    h_ratio = (
        math.sqrt(float(np.mean(h[good] ** 2) / np.mean(2.0 * ha[good] ** 2))) if good.any() else math.nan
    )
    vgood = np.isfinite(va) & (va > 0)
    v_ratio = (
        math.sqrt(float(np.mean(e[vgood, 2] ** 2) / np.mean(va[vgood] ** 2))) if vgood.any() else math.nan
    )
    return {
        "epochs": int(len(e)),
        "horizontal_m": _quantiles(h),
        "vertical_abs_m": _quantiles(np.abs(e[:, 2])),
        "mean_ned_m": [float(v) for v in e.mean(axis=0)] if len(e) else [math.nan] * 3,
        "percent_above_5m": float(100.0 * np.mean(h > THRESHOLD_M)) if len(h) else math.nan,
        "step_horizontal_m": _quantiles(steps),
        "correlation_time_s": {
            "north": correlation_time_s(t, e[:, 0]),
            "east": correlation_time_s(t, e[:, 1]),
            "down": correlation_time_s(t, e[:, 2]),
        },
        "reported_h_acc_m": _quantiles(ha),
        "accuracy_ratio_horizontal": h_ratio,
        "accuracy_ratio_vertical": v_ratio,
    }


def residuals_at_truth(
    epochs: Sequence[GnssEpoch],
    truth_ecef_m: np.ndarray,
    config: SppConfig,
    klobuchar: tuple[np.ndarray, np.ndarray] | None = None,
) -> dict[str, dict[str, dict[str, float]]]:
    """Pseudorange residuals at the TRUE position, by system and elevation bin (median, p95, n).

    Raw pseudoranges (RINEX, UBX) first lose the atmosphere the solution models (``config.tropo``:
    Saastamoinen; ``config.iono`` with ``klobuchar``), as corrected ones (smartLoc) already have.
    Per epoch and system the receiver clock is the weighted mean (the SPP's σ model at the true
    elevations) of ``y − ρ(truth) − atmosphere``; a system with a single satellite that epoch is
    left out (its residual would be zero by construction). Positive = the signal arrived late (NLOS,
    multipath) or the atmosphere models fell short."""
    res: list[np.ndarray] = []
    el_all: list[np.ndarray] = []
    sys_all: list[np.ndarray] = []
    for e, p in zip(epochs, truth_ecef_m, strict=True):
        if not np.isfinite(p).all():
            continue
        y = e.pseudorange_m if e.corrected else e.pseudorange_m + C_M_S * e.sat_clock_s
        geo = geometry_at(e, p, config, klobuchar)
        el = geo.el
        w = 1.0 / sigma_model_m(e, el, config) ** 2
        d = y - geo.rho - geo.atm
        r = np.full(e.n, np.nan)
        for s in np.unique(e.system):
            m = (e.system == s) & np.isfinite(d)
            if m.sum() >= 2:
                r[m] = d[m] - np.sum(w[m] * d[m]) / np.sum(w[m])
        res.append(r)
        el_all.append(np.rad2deg(el))
        sys_all.append(e.system)
    if not res:
        return {}

    def stat(v: np.ndarray) -> dict[str, float]:
        q = _quantiles(v)
        return {"median": q["median"], "p95": q["p95"], "n": q["n"]}

    return by_system_and_elevation(np.concatenate(sys_all), np.concatenate(el_all), np.concatenate(res), stat)


CLOCK_ELEVATION_DEG = 40.0  # the receiver clock at the truth: from the satellites above this elevation


@dataclass(frozen=True)
class TruthResiduals:
    """One epoch's observations at the TRUE position (arrays (n,))."""

    residual_m: np.ndarray  # pseudorange − Sagnac range − the system's clock; + = arrived late (NLOS)
    clock_m: np.ndarray  # the receiver clock of each observation's system (m)
    los_ecef: np.ndarray  # (n, 3) unit vectors receiver → satellite
    elevation_deg: np.ndarray


def epoch_residuals_at_truth(
    epoch: GnssEpoch,
    p_ecef_m: np.ndarray,
    config: SppConfig | None = None,
    klobuchar: tuple[np.ndarray, np.ndarray] | None = None,
) -> TruthResiduals:
    """Each observation's residual at the true position ``p_ecef_m``: pseudorange − |sat − p| (Sagnac)
    − the receiver clock of its system, taken robustly as the MEDIAN of ``pseudorange − range`` over that
    system's satellites above ``CLOCK_ELEVATION_DEG`` (high satellites are rarely reflected; the median
    ignores the few that are), over all of that system's satellites when none is that high.

    The model is the solution's (``spp.geometry_at``): raw pseudoranges (RINEX, UBX) first lose the
    atmosphere it takes off (``config``, default ``SppConfig()``: ``tropo`` Saastamoinen, ``iono`` Klobuchar
    with ``klobuchar``), as corrected ones (smartLoc) already have; else a clean low signal shows metres
    of "late" residual."""
    y = epoch.pseudorange_m if epoch.corrected else epoch.pseudorange_m + C_M_S * epoch.sat_clock_s
    geo = geometry_at(epoch, p_ecef_m, config or SppConfig(), klobuchar)
    el = np.degrees(geo.el)
    d = y - geo.rho - geo.atm
    clock = np.full(epoch.n, np.nan)
    for s in np.unique(epoch.system):
        m = epoch.system == s
        hi = m & (el > CLOCK_ELEVATION_DEG)
        clock[m] = np.median(d[hi] if hi.sum() else d[m])
    return TruthResiduals(d - clock, clock, geo.los, el)


def by_system_and_elevation(system: np.ndarray, el_deg: np.ndarray, values: np.ndarray,
                            stat: Callable[[np.ndarray], dict[str, float]]
                            ) -> dict[str, dict[str, dict[str, float]]]:
    """``stat`` of the finite ``values`` per system (``SHORT_NAME``) and ``ELEVATION_BINS_DEG`` band
    (keys "lo-hi deg", the top band to 90)."""
    out: dict[str, dict[str, dict[str, float]]] = {}
    for s in np.unique(system):
        name = SHORT_NAME[System(int(s))]
        out[name] = {}
        for lo, hi in zip(ELEVATION_BINS_DEG[:-1], ELEVATION_BINS_DEG[1:], strict=True):
            m = (system == s) & (el_deg >= lo) & (el_deg < hi) & np.isfinite(values)
            out[name][f"{lo:g}-{min(hi, 90):g}deg"] = stat(values[m])
    return out


def write_error_csv(
    path: Path, t_s: np.ndarray, err_ned_m: np.ndarray, h_acc_m: np.ndarray, v_acc_m: np.ndarray
) -> int:
    """``t_s,err_n_m,err_e_m,err_d_m,h_acc_m,v_acc_m``; t from the first row; an epoch without a
    solution is left out; unknown accuracies are empty fields. Returns the number of rows."""
    ok = np.isfinite(err_ned_m).all(axis=1)
    t0 = float(t_s[ok][0]) if ok.any() else 0.0
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", encoding="ascii") as f:
        f.write(ERROR_CSV_HEADER + "\n")
        for t, e, ha, va in zip(t_s[ok], err_ned_m[ok], h_acc_m[ok], v_acc_m[ok], strict=True):
            acc = ",".join(f"{a:.3f}" if math.isfinite(a) else "" for a in (ha, va))
            f.write(f"{t - t0:.3f},{e[0]:.3f},{e[1]:.3f},{e[2]:.3f},{acc}\n")
    return int(ok.sum())
