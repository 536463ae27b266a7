"""The figures of ``beliefnav replay``: ``track.png`` and ``errors.png`` (pure: arrays in, a file out).

Tracks are horizontal, in the replay's local NED frame (east on x, north on y, metres). The
estimate's error is measured at each reference time (truth, the log's own estimate, a fix) against
the estimate interpolated there; a reference between two estimates more than ``MAX_GAP_S`` apart,
or outside them, is not compared (NaN), as in the replay's summary (``companion.metrics``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gcs_tools import palette
from gcs_tools.figures import DPI, _legend, plt
from gcs_tools.replay.core import CSV_COLUMNS, MAX_GAP_US
from gcs_tools.replay.events import AUTOPILOT, TRUTH

MAX_GAP_S = MAX_GAP_US / 1e6  # as the summary's comparisons
GNSS = "gnss"
LABELS = {TRUTH: "truth", AUTOPILOT: "the log's autopilot estimate", GNSS: "GNSS fixes"}


def at_times(t_s: np.ndarray, x: np.ndarray, t_query_s: np.ndarray,
             max_gap_s: float = MAX_GAP_S) -> np.ndarray:
    """``x`` (N, k) sampled at ``t_s`` (N,), linearly interpolated at ``t_query_s`` (M,) -> (M, k);
    NaN outside ``t_s``, between two samples more than ``max_gap_s`` apart, or where ``x`` is NaN."""
    t = np.asarray(t_s, dtype=float)
    x = np.asarray(x, dtype=float).reshape(len(t), -1)
    q = np.asarray(t_query_s, dtype=float)
    out = np.full((len(q), x.shape[1]), np.nan)
    ok = np.isfinite(t) & np.isfinite(x).all(axis=1)
    t, x = t[ok], x[ok]
    if len(t) < 2 or not len(q):
        return out
    order = np.argsort(t, kind="stable")
    t, x = t[order], x[order]
    i = np.clip(np.searchsorted(t, q, side="right"), 1, len(t) - 1)
    inside = np.isfinite(q) & (q >= t[0]) & (q <= t[-1]) & (t[i] - t[i - 1] <= max_gap_s)
    for k in range(x.shape[1]):
        out[inside, k] = np.interp(q[inside], t, x[:, k])
    return out


def horizontal_distance(t_s: np.ndarray, p_ne_m: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """‖p̂_NE(t) − r_NE‖ at each reference row ``ref`` (K, 4: t_s, n, e, d) -> (K,) metres."""
    ref = np.asarray(ref, dtype=float).reshape(-1, 4)
    p = at_times(t_s, p_ne_m, ref[:, 0])
    return np.hypot(p[:, 0] - ref[:, 1], p[:, 1] - ref[:, 2])


def track_figure(path: Path, p_ne_m: np.ndarray, tracks: dict[str, np.ndarray], title: str = "") -> None:
    """The estimate (N, 2: north, east) with the references in ``tracks`` (kind -> (K, 4): t_s, n, e,
    d; kinds ``gnss`` drawn as dots, ``autopilot_estimate``, ``truth``); equal axes."""
    q = palette.quantity
    fig, ax = plt.subplots(figsize=(7.0, 6.4))
    fixes = np.asarray(tracks.get(GNSS, np.zeros((0, 4))), dtype=float).reshape(-1, 4)
    if len(fixes):
        ax.plot(fixes[:, 2], fixes[:, 1], ".", color=q("gnss"), ms=2.0, alpha=0.55, ls="none", zorder=2,
                label=f"GNSS fixes ({len(fixes):,})")
    for kind, colour, lw in ((TRUTH, q("true"), 1.6), (AUTOPILOT, q("autopilot"), 1.1)):
        ref = tracks.get(kind)
        if ref is not None and len(ref):
            ref = np.asarray(ref, dtype=float).reshape(-1, 4)
            ax.plot(ref[:, 2], ref[:, 1], color=colour, lw=lw, zorder=3, label=LABELS[kind])
    p = np.asarray(p_ne_m, dtype=float).reshape(-1, 2)
    ax.plot(p[:, 1], p[:, 0], color=q("estimated"), lw=1.1, zorder=4, label="estimate")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.25)
    ax.legend(fontsize=8, loc="best", framealpha=0.9)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def errors_figure(path: Path, t_s: np.ndarray, p_ne_m: np.ndarray, sigma_h_m: np.ndarray,
                  tracks: dict[str, np.ndarray], belief: np.ndarray | None = None,
                  belief_label: str = "belief β", title: str = "") -> None:
    """Top: with a truth, the estimate's horizontal error and its reported 1σ horizontal accuracy
    ``sigma_h_m`` (N,) as a band, and the raw fixes' error; without, the estimate's horizontal
    distance to the log's autopilot estimate and to the fixes. Bottom (when ``belief`` (N,) has a
    finite value): the belief over time."""
    q = palette.quantity
    t = np.asarray(t_s, dtype=float)
    p = np.asarray(p_ne_m, dtype=float).reshape(-1, 2)
    b = None if belief is None else np.asarray(belief, dtype=float)
    two = b is not None and bool(np.isfinite(b).any())
    fig, axes = plt.subplots(2 if two else 1, 1, figsize=(8.0, 6.4 if two else 4.2), sharex=True,
                             squeeze=False, height_ratios=(1.6, 1) if two else None)
    ax = axes[0, 0]
    fixes = np.asarray(tracks.get(GNSS, np.zeros((0, 4))), dtype=float).reshape(-1, 4)
    truth = tracks.get(TRUTH)
    if truth is not None and len(truth):
        truth = np.asarray(truth, dtype=float).reshape(-1, 4)
        ax.fill_between(t, 0.0, np.asarray(sigma_h_m, dtype=float), color=q("uncertainty"), alpha=0.18, lw=0,
                        label="reported 1σ horizontal accuracy")
        if len(fixes):
            raw = at_times(truth[:, 0], truth[:, 1:3], fixes[:, 0])
            ax.plot(fixes[:, 0], np.hypot(fixes[:, 1] - raw[:, 0], fixes[:, 2] - raw[:, 1]), ".",
                    color=q("gnss"), ms=2.0, alpha=0.6, ls="none", label="the raw fixes' horizontal error")
        ax.plot(truth[:, 0], horizontal_distance(t, p, truth), color=q("est_error"), lw=1.0,
                label="estimate's horizontal error vs truth")
        ax.set_ylabel("horizontal error [m]")
    else:
        auto = tracks.get(AUTOPILOT)
        if auto is not None and len(auto):
            auto = np.asarray(auto, dtype=float).reshape(-1, 4)
            ax.plot(auto[:, 0], horizontal_distance(t, p, auto), color=q("autopilot"), lw=1.0,
                    label="estimate to the log's autopilot estimate")
        if len(fixes):
            ax.plot(fixes[:, 0], horizontal_distance(t, p, fixes), ".", color=q("gnss"), ms=2.0, alpha=0.6,
                    ls="none", label="estimate to the GNSS fixes")
        ax.fill_between(t, 0.0, np.asarray(sigma_h_m, dtype=float), color=q("uncertainty"), alpha=0.18, lw=0,
                        label="reported 1σ horizontal accuracy")
        ax.set_ylabel("horizontal distance [m] (no truth)")
    ax.set_ylim(bottom=0.0)
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7.5, loc="upper left", framealpha=0.9)
    if two:
        assert b is not None
        ax = axes[1, 0]
        ax.plot(t, b, color=q("beta"), lw=1.0, label=belief_label)
        ax.set_ylim(-0.02, 1.02)
        ax.set_ylabel(belief_label)
        _legend(ax, loc="lower left")
    axes[-1, 0].set_xlabel("log time [s]")
    for a in axes[:, 0]:
        a.grid(alpha=0.25)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def save(out_dir: Path, t_s: np.ndarray, table: np.ndarray, tracks: dict[str, np.ndarray], name: str,
         method: str, coupling: str) -> list[Path]:
    """``track.png`` and ``errors.png`` in ``out_dir`` from the estimate rows (``t_s`` (N,), ``table``
    (N, k): ``core.CSV_COLUMNS`` after t_s) and the replay's ``tracks``; returns their paths."""
    col = {c: i - 1 for i, c in enumerate(CSV_COLUMNS)}
    table = np.asarray(table, dtype=float).reshape(len(t_s), -1)
    p_ne = table[:, [col["p_n_m"], col["p_e_m"]]]
    with np.errstate(invalid="ignore"):
        sigma_h = np.sqrt(table[:, col["var_p_n_m2"]] + table[:, col["var_p_e_m2"]])  # as EKF2's eph
    title = f"{name}: {method}, {coupling} coupling"
    paths = [out_dir / "track.png", out_dir / "errors.png"]
    track_figure(paths[0], p_ne, tracks, title)
    label = "mean per-satellite belief" if coupling == "tight" else "belief β"
    errors_figure(paths[1], t_s, p_ne, sigma_h, tracks, table[:, col["beta"]], label, title)
    return paths


def read_estimates(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """``estimates.csv`` as written by the replay -> (t_s (N,), the columns after t_s (N, k))."""
    rows = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return rows[:, 0], rows[:, 1:]
