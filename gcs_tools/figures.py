"""Figures shared by ``fly``, SITL, ``plot`` and the evaluation (matplotlib, Agg; files only)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402

from gcs_tools import palette  # noqa: E402

DPI = 110


def draw_world(ax: Any, world: Any) -> None:
    """Buildings as grey rectangles, east on x and north on y (``world.rects_m`` rows n0, e0, n1, e1)."""
    for n0, e0, n1, e1 in np.asarray(world.rects_m, dtype=float):
        ax.add_patch(Rectangle((e0, n0), e1 - e0, n1 - n0, facecolor=palette.quantity("building"),
                               edgecolor="0.4", lw=0.6))
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")


def draw_route_marks(ax: Any, waypoints_ned_m: np.ndarray, label: bool = True, vertices: bool = True) -> None:
    """Planned path (dashed), start (square) and goal (star), each with a legend entry when ``label``."""
    wp = np.asarray(waypoints_ned_m).reshape(-1, 3)
    if not len(wp):  # a recording may hold no route
        return
    colour = palette.quantity("reference")
    ax.plot(wp[:, 1], wp[:, 0], color=colour, ls="--", lw=1.0, marker="o" if vertices else None, ms=2.5,
            label="planned path" if label else None)
    ax.plot(wp[0, 1], wp[0, 0], "s", color="k", ms=6, ls="none", label="start" if label else None)
    ax.plot(wp[-1, 1], wp[-1, 0], "*", color="k", ms=11, ls="none", label="goal" if label else None)


def _error_track(ax: Any, p_ned_m: np.ndarray, error_m: np.ndarray, norm: Any, lw: float) -> Any:
    """The estimated track coloured by its error (a LineCollection); returns it for a colour bar."""
    from matplotlib.collections import LineCollection

    xy = np.column_stack([p_ned_m[:, 1], p_ned_m[:, 0]])
    segs = np.stack([xy[:-1], xy[1:]], axis=1)
    err = np.asarray(error_m, dtype=float)[1:]
    ok = np.isfinite(segs).all(axis=(1, 2)) & np.isfinite(err)
    lines = LineCollection(list(segs[ok]), cmap=ERROR_CMAP, norm=norm, lw=lw, zorder=3)
    lines.set_array(err[ok])
    ax.add_collection(lines)
    return lines


ERROR_CMAP = "plasma"  # estimation error along the track: dark = small, yellow = large
ZOOM_HALF_M = 6.0  # the zoom panel shows at least +-6 m about the largest error


def map_figure(path: Path, world: Any, waypoints_ned_m: np.ndarray, tracks: dict[str, np.ndarray],
               title: str = "", fixes_ned_m: np.ndarray | None = None, rejected: np.ndarray | None = None,
               error_m: np.ndarray | None = None) -> None:
    """The city with the planned path and NED tracks (label -> (N, 3)); a label's colour is its
    meaning ("true", "estimated", ... in :mod:`gcs_tools.palette`). With ``error_m`` (N,) the
    estimated track is coloured by its estimation error, and a second panel zooms to where that
    error was largest (a city-scale map cannot show a 1 m error). ``fixes_ned_m`` (K, 3): the GNSS
    fixes the filter received, ``rejected`` (K,) those its innovation gate refused (red crosses)."""
    est = tracks.get("estimated")
    err = None if error_m is None or est is None else np.asarray(error_m, dtype=float)
    zoom = err is not None and bool(np.isfinite(err).any())
    fig, axes = plt.subplots(1, 2 if zoom else 1, figsize=(11.5 if zoom else 6.4, 6.0), squeeze=False,
                             width_ratios=(1.25, 1) if zoom else None)
    ax = axes[0, 0]
    fixes = np.zeros((0, 3)) if fixes_ned_m is None else np.asarray(fixes_ned_m, dtype=float).reshape(-1, 3)
    bad = np.zeros(len(fixes), bool) if rejected is None else np.asarray(rejected, dtype=bool)
    norm = None
    if zoom:
        from matplotlib.colors import Normalize

        assert err is not None
        norm = Normalize(0.0, max(float(np.nanpercentile(err, 99)), 0.1))

    def draw(a: Any, fine: bool) -> Any:
        draw_world(a, world)
        draw_route_marks(a, waypoints_ned_m, vertices=not fine)
        if len(fixes):
            ok = ~bad
            a.plot(fixes[ok, 1], fixes[ok, 0], ".", color=palette.quantity("gnss"), ls="none", zorder=2,
                   ms=3.5 if fine else 1.6, alpha=0.8 if fine else 0.45,
                   label=f"GNSS fixes ({int(ok.sum())})")
            if bad.any():
                a.plot(fixes[bad, 1], fixes[bad, 0], "x", color=palette.quantity("rejected"), ls="none",
                       zorder=5, ms=6 if fine else 4, mew=1.4, label=f"rejected fixes ({int(bad.sum())})")
        mappable = None
        for label, p in tracks.items():
            p = np.asarray(p)
            if label == "estimated" and err is not None and zoom:
                mappable = _error_track(a, p, err, norm, 2.2 if fine else 1.6)
                a.plot([], [], color=plt.get_cmap(ERROR_CMAP)(0.6), lw=1.6, label="estimated (colour: error)")
                continue
            ok = np.isfinite(p[:, 0])
            a.plot(p[ok, 1], p[ok, 0], color=palette.quantity(label), lw=1.4 if fine else 1.0, label=label,
                   zorder=4)
        return mappable

    mappable = draw(ax, fine=False)
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.25)
    if zoom and est is not None and err is not None:
        # the largest error once the filter has settled (the first 10 % of the flight is start-up)
        settled = err.copy()
        settled[: len(err) // 10] = np.nan
        k = int(np.nanargmax(settled if np.isfinite(settled).any() else err))
        centre = np.asarray(est)[k]
        if not np.isfinite(centre[:2]).all():
            centre = np.asarray(tracks.get("true", est))[k]
        half = max(ZOOM_HALF_M, 2.5 * float(err[k]))
        z = axes[0, 1]
        draw(z, fine=True)
        z.set_xlim(centre[1] - half, centre[1] + half)
        z.set_ylim(centre[0] - half, centre[0] + half)
        z.set_aspect("equal", adjustable="box")
        z.grid(alpha=0.35)
        z.set_title(f"zoom: ±{half:.0f} m about the largest estimation error after start-up, {err[k]:.2f} m",
                    fontsize=9)
        ax.add_patch(Rectangle((centre[1] - half, centre[0] - half), 2 * half, 2 * half, fill=False, ec="k",
                               lw=1.0, zorder=6))
        z.legend(fontsize=7.5, loc="upper left", framealpha=0.9)
        bar = fig.colorbar(mappable, ax=z, fraction=0.046, pad=0.03)
        bar.set_label("estimation error ‖p̂ − p‖ [m]")
    else:
        ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def _legend(*axes: Any, loc: str = "upper left") -> None:
    """One legend with the lines of all axes, drawn on the last (a twin axes is drawn on top)."""
    handles, labels = [], []
    for a in axes:
        h, lab = a.get_legend_handles_labels()
        handles += h
        labels += lab
    axes[-1].legend(handles, labels, loc=loc, fontsize=8, framealpha=0.9)


NIS_DOF = 3  # the NIS of a 3-D position fix: chi-square with 3 degrees of freedom when consistent
NIS_CHI2_95 = 7.815  # its 95th percentile


NIS_MEAN_S = 5.0  # window of the NIS's moving mean [s]


def _moving_mean(t_s: np.ndarray, x: np.ndarray, window_s: float) -> np.ndarray:
    """Centred moving mean of the finite values over ``window_s`` (NaN where the window has none)."""
    ok = np.isfinite(x)
    csum = np.concatenate([[0.0], np.cumsum(np.where(ok, x, 0.0))])
    cnt = np.concatenate([[0], np.cumsum(ok)])
    lo = np.searchsorted(t_s, t_s - window_s / 2, side="left")
    hi = np.searchsorted(t_s, t_s + window_s / 2, side="right")
    n = cnt[hi] - cnt[lo]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, (csum[hi] - csum[lo]) / np.maximum(n, 1), np.nan)


def belief_figure(path: Path, series: dict[str, np.ndarray], title: str = "",
                  fixes: dict[str, np.ndarray] | None = None) -> None:
    """β with the clearance d_k; NIS against its χ² band, with the fixes the gate rejected (from
    ``fixes``: ``t_s``, ``rejected``, as ``FlightResult.fixes``); true vs estimated bias norm; GNSS
    latency; the two errors. One time axis."""
    q = palette.quantity
    t = np.asarray(series["t_s"])
    fig, axes = plt.subplots(5, 1, figsize=(7.5, 10.4), sharex=True, height_ratios=(1.2, 0.9, 1, 0.7, 1))
    rejected = np.asarray(fixes["rejected"], dtype=float) if fixes else np.full(0, np.nan)
    t_rej = np.asarray(fixes["t_s"])[np.nan_to_num(rejected) > 0] if fixes else np.zeros(0)
    ax = axes[0]
    ax.plot(t, series["beta"], color=q("beta"), lw=1.1, label="belief β")
    ax.set_ylim(-0.02, 1.02)
    ax.set_ylabel("β")
    ax2 = ax.twinx()
    ax2.plot(t, series["clearance_m"], color=q("clearance"), lw=0.8, label="clearance d_k [m] (right)")
    ax2.set_ylabel("clearance d_k [m]", color=q("clearance"))
    _legend(ax, ax2, loc="lower left")
    ax.set_title(title, fontsize=9)
    ax = axes[1]
    nis = np.asarray(series["nis"], dtype=float)
    ax.axhspan(0, NIS_CHI2_95, color=q("nis"), alpha=0.12, lw=0, label=f"χ²({NIS_DOF}) 95 % band")
    ax.axhline(NIS_DOF, color=q("nis"), lw=0.8, ls="--", label=f"expected {NIS_DOF}")
    ax.plot(t, nis, color=q("nis"), lw=0.6, alpha=0.45, label="NIS of the last fused fix")
    ax.plot(t, _moving_mean(t, nis, NIS_MEAN_S), color="#5b5c0f", lw=1.3, label=f"its {NIS_MEAN_S:g} s mean")
    finite = nis[np.isfinite(nis)]
    top = max(3 * NIS_CHI2_95, float(np.percentile(finite, 99.5)) * 1.15 if finite.size else 0.0)
    ax.set_ylim(0, top)
    if t_rej.size:
        ax.plot(t_rej, np.full(t_rej.size, 0.04 * top), "^", color=q("rejected"), ms=6, ls="none", zorder=5,
                label=f"fix rejected by the gate ({int(np.nansum(rejected))})")
    elif np.isfinite(rejected).any():
        ax.plot([], [], "^", color=q("rejected"), ls="none", label="fix rejected by the gate (none)")
    ax.set_ylabel("NIS")
    ax.legend(loc="upper left", fontsize=7.5, ncol=2, framealpha=0.9)
    ax = axes[2]
    ax.plot(t, np.linalg.norm(series["b_true_ned_m"], axis=1), color=q("true"), lw=0.9, label="‖b‖ true")
    b_est = np.linalg.norm(series["b_est_ned_m"], axis=1)
    ax.plot(t, b_est, color=q("estimated"), lw=0.9,
            label="‖b‖ estimated" + ("" if np.isfinite(b_est).any() else " (not recorded)"))
    ax.set_ylabel("GNSS bias [m]")
    ax.legend(loc="upper left", fontsize=8)
    ax = axes[3]
    ax.plot(t, series["latency_s"], color=q("latency"), lw=0.8, label="GNSS latency")
    ax.set_ylabel("latency [s]")
    ax.legend(loc="upper left", fontsize=8)
    ax = axes[4]
    ax.plot(t, series["est_error_m"], color=q("est_error"), lw=0.9, label="estimation error ‖p̂ − p‖")
    ax.plot(t, series["track_error_m"], color=q("track_error"), lw=0.9, label="tracking error ‖p − p_ref‖")
    ax.set_ylabel("error [m]")
    ax.set_xlabel("time [s]")
    ax.legend(loc="upper left", fontsize=8)
    for a in axes:
        a.grid(alpha=0.25)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
