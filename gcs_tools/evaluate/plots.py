"""The paper's Figs. 3–6 drawn from campaign results (matplotlib, Agg; files only).

- ``fig3_belief.png``: β over time, first- vs second-order, one line (and colour) per mission profile.
- ``fig4_trajectories.png``: true trajectories on the map for naive, first- and second-order, one
  small map per profile.
- ``fig5_tracking_error.png`` / ``fig6_estimation_error.png``: box plots per method.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from gcs_tools import palette  # noqa: E402
from gcs_tools.evaluate.aggregate import of_method, pooled  # noqa: E402
from gcs_tools.evaluate.campaign import JobResult  # noqa: E402
from gcs_tools.figures import DPI, draw_route_marks, draw_world  # noqa: E402

ZOOM_MARGIN_M = 12.0  # Fig. 4: each map shows its route's extent plus this margin [m]
FIGURES = {
    "fig3": "fig3_belief.png",
    "fig4": "fig4_trajectories.png",
    "fig5": "fig5_tracking_error.png",
    "fig6": "fig6_estimation_error.png",
}


def color(method: str) -> str:
    return palette.method(method)


def fig3_belief(results: Sequence[JobResult], seed: int, path: Path,
                profile_names: Sequence[str] = ()) -> None:
    """β over time for first- and second-order, one panel each; one colour per mission profile (the
    same colour in both panels) and one legend naming the profiles."""
    methods = [m for m in ("first-order", "second-order") if of_method(results, m)]
    fig, axes = plt.subplots(len(methods) or 1, 1, figsize=(8.6, 2.7 * max(1, len(methods))), sharex=True,
                             squeeze=False)
    axes = axes[:, 0]
    seen: dict[int, Any] = {}
    for ax, method in zip(axes, methods, strict=False):
        for r in sorted(of_method(results, method), key=lambda r: r.job.profile_index):
            if r.job.seed == seed:
                p = r.job.profile_index
                line, = ax.plot(r.t_fig_s, r.beta_fig, color=palette.category(p), lw=0.9, alpha=0.85)
                seen.setdefault(p, line)
        ax.set_ylim(-0.02, 1.02)
        ax.set_ylabel("belief β")
        ax.set_title(f"{method} (seed {seed})", fontsize=9)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    if seen:
        labels = [f"{p} {profile_names[p]}" if p < len(profile_names) else f"profile {p}" for p in seen]
        fig.legend(list(seen.values()), labels, loc="center right", fontsize=7.5, frameon=False,
                   title="mission profile", title_fontsize=8)
    fig.tight_layout(rect=(0, 0, 0.78 if seen else 1, 1))
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def fig4_trajectories(
    results: Sequence[JobResult], mission: Any, profiles: Sequence[int], seed: int, path: Path
) -> None:
    """One small map per profile (5 per row); methods in their colours and dash patterns, so a
    method flying under another stays visible; one legend for the figure."""
    methods = [m for m in ("naive", "first-order", "second-order") if of_method(results, m)]
    n = max(1, len(profiles))
    ncols = min(n, 5)
    nrows = math.ceil(n / ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(3.3 * ncols, 3.3 * nrows + 0.5), squeeze=False)
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    for ax, profile in zip(axes.flat, profiles, strict=False):
        if mission is not None:
            draw_world(ax, mission.world)
            ax.set_aspect("equal", adjustable="box")  # the limits below are the route's: keep them
        ref_drawn = False
        for method in methods:
            for r in of_method(results, method):
                if r.job.seed != seed or r.job.profile_index != profile:
                    continue
                if not ref_drawn:
                    ref = np.column_stack([r.p_ref_ne_m, np.zeros(len(r.p_ref_ne_m))])
                    draw_route_marks(ax, ref, vertices=False)
                    ref_drawn = True
                    # zoom to the route (the city is the same in every panel): metre-scale
                    # differences between methods become visible
                    # (a square view about the route: equal axes without squeezing the panel)
                    lo, hi = r.p_ref_ne_m.min(axis=0), r.p_ref_ne_m.max(axis=0)
                    mid, half = (lo + hi) / 2, float((hi - lo).max()) / 2 + ZOOM_MARGIN_M
                    ax.set_xlim(mid[1] - half, mid[1] + half)
                    ax.set_ylim(mid[0] - half, mid[0] + half)
                ax.plot(r.p_true_ne_m[:, 1], r.p_true_ne_m[:, 0], color=color(method), lw=1.3,
                        ls=palette.METHOD_DASH.get(method, "-"), label=f"{method} (true track)")
        ax.set_title(f"profile {profile}", fontsize=9)
        ax.tick_params(labelsize=7)
        ax.xaxis.label.set_size(8)
        ax.yaxis.label.set_size(8)
    handles, labels = axes.flat[0].get_legend_handles_labels()
    if labels:  # rows without naive / first- / second-order draw only the map
        fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=8, frameon=False)
    fig.suptitle(f"True trajectories per mission profile (seed {seed})", fontsize=10)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def error_boxes(
    results: Sequence[JobResult], methods: Sequence[str], attr: str, ylabel: str, title: str, path: Path
) -> None:
    data = [pooled(of_method(results, m), attr) for m in methods]
    # a log axis has no zero: values <= 0 (e.g. a tracking error of exactly 0 at the start) are
    # left out and counted in the title
    dropped = sum(int((np.isfinite(d) & (d <= 0)).sum()) for d in data)
    data = [d[np.isfinite(d) & (d > 0)] for d in data]
    fig, ax = plt.subplots(figsize=(1.5 * len(methods) + 2.5, 3.8))
    # whiskers at the 1st and 99th percentiles (1.5 IQR below Q1 is negative: on a log axis Tukey's
    # whisker would reach down to the start-up samples of ~1e-6 m); no fliers
    box = ax.boxplot(data, tick_labels=list(methods), showfliers=False, whis=(1, 99), patch_artist=True,
                     medianprops={"color": "k"})
    for patch, method in zip(box["boxes"], methods, strict=True):
        patch.set_facecolor(color(method))
        patch.set_alpha(0.6)
    ax.set_yscale("log")
    ax.set_ylabel(ylabel)
    ax.set_title(title + "; box: quartiles, whiskers: 1st–99th percentile"
                 + (f"\n({dropped} samples ≤ 0 not drawn on the log axis)" if dropped else ""), fontsize=9)
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
    map_profiles: int | None = None,
) -> dict[str, str]:
    """Write the four figures into ``out_dir``; returns {fig key: file name}."""
    n_prof = len({r.job.profile_index for r in results})
    names = [p.name for p in mission.profiles] if mission is not None else []
    fig3_belief(results, seed, out_dir / FIGURES["fig3"], names)
    map_list = list(profiles)[:map_profiles] if map_profiles else list(profiles)
    fig4_trajectories(results, mission, map_list, seed, out_dir / FIGURES["fig4"])
    error_boxes(results, methods, "track_error_m", "tracking error ‖p − p_ref‖ [m]",
                f"Tracking error over {n_prof} mission profiles", out_dir / FIGURES["fig5"])
    error_boxes(results, methods, "est_error_m", "estimation error ‖p̂ − p‖ [m]",
                f"Estimation error over {n_prof} mission profiles", out_dir / FIGURES["fig6"])
    return dict(FIGURES)
