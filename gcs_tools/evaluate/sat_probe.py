"""``python -m gcs_tools.evaluate.sat_probe``: what the per-satellite belief sees, against the truth.

    python -m gcs_tools.evaluate.sat_probe [--mission default-tuning] [--profiles 0,1,2,3]
        [--seeds 1000,1001] [--smartloc INPUT] [--out DIR]

**Calibrated canyon** (``canyon`` scenario; the simulated receiver knows, per satellite and epoch, whether
the tracked signal is a reflection and its range error from the city, ``SatTruth``): each flight is flown
as ``tight_sim`` flies it, with the ``second-order`` (belief) and ``fde`` rows, no map; every observation
of every epoch is kept with its β, pre-fit innovation y, C/N0, elevation, whether each row used it, and
its truth. **smartLoc** (no NLOS flag in the format): the truth is each observation's residual at the
true position (``tight.observations_at_truth``: the per-system clock as the median residual of the
satellites above 40°).

Reported (``probe_stats``):

* how well each score tells a bad observation (NLOS; |error| above 10 m) from a good one, as the area
  under the ROC curve (0.5: chance, 1: perfect): 1 − β, −C/N0, −elevation, |y|; and the FDE row's
  exclusion as a detector (its true and false positive rates);
* per error bin: β and the variance the belief fuses with over the σ model's (the single-point solution's
  C/N0 + elevation variance, which the baseline rows fuse with): ``belief_sigma_scale``² · k^(1 − β);
* how the errors persist: each satellite's error autocorrelation time (first lag below 1/e), the NLOS
  episodes' durations (canyon), and how fast β reacts to an NLOS onset (the first epoch at which β is
  0.1 below its value before the onset);
* the common mode: the epoch's median error (what a receiver clock absorbs) against its spread.

Nothing here changes a filter: the probe only reads.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import rankdata

from companion.errors import UserError
from gcs_tools import choices
from gcs_tools.evaluate import tuning
from gcs_tools.evaluate.nlos_probe import _correlation_time
from gcs_tools.evaluate.tight import table_lines
from gcs_tools.jsonvalues import write_results_or_error

ERROR_BINS_M = (-math.inf, -5.0, 5.0, 10.0, 20.0, 40.0, math.inf)
BAD_M = 10.0  # "a bad observation": |error| above this
DT_S = 0.2  # the receivers' epoch interval (5 Hz)


def auc(bad: np.ndarray, score: np.ndarray) -> float:
    """Area under the ROC curve of ``score`` (higher = more suspect) as a detector of ``bad`` (Mann-Whitney
    U over the pairs, ties counted half); NaN without both classes."""
    bad = np.asarray(bad, dtype=bool)
    n1, n0 = int(bad.sum()), int((~bad).sum())
    if not n1 or not n0:
        return math.nan
    r = rankdata(score)
    return float((r[bad].sum() - n1 * (n1 + 1) / 2.0) / (n1 * n0))


def probe_stats(t_us: np.ndarray, key: np.ndarray, error_m: np.ndarray, beta: np.ndarray, y_m: np.ndarray,
                cn0_dbhz: np.ndarray, elevation_deg: np.ndarray, k_inflation: float, r_scale: float = 1.0,
                nlos: np.ndarray | None = None, fde_used: np.ndarray | None = None) -> dict[str, Any]:
    """The statistics of the module doc from per-observation arrays ((n,) each; ``error_m`` the truth:
    the simulator's range error from the city, or the residual at the true position); the belief's R is
    ``r_scale`` · ``k_inflation``^(1 − β) times the σ model's variance."""
    labels = {f"|error| > {BAD_M:g} m": np.abs(error_m) > BAD_M}
    if nlos is not None:
        labels = {"NLOS": nlos, **labels}
    scores = {"1 - beta": 1.0 - beta, "-C/N0": -cn0_dbhz, "-elevation": -elevation_deg, "|y|": np.abs(y_m)}
    detect = {}
    for name, lab in labels.items():
        d: dict[str, float] = {s: auc(lab, v) for s, v in scores.items()}
        if fde_used is not None:
            d["fde TPR"] = float(np.mean(~fde_used[lab]))
            d["fde FPR"] = float(np.mean(~fde_used[~lab]))
        detect[name] = d
    bins = []
    for lo, hi in zip(ERROR_BINS_M[:-1], ERROR_BINS_M[1:], strict=True):
        m = (error_m >= lo) & (error_m < hi)
        if m.any():
            bins.append({"from_m": lo, "to_m": hi, "n": int(m.sum()),
                         "beta_median": float(np.median(beta[m])),
                         "r_over_model_median": float(np.median(r_scale * k_inflation ** (1.0 - beta[m]))),
                         "abs_y_median_m": float(np.median(np.abs(y_m[m])))})
    corr, episodes, lags = [], [], []
    for k in np.unique(key):
        s = np.flatnonzero(key == k)
        s = s[np.argsort(t_us[s], kind="stable")]
        if len(s) >= 100:
            c = _correlation_time(error_m[s], DT_S)
            if math.isfinite(c):
                corr.append(c)
        if nlos is None:
            continue
        on = nlos[s]
        for i in np.flatnonzero(on[1:] & ~on[:-1]) + 1:
            j = i
            while j < len(s) and on[j]:
                j += 1
            episodes.append(DT_S * (j - i))
            if np.median(error_m[s[i:j]]) > BAD_M:
                drop = np.flatnonzero(beta[s[i:j]] < beta[s[i - 1]] - 0.1)
                lags.append(DT_S * drop[0] if drop.size else math.nan)
    epoch_median, epoch_spread = [], []
    for t in np.unique(t_us):
        e = error_m[t_us == t]
        if len(e) >= 5:
            epoch_median.append(float(np.median(e)))
            epoch_spread.append(float(np.std(e)))
    def median(v: Sequence[float]) -> float:
        return float(np.median(v)) if len(v) else math.nan

    out: dict[str, Any] = {"observations": int(len(error_m)), "detection_auc": detect, "by_error": bins,
                           "correlation_time_s_median": median(corr),
                           "correlation_time_s_p25_p75": [float(v) for v in np.percentile(corr, [25, 75])]
                           if corr else [math.nan, math.nan],
                           "epoch_median_error_m": median(epoch_median),
                           "epoch_spread_m": median(epoch_spread)}
    if nlos is not None:
        ep = np.asarray(episodes)
        lag = np.asarray(lags)
        out.update(nlos_fraction=float(nlos.mean()), nlos_episode_s_median=float(np.median(ep)),
                   nlos_episode_s_time_weighted_median=float(np.median(np.repeat(ep, np.rint(ep / DT_S)
                                                                                 .astype(int)))),
                   onset_beta_drop_fraction=float(np.mean(np.isfinite(lag))),
                   onset_beta_drop_lag_s_median=median(lag[np.isfinite(lag)]))
    return out


def canyon(mission: str, profiles: Sequence[int], seeds: Sequence[int], max_duration_s: float | None = None
           ) -> dict[str, Any]:
    """``probe_stats`` over the flights' observations (the belief and the FDE rows, no map)."""
    from companion.tight import TightConfig
    from gcs_tools.evaluate.tight_sim import fly_rows

    rec: dict[str, list[tuple[float, ...]]] = {"second-order": [], "fde": []}
    done: list[tuple[int, int]] = []  # the flights flown (the current one's index: its length)

    def on_raw(row: str, raw: Any, nav: Any) -> None:
        e = nav.engine.entries[-1] if nav.engine.entries else None
        if e is None or e.t_us != raw.t_us or e.info.key is None:
            return  # not fused (yet): a late epoch re-fused later is not counted twice
        ep, tr = raw.epoch, raw.truth
        row_of = {k: i for i, k in enumerate((ep.system.astype(int) * 1000 + ep.prn.astype(int)).tolist())}
        flight = float(len(done))
        for k, b, y, u in zip(e.info.key.tolist(), e.info.beta.tolist(), e.info.y_m.tolist(),
                              e.info.used.tolist(), strict=True):
            i = row_of[k]
            rec[row].append((flight, raw.t_us, k, b, y, float(u), ep.cn0_dbhz[i], ep.elevation_deg[i],
                             tr.env_error_m[i], float(tr.nlos[i])))

    for p in profiles:
        for s in seeds:
            fly_rows(mission, p, s, tuple(rec), max_duration_s, maps=False, on_raw=on_raw)
            done.append((p, s))
    a, f = (np.array(rec[r], dtype=float).reshape(-1, 10) for r in ("second-order", "fde"))
    fde_used = {(int(r[0]), int(r[1]), int(r[2])): r[5] > 0.5 for r in f}
    ids = [(int(r[0]), int(r[1]), int(r[2])) for r in a]
    keep = np.array([i in fde_used for i in ids], dtype=bool)
    a = a[keep]
    used_fde = np.array([fde_used[i] for i, k in zip(ids, keep, strict=True) if k], dtype=bool)
    # a satellite of another flight is another series: the flight goes into the key
    key = a[:, 0].astype(np.int64) * 1_000_000 + a[:, 2].astype(np.int64)
    t_us = a[:, 0].astype(np.int64) * 10**13 + a[:, 1].astype(np.int64)
    cfg = TightConfig()
    stats = probe_stats(t_us, key, a[:, 8], a[:, 3], a[:, 4], a[:, 6], a[:, 7], cfg.r_inflation_max,
                        cfg.belief_sigma_scale**2, a[:, 9] > 0.5, used_fde)
    return {"mission": mission, "profiles": list(profiles), "seeds": list(seeds), **stats}


def smartloc(input_path: Path) -> dict[str, Any]:
    """``probe_stats`` of smartLoc's observations (the belief row with odometry; FDE's exclusions)."""
    from companion.tight import TightConfig
    from gcs_tools.evaluate.tight import _EpochLog, observations_at_truth
    from gcs_tools.gnss import smartloc as sl
    from gcs_tools.gnss import tight_replay as tr
    from gcs_tools.replay import core

    data, truth = sl.read_drive(input_path, None)
    cfg = TightConfig.for_ground_vehicle()
    obs = {}
    for row in ("second-order", "fde"):
        src: Any = tr.SmartLocRawSource(data.epochs, data.odometry, truth.t_s, truth.p_ecef_m)  # a LogReader
        log = _EpochLog()
        core.replay(input_path, row, home=src.anchor, reader=src, on_imu=log, rate_hz=20.0,
                    navigator=tr.tight_factory(cfg))
        obs[row] = observations_at_truth(data.epochs, truth, log.rows, src)
    o, f = obs["second-order"], obs["fde"]
    fde_used = dict(zip(zip(f.t_us.tolist(), f.key.tolist(), strict=True), f.used.tolist(), strict=True))
    pairs = list(zip(o.t_us.tolist(), o.key.tolist(), strict=True))
    keep = np.array([p in fde_used for p in pairs], dtype=bool) & np.isfinite(o.residual_m)
    used = np.array([fde_used.get(p, True) for p in pairs], dtype=bool)
    return {"input": input_path.name, **probe_stats(
        o.t_us[keep], o.key[keep], o.residual_m[keep], o.beta[keep], o.y_m[keep], o.cn0_dbhz[keep],
        o.elevation_deg[keep], cfg.r_inflation_max, cfg.belief_sigma_scale**2, None, used[keep])}


def markdown(r: dict[str, Any]) -> str:
    lines: list[str] = []
    for name, s in r.items():
        lo, hi = s["correlation_time_s_p25_p75"]
        lines += [f"## {name}", "", f"{s['observations']} observations; error autocorrelation time per "
                  f"satellite median {s['correlation_time_s_median']:.1f} s (p25-p75 {lo:.1f}-{hi:.1f}); "
                  f"epoch median error {s['epoch_median_error_m']:.1f} m, "
                  f"spread {s['epoch_spread_m']:.1f} m.",
                  ""]
        if "nlos_fraction" in s:
            lines += [f"NLOS {s['nlos_fraction']:.1%} of observations; episodes "
                      f"{s['nlos_episode_s_median']:.1f} s median "
                      f"({s['nlos_episode_s_time_weighted_median']:.1f} s time-weighted); β drops by 0.1 in "
                      f"{s['onset_beta_drop_fraction']:.0%} of the episodes above {BAD_M:g} m, after "
                      f"{s['onset_beta_drop_lag_s_median']:.1f} s (median).", ""]
        cols = list(next(iter(s["detection_auc"].values())))
        lines += table_lines(("bad observation", *cols),
                             ((lab, *(f"{d[c]:.3f}" for c in cols)) for lab, d in s["detection_auc"].items()))
        by_error = ((f"{b['from_m']:g} to {b['to_m']:g}", str(b["n"]), f"{b['beta_median']:.2f}",
                     f"{b['r_over_model_median']:.2f}", f"{b['abs_y_median_m']:.1f}") for b in s["by_error"])
        head = ("error (m)", "n", "β median", "R / σ model's median", "|y| median (m)")
        lines += ["", *table_lines(head, by_error), ""]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(allow_abbrev=False, prog="python -m gcs_tools.evaluate.sat_probe",
                                description=(__doc__ or "").splitlines()[0])
    p.add_argument("--mission", default=tuning.TUNING_MISSION)
    p.add_argument("--profiles", default="0,1,2,3")
    p.add_argument("--seeds", default="1000,1001")
    p.add_argument("--smartloc", type=Path, default=None, metavar="INPUT", help="smartLoc *_Input.txt")
    p.add_argument("--out", type=Path, default=Path("runs/sat-probe"))
    args = p.parse_args(argv)

    def compute() -> dict[str, Any]:
        profiles = choices.seeds(args.profiles, "--profiles") if args.profiles else ()
        seeds = choices.seeds(args.seeds) if args.seeds else ()
        if args.smartloc is not None and not args.smartloc.is_file():
            raise UserError(f"{args.smartloc}: no such file")
        r: dict[str, Any] = {}
        if profiles and seeds:
            r["canyon"] = canyon(args.mission, profiles, seeds)
        if args.smartloc is not None:
            r["smartloc"] = smartloc(args.smartloc)
        return r

    return write_results_or_error(args.out, compute, markdown)

if __name__ == "__main__":
    raise SystemExit(main())
