"""Figures shared by ``fly``, SITL, ``plot`` and the evaluation (matplotlib, Agg; files only)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402

DPI = 110


def draw_world(ax: Any, world: Any) -> None:
    """Buildings as grey rectangles, east on x and north on y (``world.rects_m`` rows n0, e0, n1, e1)."""
    for n0, e0, n1, e1 in np.asarray(world.rects_m, dtype=float):
        ax.add_patch(Rectangle((e0, n0), e1 - e0, n1 - n0, facecolor="0.75", edgecolor="0.4", lw=0.6))
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")


def map_figure(path: Path, world: Any, waypoints_ned_m: np.ndarray, tracks: dict[str, np.ndarray],
               title: str = "") -> None:
    """Map with the planned path (waypoints) and any number of NED tracks (label -> (N, 3))."""
    fig, ax = plt.subplots(figsize=(6.4, 6.0))
    draw_world(ax, world)
    wp = np.asarray(waypoints_ned_m).reshape(-1, 3)
    if len(wp):  # a recording may hold no route
        ax.plot(wp[:, 1], wp[:, 0], "k--", lw=1.0, marker="o", ms=3, label="planned path")
        ax.plot(wp[0, 1], wp[0, 0], "ks", ms=6)
        ax.plot(wp[-1, 1], wp[-1, 0], "k*", ms=10)
    colours = ("tab:green", "tab:red", "tab:blue", "tab:orange")
    for (label, p), colour in zip(tracks.items(), colours, strict=False):
        p = np.asarray(p)
        ok = np.isfinite(p[:, 0])
        ax.plot(p[ok, 1], p[ok, 0], color=colour, lw=1.1, label=label)
    ax.legend(fontsize=8, loc="best")
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.25)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def belief_figure(path: Path, series: dict[str, np.ndarray], title: str = "") -> None:
    """β with the clearance d_k; true vs estimated bias norm; estimation and tracking errors."""
    t = np.asarray(series["t_s"])
    fig, axes = plt.subplots(3, 1, figsize=(7.5, 7.0), sharex=True)
    ax = axes[0]
    ax.plot(t, series["beta"], color="tab:green", lw=1.1, label="belief β")
    ax.set_ylim(-0.02, 1.02)
    ax.set_ylabel("β")
    ax2 = ax.twinx()
    ax2.plot(t, series["clearance_m"], color="0.5", lw=0.8, label="clearance d_k")
    ax2.set_ylabel("clearance d_k [m]", color="0.4")
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title(title, fontsize=9)
    ax = axes[1]
    ax.plot(t, np.linalg.norm(series["b_true_ned_m"], axis=1), color="k", lw=0.9, label="‖b‖ true")
    ax.plot(t, np.linalg.norm(series["b_est_ned_m"], axis=1), color="tab:blue", lw=0.9, label="‖b‖ estimated")
    ax.plot(t, series["latency_s"], color="tab:purple", lw=0.8, label="latency [s]")
    ax.set_ylabel("bias [m]")
    ax.legend(loc="upper left", fontsize=8)
    ax = axes[2]
    ax.plot(t, series["est_error_m"], color="tab:red", lw=0.9, label="estimation error")
    ax.plot(t, series["track_error_m"], color="tab:orange", lw=0.9, label="tracking error")
    ax.set_ylabel("error [m]")
    ax.set_xlabel("time [s]")
    ax.legend(loc="upper left", fontsize=8)
    for a in axes:
        a.grid(alpha=0.25)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
