"""The paper's Figs. 3–6 drawn from campaign results (matplotlib, Agg; files only).

- ``fig3_belief.png``: β over time, first- vs second-order, one line per mission profile.
- ``fig4_trajectories.png``: true trajectories on the map for naive, first- and second-order.
- ``fig5_tracking_error.png`` / ``fig6_estimation_error.png``: box plots per method.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from gcs_tools.evaluate.aggregate import of_method, pooled  # noqa: E402
from gcs_tools.evaluate.campaign import JobResult  # noqa: E402
from gcs_tools.figures import DPI, draw_world  # noqa: E402

FIGURES = {
    "fig3": "fig3_belief.png",
    "fig4": "fig4_trajectories.png",
    "fig5": "fig5_tracking_error.png",
    "fig6": "fig6_estimation_error.png",
}
COLORS = {
    "naive": "tab:red",
    "adaptive": "tab:orange",
    "first-order": "tab:blue",
    "second-order": "tab:green",
}
def color(method: str) -> str:
    return COLORS.get(method, "tab:purple")


def fig3_belief(results: Sequence[JobResult], seed: int, path: Path) -> None:
    methods = [m for m in ("first-order", "second-order") if of_method(results, m)]
    fig, axes = plt.subplots(len(methods) or 1, 1, figsize=(7, 2.6 * max(1, len(methods))), sharex=True)
    for ax, method in zip(np.atleast_1d(axes), methods, strict=False):
        for r in of_method(results, method):
            if r.job.seed == seed:
                ax.plot(r.t_fig_s, r.beta_fig, color=color(method), lw=0.9, alpha=0.75)
        ax.set_ylim(-0.02, 1.02)
        ax.set_ylabel("belief β")
        ax.set_title(f"{method}: one line per mission profile (seed {seed})", fontsize=9)
        ax.grid(alpha=0.3)
    np.atleast_1d(axes)[-1].set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def fig4_trajectories(
    results: Sequence[JobResult], mission: Any, profiles: Sequence[int], seed: int, path: Path
) -> None:
    methods = [m for m in ("naive", "first-order", "second-order") if of_method(results, m)]
    n = max(1, len(profiles))
    fig, axes = plt.subplots(1, n, figsize=(4.2 * n, 4.2), squeeze=False)
    for ax, profile in zip(axes[0], profiles, strict=False):
        if mission is not None:
            draw_world(ax, mission.world)
        ref_drawn = False
        for method in methods:
            for r in of_method(results, method):
                if r.job.seed != seed or r.job.profile_index != profile:
                    continue
                if not ref_drawn:
                    ax.plot(r.p_ref_ne_m[:, 1], r.p_ref_ne_m[:, 0], "k--", lw=1.0, label="reference")
                    ax.plot(*r.p_ref_ne_m[0, ::-1], "ko", ms=4)
                    ax.plot(*r.p_ref_ne_m[-1, ::-1], "k*", ms=8)
                    ref_drawn = True
                ax.plot(r.p_true_ne_m[:, 1], r.p_true_ne_m[:, 0], color=color(method), lw=1.2, label=method)
        ax.set_title(f"profile {profile} (seed {seed})", fontsize=9)
        ax.set_xlabel("east [m]")
        ax.set_ylabel("north [m]")
        ax.set_aspect("equal", adjustable="datalim")
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def error_boxes(
    results: Sequence[JobResult], methods: Sequence[str], attr: str, ylabel: str, title: str, path: Path
) -> None:
    data = [pooled(of_method(results, m), attr) for m in methods]
    data = [d[np.isfinite(d)] for d in data]
    fig, ax = plt.subplots(figsize=(1.5 * len(methods) + 2.5, 3.8))
    box = ax.boxplot(data, tick_labels=list(methods), showfliers=True, whis=1.5, patch_artist=True,
                     flierprops={"markersize": 1.5, "alpha": 0.3}, medianprops={"color": "k"})
    for patch, method in zip(box["boxes"], methods, strict=True):
        patch.set_facecolor(color(method))
        patch.set_alpha(0.6)
    ax.set_yscale("log")
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3, axis="y", which="both")
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def draw_all(
    results: Sequence[JobResult],
    methods: Sequence[str],
    mission: Any,
    profiles: Sequence[int],
    seed: int,
    out_dir: Path,
    map_profiles: int = 2,
) -> dict[str, str]:
    """Write the four figures into ``out_dir``; returns {fig key: file name}."""
    n_prof = len({r.job.profile_index for r in results})
    fig3_belief(results, seed, out_dir / FIGURES["fig3"])
    fig4_trajectories(results, mission, list(profiles)[:map_profiles], seed, out_dir / FIGURES["fig4"])
    error_boxes(results, methods, "track_error_m", "tracking error ‖p − p_ref‖ [m]",
                f"Tracking error over {n_prof} mission profiles", out_dir / FIGURES["fig5"])
    error_boxes(results, methods, "est_error_m", "estimation error ‖p̂ − p‖ [m]",
                f"Estimation error over {n_prof} mission profiles", out_dir / FIGURES["fig6"])
    return dict(FIGURES)
