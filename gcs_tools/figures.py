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


def map_figure(path: Path, world: Any, waypoints_ned_m: np.ndarray, tracks: dict[str, np.ndarray],
               title: str = "") -> None:
    """Map with the planned path and NED tracks (label -> (N, 3)); a label's colour is its meaning
    ("true", "estimated", "gnss", ... in :mod:`gcs_tools.palette`)."""
    fig, ax = plt.subplots(figsize=(6.4, 6.0))
    draw_world(ax, world)
    draw_route_marks(ax, waypoints_ned_m)
    for label, p in tracks.items():
        p = np.asarray(p)
        ok = np.isfinite(p[:, 0])
        ax.plot(p[ok, 1], p[ok, 0], color=palette.quantity(label), lw=1.1, label=label)
    ax.legend(fontsize=8, loc="best")
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.25)
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


def belief_figure(path: Path, series: dict[str, np.ndarray], title: str = "") -> None:
    """β and NIS with the clearance d_k; true vs estimated bias norm; GNSS latency; the two errors."""
    q = palette.quantity
    t = np.asarray(series["t_s"])
    fig, axes = plt.subplots(4, 1, figsize=(7.5, 8.6), sharex=True, height_ratios=(1.2, 1, 0.7, 1))
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
    ax.plot(t, np.linalg.norm(series["b_true_ned_m"], axis=1), color=q("true"), lw=0.9, label="‖b‖ true")
    b_est = np.linalg.norm(series["b_est_ned_m"], axis=1)
    ax.plot(t, b_est, color=q("estimated"), lw=0.9,
            label="‖b‖ estimated" + ("" if np.isfinite(b_est).any() else " (not recorded)"))
    ax.set_ylabel("GNSS bias [m]")
    ax.legend(loc="upper left", fontsize=8)
    ax = axes[2]
    ax.plot(t, series["latency_s"], color=q("latency"), lw=0.8, label="GNSS latency")
    ax.set_ylabel("latency [s]")
    ax.legend(loc="upper left", fontsize=8)
    ax = axes[3]
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
