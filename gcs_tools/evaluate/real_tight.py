"""What the real IMU gives the tightly coupled filter on the ANSFL flights under a smartLoc drive's sky.

    python -m gcs_tools.evaluate.real_tight --corpus ansfl/ --flights reporting \\
        --errors smartloc-sats:Berlin_Potsdamer_Platz_Input.txt --seeds 0-4 --gnss-velocity none --out DIR

``tight-second-order`` (``TightConfig()``, no map) replayed as ``evaluate.real`` replays it
(``transplant.sky_on_flight``: the drive's per-satellite residuals placed on the flight's truth, arriving
with the fixes), with the flight's IMU changed per *variant* (``VARIANTS``): as recorded; its attitude
turned by the flight's fitted heading error (``clock_alignment.yaw_deg``); the IMU's process noise
changed; no IMU at all (a level, zero-acceleration input and ``TightConfig.for_ground_vehicle()``: the
GNSS-only white-acceleration model of the smartLoc car); and each with error-free pseudoranges
(``-clean``: the residuals × 0, what the IMU path alone costs). Per run, against the RTK truth: the
horizontal error (median, p95, max, and the median over 0-10 s, 10-20 s and after 20 s from the
filter's start), the horizontal velocity error (RMS) against the truth's central differences and the
filter's own σ, and the horizontal NEES of velocity and position (a consistent filter: 2).

Two measurements without a filter variant:

* ``drift``: the IMU's own horizontal velocity dead reckoning against the truth over horizons of 0.5-10 s
  (the truth's velocity at t₀ plus the integrated IMU acceleration, minus the truth's at t₀ + T; RMS
  per axis), beside what ``TightConfig()``'s process model allows (its white acceleration and its two
  acceleration error priors, per axis);
* ``placement``: on the drive itself, over exactly the windows the flights read (their seed-drawn start
  and span), the single-point solution's errors, the drive's GNSS-only tight filter run over the
  whole drive (as ``evaluate.tight`` runs it) and that filter started afresh at each window's start
  (as a flight starts it).
"""

from __future__ import annotations

import argparse
import functools
import math
import sys
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from companion.errors import UserError
from gcs_tools.choices import seeds as parse_seeds

ROW = "second-order"
HORIZONS_S = (0.5, 1.0, 2.0, 5.0, 10.0)
TIME_BINS_S = ((0.0, 10.0), (10.0, 20.0), (20.0, math.inf))
METRICS = ("median", "p95", "max", "median_0_10", "median_10_20", "median_20_end", "velocity_error_rms",
           "velocity_sigma_rms", "nees_velocity", "nees_position")


def _tight(**over: Any) -> Any:
    from companion.tight import TightConfig

    return TightConfig(**over)


def _ground(**over: Any) -> Any:
    from companion.tight import TightConfig

    return TightConfig.for_ground_vehicle(**over)


# name -> (IMU input: "imu" as recorded, "heading" its attitude turned by the fitted heading error,
# "level" none; the config; error-free pseudoranges)
VARIANTS: dict[str, tuple[str, Callable[[], Any], bool]] = {
    "imu": ("imu", _tight, False),
    "imu-heading": ("heading", _tight, False),
    # the process noise doubled / at the dead reckoning measured on the tuning flights (``drift``)
    "imu-noise-x2": ("imu", functools.partial(_tight, sigma_acc_m_s2=0.6, sigma_acc_vertical_m_s2=0.6,
                                              sigma_acc_bias0_m_s2=0.4, sigma_acc_ned0_m_s2=0.4), False),
    "imu-noise-measured": ("imu", functools.partial(_tight, sigma_acc_m_s2=0.15, sigma_acc_bias0_m_s2=0.1,
                                                    sigma_acc_ned0_m_s2=0.1), False),
    "gnss-only": ("level", _ground, False),
    "imu-clean": ("imu", _tight, True),
    "gnss-only-clean": ("level", _ground, True),
}
DEFAULT_VARIANTS = ("imu", "imu-heading", "imu-noise-x2", "imu-noise-measured", "gnss-only", "imu-clean",
                    "gnss-only-clean")


class ImuVariant:
    """A log reader whose IMU is ``mode``: "imu" as is, "heading" every attitude turned about down by
    ``yaw_deg`` (the rotation that turns the IMU's horizontal acceleration onto the truth's), "level" a
    level attitude and a zero acceleration (specific force −g on z, no rotation)."""

    def __init__(self, inner: Any, mode: str, yaw_deg: float = 0.0, gravity_m_s2: float = 9.80665) -> None:
        if mode not in ("imu", "heading", "level"):
            raise ValueError(f"IMU mode {mode!r}")
        self.inner, self.mode = inner, mode
        self.format, self.stats, self.sources = inner.format, inner.stats, dict(inner.sources)
        self.references = inner.references
        self.anchor = getattr(inner, "anchor", None)
        self.clock = getattr(inner, "clock", None)
        half = math.radians(yaw_deg) / 2.0
        self._q_yaw = np.array([math.cos(half), 0.0, 0.0, math.sin(half)])  # about NED's down axis
        self._g = gravity_m_s2
        if mode == "level":
            self.sources["imu"] = "none (zero acceleration, level: the constant-velocity model)"
            self.sources["attitude"] = "none (level)"

    def first_fix(self) -> Any:
        return None

    def describe_empty(self) -> str:
        return str(self.inner.describe_empty())

    def __iter__(self) -> Iterator[Any]:
        from companion.domain.samples import AttitudeSample, ImuSample

        level, acc0, gyro0 = np.array([1.0, 0.0, 0.0, 0.0]), np.array([0.0, 0.0, -self._g]), np.zeros(3)
        for ev in self.inner:
            kind = type(ev)
            if kind is AttitudeSample and self.mode != "imu":
                q = level if self.mode == "level" else quat_mul(self._q_yaw, ev.q_ned_frd)
                yield AttitudeSample(ev.t_us, q)
            elif kind is ImuSample and self.mode == "level":
                yield ImuSample(ev.t_us, acc0, gyro0)
            else:
                yield ev


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a ⊗ b of (w, x, y, z) quaternions."""
    w1, x1, y1, z1 = (float(v) for v in a)
    w2, x2, y2, z2 = (float(v) for v in b)
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def nees(err: np.ndarray, var: np.ndarray) -> np.ndarray:
    """Per row Σ e² / σ² over the columns (the covariance's diagonal only)."""
    return np.sum(np.asarray(err) ** 2 / np.asarray(var), axis=1)


def against_truth(t_us: np.ndarray, table: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    """The replay's estimate rows (``core.ReplayResult``) against its 10 Hz truth track (t_s, n, e, d, ...):
    the horizontal metrics of ``METRICS`` over the truth samples inside the estimate's span."""
    from gcs_tools.replay.core import CSV_COLUMNS

    col = {c: i for i, c in enumerate(CSV_COLUMNS[1:])}
    t_est = t_us * 1e-6
    t_tr, p_tr = truth[:, 0], truth[:, 1:3]
    v_tr = np.gradient(p_tr, t_tr, axis=0)
    keep = (t_tr >= t_est[0]) & (t_tr <= t_est[-1])

    def at(*names: str) -> np.ndarray:
        return np.column_stack([np.interp(t_tr[keep], t_est, table[:, col[n]]) for n in names])

    e_p = at("p_n_m", "p_e_m") - p_tr[keep]
    e_v = at("v_n_m_s", "v_e_m_s") - v_tr[keep]
    var_p, var_v = at("var_p_n_m2", "var_p_e_m2"), at("var_v_n_m2_s2", "var_v_e_m2_s2")
    h = np.hypot(e_p[:, 0], e_p[:, 1])
    since = t_tr[keep] - t_est[0]
    out = {"median": float(np.median(h)), "p95": float(np.percentile(h, 95)), "max": float(np.max(h))}
    for (a, b), name in zip(TIME_BINS_S, ("median_0_10", "median_10_20", "median_20_end"), strict=True):
        m = (since >= a) & (since < b)
        out[name] = float(np.median(h[m])) if m.any() else math.nan
    out.update(velocity_error_rms=float(np.sqrt(np.mean(np.sum(e_v**2, axis=1)))),
               velocity_sigma_rms=float(np.sqrt(np.mean(np.sum(var_v, axis=1)))),
               nees_velocity=float(np.mean(nees(e_v, var_v))), nees_position=float(np.mean(nees(e_p, var_p))))
    return out


_SKIES: dict[Path, Any] = {}


def _sky(errors: str) -> Any:
    from gcs_tools.gnss import transplant

    path = transplant.check_choice(errors)
    if path not in _SKIES:
        _SKIES[path] = transplant.drive_sky(path)
    return _SKIES[path]


def _placed(flight: Path, sky: Any, seed: int, velocity: float | None, clean: bool) -> Any:
    """``transplant.sky_on_flight`` as ``evaluate.real`` calls it (5 Hz, the latency model's process);
    ``clean``: the residuals × 0 (error-free pseudoranges)."""
    from gcs_tools.gnss import transplant
    from gcs_tools.replay.synthetic_gnss import GnssErrorOptions

    opts = GnssErrorOptions("none", rate_hz=5.0, accuracy="reported", latency_ms=None, seed=seed,
                            velocity_std_m_s=velocity)
    if not clean:
        return transplant.sky_on_flight(flight, sky, opts)
    place = transplant.place
    transplant.place = functools.partial(place, residual_scale=0.0)
    try:
        return transplant.sky_on_flight(flight, sky, opts)
    finally:
        transplant.place = place


def run_variant(flight: Path, errors: str, seed: int, variant: str, velocity: float | None, row: str = ROW
                ) -> dict[str, Any]:
    """One replay of ``tight-<row>`` (default: the belief per satellite) on ``flight`` with the IMU of
    ``variant``."""
    from gcs_tools.gnss import tight_replay as tr
    from gcs_tools.gnss import transplant
    from gcs_tools.replay import core

    mode, make_config, clean = VARIANTS[variant]
    sky = _sky(errors)
    placed = _placed(flight, sky, seed, velocity, clean)
    inner = transplant.on_drive_frame(flight, None, sky)
    yaw = float(getattr(inner, "clock", {}).get("yaw_deg", 0.0))
    raw: Any = transplant.placed_raw_reader(ImuVariant(inner, mode, yaw), placed, sky.name)
    res = core.replay(flight, row, home=placed.frame, reader=raw, rate_hz=10.0,
                      navigator=tr.tight_factory(make_config()))
    nav = res.summary["navigator"]
    return {"flight": flight.name, "seed": seed, "variant": variant, "heading_error_deg": -yaw,
            **against_truth(res.t_us, res.table, res.tracks["truth"]),
            "sat_used": nav.get("sat_used", 0), "sat_rejected": nav.get("sat_rejected", 0),
            "gnss_resets": nav.get("gnss_resets", 0)}


def model_velocity_sigma(T_s: float, white: float, bias0: float, ned0: float) -> float:
    """Per axis: the white acceleration's random walk and two constant acceleration errors (the body bias's
    and the NED error's priors), independent, integrated over ``T_s``."""
    return math.sqrt(white**2 * T_s + (bias0**2 + ned0**2) * T_s**2)


def dead_reckoning(flight: Path, horizons: Sequence[float] = HORIZONS_S, lag_s: float = 0.2
                   ) -> dict[float, np.ndarray]:
    """Per horizon T: the horizontal velocity errors (k, 2) of the IMU's dead reckoning from the truth's
    velocity at t₀ (every 0.5 s) to t₀ + T against the truth's, the truth's velocity by central differences
    over ± ``lag_s``."""
    from gcs_tools.replay.ansfl import IMU_FILE, TRUTH_FILE, load_flight

    fl = load_flight(flight / IMU_FILE, flight / TRUTH_FILE)
    t, a = fl.t_s, fl.a_ned_m_s2()[:, :2]
    dv = np.vstack([np.zeros((1, 2)), np.cumsum(0.5 * (a[1:] + a[:-1]) * np.diff(t)[:, None], axis=0)])
    tt, p = fl.t_truth_s, fl.p_truth_ned_m[:, :2]
    k = max(1, int(round(lag_s / float(np.median(np.diff(tt))))))
    tv, v = tt[k:-k], (p[2 * k:] - p[:-2 * k]) / (tt[2 * k:] - tt[:-2 * k])[:, None]

    def interp(x: np.ndarray, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
        return np.column_stack([np.interp(x, xs, ys[:, i]) for i in range(ys.shape[1])])

    out = {}
    lo, hi = max(tv[0], t[0]), min(tv[-1], t[-1])
    for T in horizons:
        t0 = np.arange(lo, hi - T, 0.5)
        out[T] = interp(t0, tv, v) + interp(t0 + T, t, dv) - interp(t0, t, dv) - interp(t0 + T, tv, v)
    return out


def placement(errors: str, flights: Sequence[Path], seeds: Sequence[int]) -> list[dict[str, Any]]:
    """Per flight × seed: the drive's window the flight reads, and over it the single-point solution's and the
    drive's GNSS-only tight filter's horizontal errors (over the whole drive, and started at the window)."""
    from companion.gnss.geometry import ecef_to_ned_matrix, geodetic_to_ecef
    from companion.gnss.spp import SppConfig
    from gcs_tools.gnss import smartloc, transplant
    from gcs_tools.gnss import tight_replay as tr
    from gcs_tools.gnss.baseline import solve_series
    from gcs_tools.replay import core

    path = transplant.check_choice(errors)
    data, truth = smartloc.read_drive(path, None)
    t_ep = np.array([e.t_gps_s for e in data.epochs])
    home = tr.SmartLocRawSource(data.epochs, data.odometry, truth.t_s, truth.p_ecef_m, False).anchor
    lat, lon = math.radians(home.home_lat_deg), math.radians(home.home_lon_deg)
    R, p0 = ecef_to_ned_matrix(lat, lon), geodetic_to_ecef(lat, lon, home.home_alt_m)
    true_ne = ((truth.at(t_ep) - p0) @ R.T)[:, :2]
    spp = ((solve_series(data.epochs, SppConfig()).p_ecef_m - p0) @ R.T)[:, :2]
    e_spp = np.hypot(*(spp - true_ne).T)

    def gnss_only(sel: np.ndarray) -> np.ndarray:
        epochs = [data.epochs[i] for i in np.flatnonzero(sel)]
        src: Any = tr.SmartLocRawSource(epochs, data.odometry, truth.t_s, truth.p_ecef_m, False)
        src.anchor = home
        res = core.replay(path, ROW, home=home, reader=src, rate_hz=20.0,
                          navigator=tr.tight_factory(_ground()))
        boot = np.array([src.boot_us(t) for t in t_ep[sel]]) * 1e-6
        t_est = res.t_us * 1e-6
        est = np.column_stack([np.interp(boot, t_est, res.table[:, i], left=np.nan) for i in range(2)])
        return np.hypot(*(est - true_ne[sel]).T)

    whole = gnss_only(np.ones(len(t_ep), dtype=bool))
    sky = _sky(errors)
    out = [{"window": "whole drive", **_stats(e_spp, "spp"), **_stats(whole, "drive_whole")}]
    for flight in flights:
        for seed in seeds:
            pl = _placed(flight, sky, seed, None, False).placed
            span = (pl.t_validity_us[-1] - pl.t_validity_us[0]) * 1e-6
            sel = (t_ep >= pl.start_s - 1e-6) & (t_ep <= pl.start_s + span + 1e-6)
            since = t_ep[sel] - t_ep[sel][0]
            row = {"flight": flight.name, "seed": seed, "start_s": float(pl.start_s - t_ep[0]),
                   "span_s": float(span)}
            for name, e in (("spp", e_spp[sel]), ("drive_whole", whole[sel]), ("drive_restarted",
                                                                                gnss_only(sel))):
                row.update(_stats(e, name, since))
            out.append(row)
    return out


def _stats(e: np.ndarray, name: str, since: np.ndarray | None = None) -> dict[str, float]:
    out = {f"{name}_median": float(np.nanmedian(e)), f"{name}_p95": float(np.nanpercentile(e, 95))}
    if since is not None:
        for (a, b), tag in zip(TIME_BINS_S, ("0_10", "10_20", "20_end"), strict=True):
            m = (since >= a) & (since < b)
            out[f"{name}_median_{tag}"] = float(np.nanmedian(e[m])) if m.any() else math.nan
    return out


def _mean(rows: Sequence[dict[str, Any]], key: str) -> float:
    vals = [r[key] for r in rows if key in r and np.isfinite(r[key])]
    return float(np.mean(vals)) if vals else math.nan


def markdown(result: dict[str, Any]) -> str:
    lines = [f"# {result.get('row', 'tight-' + ROW)} on real IMU flights: {result['errors']}", "",
             f"Flights {', '.join(result['flights'])}, seeds {result['seeds']}, velocity: "
             f"{result['velocity']}. Means over runs (flight × seed); NEES horizontal (consistent: 2).", "",
             "| variant | median | p95 | max | median 0-10 s | 10-20 s | after 20 s | velocity error RMS "
             "[m/s] | its σ | NEES v | NEES p |", "|---" * 11 + "|"]
    for v in result["variants"]:
        rows = [r for r in result["runs"] if r["variant"] == v]
        lines.append(f"| {v} | " + " | ".join(f"{_mean(rows, k):.2f}" for k in METRICS) + " |")
    if result.get("drift"):
        d = result["drift"]
        model = ", ".join(f"{T:g} s {s:.2f}" for T, s in zip(d["horizons_s"], d["model_m_s"], strict=True))
        lines += ["", "IMU dead reckoning of the horizontal velocity against the truth, RMS per axis [m/s] "
                  f"(`TightConfig()`'s process model: {model}):",
                  "", "| flight | " + " | ".join(f"{T:g} s" for T in d["horizons_s"]) + " |",
                  "|---" * (len(d["horizons_s"]) + 1) + "|"]
        for name, rms in d["rms_m_s"].items():
            lines.append(f"| {name} | " + " | ".join(f"{x:.2f}" for x in rms) + " |")
    if result.get("placement"):
        pl = result["placement"]
        w = [r for r in pl if "flight" in r]
        lines += ["", f"On the drive itself: whole drive single-point {pl[0]['spp_median']:.2f} / "
                  f"{pl[0]['spp_p95']:.2f} m, GNSS-only tight {pl[0]['drive_whole_median']:.2f} / "
                  f"{pl[0]['drive_whole_p95']:.2f} m (median / p95); over the flights' windows (means):", "",
                  "| on the windows | median | p95 | median 0-10 s | 10-20 s | after 20 s |",
                  "|---" * 6 + "|"]
        for name, label in (("spp", "single-point"),
                            ("drive_whole", "GNSS-only tight, run over the whole drive"),
                            ("drive_restarted", "GNSS-only tight, started at the window")):
            lines.append(f"| {label} | " + " | ".join(f"{_mean(w, f'{name}_{k}'):.2f}" for k in (
                "median", "p95", "median_0_10", "median_10_20", "median_20_end")) + " |")
    return "\n".join(lines)


def _rounded(x: Any) -> Any:
    if isinstance(x, float):
        return round(x, 4) if math.isfinite(x) else None
    if isinstance(x, dict):
        return {k: _rounded(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_rounded(v) for v in x]
    return x


def write_results(out: Path, result: dict[str, Any]) -> None:
    """``out/results.json`` (numbers to 4 decimals, one compact line per run) and ``out/report.md``."""
    from gcs_tools.evaluate.real import write_outputs

    rounded = _rounded(result)
    write_outputs(out, {k: v for k, v in rounded.items() if k != "runs"}, rounded["runs"], markdown(result))


def main(argv: Sequence[str] | None = None) -> int:
    from gcs_tools.evaluate.real import flight_dirs
    from gcs_tools.gnss.transplant import PREFIX
    from gcs_tools.outdir import check_out_dir, ensure_out_dir
    from gcs_tools.replay.synthetic_gnss import velocity_option

    p = argparse.ArgumentParser(prog="python -m gcs_tools.evaluate.real_tight",
                                description=__doc__.split("\n")[0], allow_abbrev=False)
    p.add_argument("--corpus", type=Path, default=None, help="the ANSFL directory (path_1, path_2, ...)")
    p.add_argument("--flights", default="reporting",
                   help="reporting (paths 5,6,7,8,10), tuning (1,2,3), all, or flight names/paths")
    p.add_argument("--errors", required=True, help=f"{PREFIX}INPUT: a smartLoc drive's satellites")
    p.add_argument("--seeds", default="0-4")
    p.add_argument("--gnss-velocity", default="none", metavar="STD_M_S|none",
                   help="synthetic Doppler of the fixes' velocity information (default: none)")
    p.add_argument("--variants", default=",".join(DEFAULT_VARIANTS),
                   help=f"comma-separated of {', '.join(VARIANTS)}")
    p.add_argument("--row", default=ROW, help=f"the tight filter's weighting (default {ROW})")
    p.add_argument("--no-placement", action="store_true", help="skip the drive-window measurement")
    p.add_argument("--out", type=Path, default=Path("runs/real_tight"))
    args = p.parse_args(argv)
    try:
        check_out_dir(args.out)
        if not args.errors.startswith(PREFIX):
            raise UserError(f"--errors {args.errors!r}: give {PREFIX}INPUT (a smartLoc *_Input.txt)")
        variants = [v.strip() for v in args.variants.split(",") if v.strip()]
        unknown = [v for v in variants if v not in VARIANTS]
        if unknown or not variants:
            raise UserError(f"--variants {args.variants!r}: choose from {', '.join(VARIANTS)}")
        _, flights = flight_dirs(args.corpus, args.flights)
        seeds = parse_seeds(args.seeds)
        velocity = velocity_option(args.gnss_velocity)
        _sky(args.errors)
        from gcs_tools.evaluate.tight import TIGHT_ROWS

        if args.row not in TIGHT_ROWS:
            raise UserError(f"--row {args.row!r}: choose from {', '.join(TIGHT_ROWS)}")
        runs = [run_variant(f, args.errors, s, v, velocity, args.row)
                for v in variants for f in flights for s in seeds]
        white, bias0, ned0 = (getattr(_tight(), k) for k in ("sigma_acc_m_s2", "sigma_acc_bias0_m_s2",
                                                               "sigma_acc_ned0_m_s2"))
        rms: dict[str, list[float]] = {}
        model = [model_velocity_sigma(T, white, bias0, ned0) for T in HORIZONS_S]
        drift = {"horizons_s": list(HORIZONS_S), "model_m_s": model, "rms_m_s": rms}
        pooled: dict[float, list[np.ndarray]] = {T: [] for T in HORIZONS_S}
        for f in flights:
            dr = dead_reckoning(f)
            rms[f.name] = [float(np.sqrt(np.mean(dr[T] ** 2))) for T in HORIZONS_S]
            for T in HORIZONS_S:
                pooled[T].append(dr[T])
        rms["pooled"] = [float(np.sqrt(np.mean(np.vstack(pooled[T]) ** 2))) for T in HORIZONS_S]
        result = {"row": f"tight-{args.row}", "errors": args.errors.removeprefix(PREFIX).rsplit("/", 1)[-1],
                  "flights": [f.name for f in flights], "seeds": list(seeds),
                  "velocity": "none" if velocity is None else f"synthetic Doppler ({velocity} m/s)",
                  "variants": variants, "drift": drift,
                  "placement": None if args.no_placement else placement(args.errors, flights, seeds),
                  "runs": runs}
        out = ensure_out_dir(args.out)
    except UserError as exc:
        print(f"real_tight: error: {exc}", file=sys.stderr)
        return 2
    write_results(out, result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
