"""``python -m gcs_tools.evaluate.tight --smartloc INPUT --out DIR``: the tight-coupling ablation.

Rows, all on the same receiver epochs and scored the same way (horizontal distance to the truth at
every epoch time; filter rows through the real replay, ``gcs_tools.replay.core.replay``, their
20 Hz estimates interpolated to the epoch times):

* ``spp``: the single-point solution (C/N0 + elevation weights), what a receiver gives;
* ``loose``: those fixes into today's loosely coupled filter (second-order belief);
* ``tight-<row>``: the tightly coupled filter with each weighting of ``companion.tight.WEIGHTINGS``
  (``naive`` fixed weights, ``cn0-elevation``, ``fde``, ``student-t``, ``first-order``,
  ``second-order`` per-satellite belief), with the car's odometry (speed, yaw rate);
* ``tight-<row>-no-odometry``: the same on GNSS alone (constant velocity) for the main rows.

Intervals: the drive is one run whose errors are correlated for 3-30 s, so epochs are not
independent. We use a moving-block bootstrap over time: the epoch series is cut into overlapping
blocks of ``--block-s`` seconds (default 20 s, ~100 epochs), ``--resamples`` resamples draw
⌈n / block⌉ block starts uniformly (seeded) and concatenate them; every row is resampled with the
SAME blocks, so differences between rows are paired. Reported: the median and p95 of each row with
95 % percentile intervals, and paired differences (row − reference) of the median and the p95.

Beside: the per-satellite belief against each observation's residual at the true position (the
per-system receiver clock taken as the median residual of that system's satellites above 40°,
else of all of them), so one sees β_s fall for reflected signals and stay high for clean ones.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from companion.errors import UserError
from companion.gnss.geometry import ecef_to_ned_matrix
from companion.gnss.spp import SppConfig
from companion.tight import TightConfig
from gcs_tools.gnss.baseline import epoch_residuals_at_truth
from gcs_tools.jsonvalues import write_results_or_error

TIGHT_ROWS = ("naive", "cn0-elevation", "fde", "student-t", "first-order", "second-order")
NO_ODOMETRY_ROWS = ("cn0-elevation", "student-t", "second-order")
REFERENCES = ("spp", "loose", "tight-naive", "tight-cn0-elevation", "tight-fde", "tight-student-t")
BELIEF_ROW = "tight-second-order"
RESIDUAL_BINS_M = (-math.inf, -10.0, -5.0, 5.0, 10.0, 20.0, 40.0, math.inf)
# --sensitivity: the belief row with each of these TightConfig fields halved and doubled, and with the
# odometry perturbed
SENSITIVITY = ("eta", "student_dof", "prior_weight", "sigma_zenith_m", "r_inflation_max", "sigma_acc_m_s2",
               "belief_early_factor", "belief_sigma_scale")


def block_indices(n: int, block: int, rng: np.random.Generator, n_resamples: int) -> np.ndarray:
    """(n_resamples, n) indices of a moving-block bootstrap (blocks of ``block`` consecutive epochs)."""
    block = max(1, min(block, n))
    k = math.ceil(n / block)
    starts = rng.integers(0, n - block + 1, size=(n_resamples, k))
    idx = (starts[:, :, None] + np.arange(block)[None, None, :]).reshape(n_resamples, -1)
    return idx[:, :n]


def _summary(e: np.ndarray) -> dict[str, float]:
    e = e[np.isfinite(e)]
    return {"median_m": float(np.median(e)), "p95_m": float(np.percentile(e, 95)), "max_m": float(e.max())}


def _interval(v: np.ndarray) -> list[float]:
    lo, hi = np.percentile(v, [2.5, 97.5])
    return [float(lo), float(hi)]


def row_statistics(errors: dict[str, np.ndarray], idx: np.ndarray) -> dict[str, dict[str, Any]]:
    out = {}
    for name, e in errors.items():
        r = e[idx]
        med, p95 = np.median(r, axis=1), np.percentile(r, 95, axis=1)
        out[name] = {"n": int(e.size), "median_m": float(np.median(e)), "median_ci_m": _interval(med),
                     "p95_m": float(np.percentile(e, 95)), "p95_ci_m": _interval(p95),
                     "max_m": float(e.max()), "over_5m": float(np.mean(e > 5.0))}
    return out


def paired(errors: dict[str, np.ndarray], row: str, reference: str, idx: np.ndarray) -> dict[str, Any]:
    a, b = errors[row][idx], errors[reference][idx]
    dm = np.median(a, axis=1) - np.median(b, axis=1)
    dp = np.percentile(a, 95, axis=1) - np.percentile(b, 95, axis=1)
    return {"row": row, "reference": reference,
            "median_diff_m": float(np.median(errors[row]) - np.median(errors[reference])),
            "median_diff_ci_m": _interval(dm),
            "p95_diff_m": float(np.percentile(errors[row], 95) - np.percentile(errors[reference], 95)),
            "p95_diff_ci_m": _interval(dp)}


def _horizontal(est_ned: np.ndarray, truth_ned: np.ndarray) -> np.ndarray:
    return np.hypot(est_ned[:, 0] - truth_ned[:, 0], est_ned[:, 1] - truth_ned[:, 1])


class _EpochLog:
    """Collects the per-satellite beliefs of a TightNavigator's epochs (replay's on_imu hook)."""

    def __init__(self) -> None:
        self.rows: list[tuple[int, Any]] = []
        self._seen: set[int] = set()

    def __call__(self, t_us: int, nav: Any) -> None:
        entries = getattr(getattr(nav, "engine", None), "entries", None)
        if not entries:
            return
        e = entries[-1]
        if e.info.key is not None and e.t_us not in self._seen:
            self._seen.add(e.t_us)
            self.rows.append((e.t_us, e.info))


def run(input_path: Path, truth_path: Path | None, seed: int = 0, block_s: float = 20.0,
        n_resamples: int = 2000, rows: Sequence[str] = TIGHT_ROWS,
        progress: Callable[[str], None] | None = None, sensitivity: bool = False,
        loose: bool = True, no_odometry: bool = True) -> dict[str, Any]:
    from gcs_tools.gnss import smartloc
    from gcs_tools.gnss import tight_replay as tr
    from gcs_tools.gnss.baseline import solve_series
    from gcs_tools.gnss.replay import smartloc_source
    from gcs_tools.replay import core

    data, truth = smartloc.read_drive(input_path, truth_path)
    t_ep = np.array([e.t_gps_s for e in data.epochs])
    truth_ecef = truth.at(t_ep)
    ok = np.isfinite(truth_ecef).all(axis=1)
    src = tr.SmartLocRawSource(data.epochs, data.odometry, truth.t_s, truth.p_ecef_m)
    home = src.anchor
    lat0, lon0 = math.radians(home.home_lat_deg), math.radians(home.home_lon_deg)
    r_ned = ecef_to_ned_matrix(lat0, lon0)
    from companion.gnss.geometry import geodetic_to_ecef

    p0 = geodetic_to_ecef(lat0, lon0, home.home_alt_m)
    truth_ned = (truth_ecef - p0) @ r_ned.T
    boot_s = np.array([src.boot_us(t) for t in t_ep]) * 1e-6
    errors: dict[str, np.ndarray] = {}
    timing: dict[str, float] = {}
    resets: dict[str, int] = {}  # per filter row: its resets to the GNSS (the state lost and restarted)

    def say(msg: str) -> None:
        if progress is not None:
            progress(msg)

    series = solve_series(data.epochs, SppConfig())
    spp_ned = (series.p_ecef_m - p0) @ r_ned.T
    errors["spp"] = _horizontal(spp_ned, truth_ned)

    def replay_row(name: str, reader: Any, navigator: Any, method: str, hook: Any = None) -> None:
        say(name)
        res = core.replay(input_path, method, home=home, reader=reader, navigator=navigator, on_imu=hook,
                          rate_hz=20.0)
        t = res.t_us * 1e-6
        est = np.column_stack([np.interp(boot_s, t, res.table[:, i], left=np.nan) for i in range(2)])
        errors[name] = _horizontal(est, truth_ned)
        timing[name] = float(res.summary["realtime_factor"])
        resets[name] = int(res.summary["navigator"].get("gnss_resets", 0))

    if loose:
        replay_row("loose", smartloc_source(input_path, truth_path, SppConfig()), None, "second-order")
    belief_log = _EpochLog()
    for odometry in (True, False) if no_odometry else (True,):
        for w in rows:
            if not odometry and w not in NO_ODOMETRY_ROWS:
                continue
            name = f"tight-{w}" + ("" if odometry else "-no-odometry")
            reader = tr.SmartLocRawSource(data.epochs, data.odometry, truth.t_s, truth.p_ecef_m, odometry,
                                          odometry_source=data.odometry_source)
            cfg = TightConfig.for_ground_vehicle()
            hook = belief_log if name == BELIEF_ROW else None
            replay_row(name, reader, tr.tight_factory(cfg), w, hook)
    sens: dict[str, dict[str, float]] = {}
    if sensitivity:
        base = TightConfig.for_ground_vehicle()
        for field in SENSITIVITY:
            for factor in (0.5, 2.0):
                name = f"{field} x{factor:g}"
                cfg = TightConfig.for_ground_vehicle(**{field: getattr(base, field) * factor})
                reader = tr.SmartLocRawSource(data.epochs, data.odometry, truth.t_s, truth.p_ecef_m)
                replay_row(name, reader, tr.tight_factory(cfg), "second-order")
                sens[name] = _summary(errors.pop(name)[ok])
        # the odometry of another car: a yaw-rate bias the vehicle did not zero, a wheel-radius error
        for name, scale, bias_deg_s in (("odometry yaw rate +0.2 deg/s", 1.0, 0.2),
                                        ("odometry yaw rate +0.5 deg/s", 1.0, 0.5),
                                        ("odometry speed x1.03", 1.03, 0.0)):
            odo = data.odometry * [1.0, scale, 1.0] + [0.0, 0.0, math.radians(bias_deg_s)]
            reader = tr.SmartLocRawSource(data.epochs, odo, truth.t_s, truth.p_ecef_m)
            cfg = TightConfig.for_ground_vehicle()
            replay_row(name, reader, tr.tight_factory(cfg), "second-order")
            sens[name] = _summary(errors.pop(name)[ok])
    keep = ok & np.all([np.isfinite(e) for e in errors.values()], axis=0)
    errors = {k: v[keep] for k, v in errors.items()}
    rng = np.random.default_rng(seed)
    block = max(1, int(round(block_s / float(np.median(np.diff(t_ep))))))
    idx = block_indices(int(keep.sum()), block, rng, n_resamples)
    stats = row_statistics(errors, idx)
    comparisons = [paired(errors, BELIEF_ROW, ref, idx) for ref in REFERENCES if ref in errors]
    if "tight-second-order-no-odometry" in errors:
        comparisons += [paired(errors, "tight-second-order-no-odometry", ref, idx)
                        for ref in ("spp", "loose", "tight-cn0-elevation-no-odometry",
                                    "tight-student-t-no-odometry") if ref in errors]
    spp = stats["spp"]
    goals = {name: {"median_ratio_to_spp": s["median_m"] / spp["median_m"],
                    "p95_ratio_to_spp": s["p95_m"] / spp["p95_m"]} for name, s in stats.items()}
    return {
        "data": {"input": Path(input_path).name, "epochs": int(keep.sum()),
                 "duration_s": float(t_ep[-1] - t_ep[0]), "odometry": data.odometry_source},
        "method": {"score": "horizontal distance to truth at every epoch time",
                   "bootstrap": f"moving blocks of {block} epochs ({block_s:g} s), {n_resamples} resamples, "
                                f"seed {seed}, the same blocks for every row (paired)"},
        "rows": stats, "paired": comparisons, "goals": goals, "realtime_factor": timing,
        "resets": {k: v for k, v in resets.items() if k in stats},
        "belief_vs_residual": belief_vs_residual(data.epochs, truth, belief_log.rows, src),
        "sensitivity": sens,
    }


class Observations(NamedTuple):
    """Per observation of the logged epochs (arrays (n,)): boot time, satellite key, its residual at the
    true position (m), the belief's β and pre-fit innovation y (m), whether it was used, C/N0, elevation."""

    t_us: np.ndarray
    key: np.ndarray
    residual_m: np.ndarray
    beta: np.ndarray
    y_m: np.ndarray
    used: np.ndarray
    cn0_dbhz: np.ndarray
    elevation_deg: np.ndarray


def observations_at_truth(epochs: Sequence[Any], truth: Any, log: Sequence[tuple[int, Any]], src: Any
                          ) -> Observations:
    """Each logged observation's residual at the true position (``baseline.epoch_residuals_at_truth``:
    the per-system receiver clock as the median residual of that system's satellites above 40°, else of
    all of them); with what the filter's epoch (``log``: (t_us, EpochInfo)) said of it."""
    by_t = {src.boot_us(e.t_gps_s): e for e in epochs}
    rows: list[tuple[float, ...]] = []
    for t_us, info in log:
        e = by_t.get(t_us)
        if e is None:
            continue
        p = truth.at(np.array([e.t_gps_s]))[0]
        if not np.isfinite(p).all():
            continue
        at_truth = epoch_residuals_at_truth(e, p)
        r, el = at_truth.residual_m, at_truth.elevation_deg
        key = e.system.astype(int) * 1000 + e.prn.astype(int)
        pos = {k: i for i, k in enumerate(key.tolist())}
        for k, b, y, u in zip(info.key.tolist(), info.beta.tolist(), info.y_m.tolist(), info.used.tolist(),
                              strict=True):
            if k in pos:
                i = pos[k]
                rows.append((t_us, k, r[i], b, y, float(u), e.cn0_dbhz[i], el[i]))
    a = np.array(rows, dtype=float).reshape(-1, 8)
    return Observations(a[:, 0].astype(np.int64), a[:, 1].astype(np.int64), a[:, 2], a[:, 3], a[:, 4],
                        a[:, 5] > 0.5, a[:, 6], a[:, 7])


def belief_vs_residual(epochs: Sequence[Any], truth: Any, log: Sequence[tuple[int, Any]], src: Any
                       ) -> list[dict[str, Any]]:
    """Median β of the observations in each bin of their residual at the true position."""
    obs = observations_at_truth(epochs, truth, log, src)
    res, beta = obs.residual_m, obs.beta
    out = []
    for lo, hi in zip(RESIDUAL_BINS_M[:-1], RESIDUAL_BINS_M[1:], strict=True):
        m = (res >= lo) & (res < hi)
        if m.any():
            out.append({"residual_from_m": lo, "residual_to_m": hi, "n": int(m.sum()),
                        "beta_median": float(np.median(beta[m])),
                        "beta_p25": float(np.percentile(beta[m], 25)),
                        "beta_p75": float(np.percentile(beta[m], 75))})
    return out


def table_lines(head: Sequence[str], rows: Iterable[Sequence[str]]) -> list[str]:
    """A markdown table: the header, its rule and one line per row of cells."""
    return ["| " + " | ".join(head) + " |", "| " + " | ".join("---" for _ in head) + " |",
            *("| " + " | ".join(row) + " |" for row in rows)]


def markdown(r: dict[str, Any]) -> str:
    def ci(v: list[float]) -> str:
        return f"[{v[0]:.1f}, {v[1]:.1f}]"

    lines = [f"smartLoc {Path(r['data']['input']).name}: {r['data']['epochs']} epochs, "
             f"{r['data']['duration_s']:.0f} s, odometry: {r['data'].get('odometry', 'odom3')}; "
             f"{r['method']['score']}; "
             f"intervals: {r['method']['bootstrap']}.", ""]
    goals = r["goals"]
    lines += table_lines(
        ("row", "median (m)", "95 % CI", "p95 (m)", "95 % CI", "max (m)", "median / SPP", "p95 / SPP"),
        ((name, f"{s['median_m']:.1f}", ci(s["median_ci_m"]), f"{s['p95_m']:.1f}", ci(s["p95_ci_m"]),
          f"{s['max_m']:.1f}", f"{goals[name]['median_ratio_to_spp']:.2f}",
          f"{goals[name]['p95_ratio_to_spp']:.2f}") for name, s in r["rows"].items()))
    reset = {k: v for k, v in r.get("resets", {}).items() if v}
    lines += ["", "Resets to the GNSS (a filter row that lost its state): "
              + (", ".join(f"{k} {v}" for k, v in reset.items()) if reset else "none") + "."]
    lines += ["", *table_lines(
        ("paired difference", "median (m)", "95 % CI", "p95 (m)", "95 % CI"),
        ((f"{c['row']} − {c['reference']}", f"{c['median_diff_m']:+.1f}", ci(c["median_diff_ci_m"]),
          f"{c['p95_diff_m']:+.1f}", ci(c["p95_diff_ci_m"])) for c in r["paired"]))]
    lines += ["", *table_lines(
        ("residual at the true position (m)", "observations", "β median", "β p25-p75"),
        ((f"{b['residual_from_m']:g} to {b['residual_to_m']:g}", str(b["n"]), f"{b['beta_median']:.2f}",
          f"{b['beta_p25']:.2f}-{b['beta_p75']:.2f}") for b in r["belief_vs_residual"]))]
    if r.get("sensitivity"):
        lines += ["", *table_lines(
            ("tight-second-order with", "median (m)", "p95 (m)", "max (m)"),
            ((name, f"{s['median_m']:.1f}", f"{s['p95_m']:.1f}", f"{s['max_m']:.1f}")
             for name, s in r["sensitivity"].items()))]
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(allow_abbrev=False, prog="python -m gcs_tools.evaluate.tight",
                                description=(__doc__ or "").splitlines()[0])
    p.add_argument("--smartloc", type=Path, required=True, metavar="INPUT", help="smartLoc *_Input.txt")
    p.add_argument("--truth", type=Path, default=None, help="smartLoc *_GT.txt (default: beside INPUT)")
    p.add_argument("--out", type=Path, default=Path("runs/tight-smartloc"))
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--block-s", type=float, default=20.0)
    p.add_argument("--resamples", type=int, default=2000)
    p.add_argument("--sensitivity", action="store_true",
                   help="also the belief row with each main parameter halved and doubled, and with "
                        "a biased odometry")
    p.add_argument("--variants", nargs="?", const="default", default=None, metavar="NAMES",
                   help="in place of the ablation: the filter on variants of the drive (comma-separated, "
                        "+ composes; default: all, gcs_tools.evaluate.tight_variants)")
    args = p.parse_args(argv)

    def compute() -> dict[str, Any]:
        if not args.smartloc.is_file():
            raise UserError(f"{args.smartloc}: no such file")
        if not (args.block_s > 0 and args.resamples >= 100):
            raise UserError("--block-s must be > 0 and --resamples >= 100")
        return run(args.smartloc, args.truth, args.seed, args.block_s, args.resamples,
                   progress=lambda m: print(f"  {m}", flush=True), sensitivity=args.sensitivity)

    def compute_variants() -> dict[str, Any]:
        from gcs_tools.evaluate import tight_variants as tv

        if not args.smartloc.is_file():
            raise UserError(f"{args.smartloc}: no such file")
        names = tv.DEFAULT if args.variants == "default" else tuple(args.variants.split(","))
        return tv.run(args.smartloc, args.truth, names, progress=lambda m: print(f"  {m}", flush=True))

    if args.variants is not None:
        from gcs_tools.evaluate.tight_variants import markdown as variants_markdown

        code = write_results_or_error(args.out, compute_variants, variants_markdown)
    else:
        code = write_results_or_error(args.out, compute, markdown)
    if code == 0:
        print(f"wrote {args.out / 'results.json'} and {args.out / 'results.md'}")
    return code

if __name__ == "__main__":
    raise SystemExit(main())
