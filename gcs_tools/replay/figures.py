"""The figures of ``beliefnav replay``: ``track.png`` and ``errors.png`` (pure: arrays in, a file out).

Tracks are horizontal, in the replay's local NED frame (east on x, north on y, metres). The
estimate's error is measured at each reference time (truth, the log's own estimate, a fix) against
the estimate of the same log segment interpolated there; a reference between two estimates more
than ``MAX_GAP_S`` apart, or outside them, is not compared (NaN), as in the replay's summary
(``companion.metrics``). After a log restart the segments share the time axis (each its own boot
time): lines are broken between segments, never drawn from one to the next.
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


def references(rows: np.ndarray | None) -> np.ndarray:
    """A track as (K, 5) rows t_s, n, e, d, segment (rows of 4 columns: segment 0)."""
    r = np.asarray(np.zeros((0, 5)) if rows is None else rows, dtype=float)
    r = r.reshape(-1, r.shape[-1] if r.ndim == 2 else 5)
    return r if r.shape[1] == 5 else np.column_stack([r[:, :4], np.zeros(len(r))])


def horizontal_distance(t_s: np.ndarray, p_ne_m: np.ndarray, ref: np.ndarray,
                        segment: np.ndarray | None = None) -> np.ndarray:
    """‖p̂_NE(t) − r_NE‖ at each reference row ``ref`` (K, 4 or 5: t_s, n, e, d[, segment]) -> (K,) m,
    the estimate (``t_s`` (N,), ``p_ne_m`` (N, 2)) taken from the reference's segment (``segment``
    (N,); None: one segment)."""
    ref = references(ref)
    t = np.asarray(t_s, dtype=float)
    p = np.asarray(p_ne_m, dtype=float).reshape(len(t), 2)
    seg = np.zeros(len(t)) if segment is None else np.asarray(segment, dtype=float)
    out = np.full(len(ref), np.nan)
    for s in np.unique(ref[:, 4]):
        rows, mine = ref[:, 4] == s, seg == s
        q = at_times(t[mine], p[mine], ref[rows, 0])
        out[rows] = np.hypot(q[:, 0] - ref[rows, 1], q[:, 1] - ref[rows, 2])
    return out


def broken(segment: np.ndarray, *columns: np.ndarray) -> list[np.ndarray]:
    """``columns`` (N, …) with a NaN row inserted wherever ``segment`` (N,) changes: one line per segment."""
    seg = np.asarray(segment, dtype=float)
    at = np.flatnonzero(seg[1:] != seg[:-1]) + 1
    return [np.insert(np.asarray(c, dtype=float), at, np.nan, axis=0) for c in columns]


def track_figure(path: Path, p_ne_m: np.ndarray, tracks: dict[str, np.ndarray], title: str = "",
                 segment: np.ndarray | None = None) -> None:
    """The estimate (N, 2: north, east; ``segment`` (N,) its log segments) with the references in
    ``tracks`` (kind -> (K, 4 or 5): t_s, n, e, d[, segment]; ``gnss`` drawn as dots,
    ``autopilot_estimate``, ``truth``); equal axes."""
    q = palette.quantity
    fig, ax = plt.subplots(figsize=(7.0, 6.4))
    fixes = references(tracks.get(GNSS))
    if len(fixes):
        ax.plot(fixes[:, 2], fixes[:, 1], ".", color=q("gnss"), ms=2.0, alpha=0.55, ls="none", zorder=2,
                label=f"GNSS fixes ({len(fixes):,})")
    for kind, colour, lw in ((TRUTH, q("true"), 1.6), (AUTOPILOT, q("autopilot"), 1.1)):
        ref = references(tracks.get(kind))
        if len(ref):
            n, e = broken(ref[:, 4], ref[:, 1], ref[:, 2])
            ax.plot(e, n, color=colour, lw=lw, zorder=3, label=LABELS[kind])
    p = np.asarray(p_ne_m, dtype=float).reshape(-1, 2)
    (p,) = broken(np.zeros(len(p)) if segment is None else segment, p)
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
                  belief_label: str = "belief β", title: str = "", segment: np.ndarray | None = None) -> None:
    """Top: with a truth, the estimate's horizontal error and its reported 1σ horizontal accuracy
    ``sigma_h_m`` (N,) as a band, and the raw fixes' error; without, the estimate's horizontal
    distance to the log's autopilot estimate and to the fixes, beside the same band. Bottom (when
    ``belief`` (N,) has a finite value): the belief over time. ``segment`` (N,): the estimates' log
    segments (None: one)."""
    q = palette.quantity
    t = np.asarray(t_s, dtype=float)
    seg = np.zeros(len(t)) if segment is None else np.asarray(segment, dtype=float)
    p = np.asarray(p_ne_m, dtype=float).reshape(-1, 2)
    b = None if belief is None else np.asarray(belief, dtype=float)
    two = b is not None and bool(np.isfinite(b).any())
    fig, axes = plt.subplots(2 if two else 1, 1, figsize=(8.0, 6.4 if two else 4.2), sharex=True,
                             squeeze=False, height_ratios=(1.6, 1) if two else None)
    ax = axes[0, 0]
    fixes = references(tracks.get(GNSS))
    truth = references(tracks.get(TRUTH))
    t_line, sigma = broken(seg, t, sigma_h_m)
    ax.fill_between(t_line, 0.0, sigma, color=q("uncertainty"), alpha=0.18, lw=0,
                    label="reported 1σ horizontal accuracy")
    if len(truth):
        if len(fixes):
            raw = horizontal_distance(truth[:, 0], truth[:, 1:3], fixes, truth[:, 4])
            ax.plot(fixes[:, 0], raw, ".", color=q("gnss"), ms=2.0, alpha=0.6, ls="none",
                    label="the raw fixes' horizontal error")
        x, y = broken(truth[:, 4], truth[:, 0], horizontal_distance(t, p, truth, seg))
        ax.plot(x, y, color=q("est_error"), lw=1.0, label="estimate's horizontal error vs truth")
        ax.set_ylabel("horizontal error [m]")
    else:
        auto = references(tracks.get(AUTOPILOT))
        if len(auto):
            x, y = broken(auto[:, 4], auto[:, 0], horizontal_distance(t, p, auto, seg))
            ax.plot(x, y, color=q("autopilot"), lw=1.0, label="estimate to the log's autopilot estimate")
        if len(fixes):
            ax.plot(fixes[:, 0], horizontal_distance(t, p, fixes, seg), ".", color=q("gnss"), ms=2.0,
                    alpha=0.6, ls="none", label="estimate to the GNSS fixes")
        ax.set_ylabel("horizontal distance [m] (no truth)")
    ax.set_ylim(bottom=0.0)
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7.5, loc="upper left", framealpha=0.9)
    if two:
        assert b is not None
        ax = axes[1, 0]
        x, y = broken(seg, t, b)
        ax.plot(x, y, color=q("beta"), lw=1.0, label=belief_label)
        ax.set_ylim(-0.02, 1.02)
        ax.set_ylabel(belief_label)
        _legend(ax, loc="lower left")
    restarts = len(seg) > 1 and bool(np.nanmax(seg) > np.nanmin(seg))
    axes[-1, 0].set_xlabel("log time [s]" + (" (log segments drawn over each other)" if restarts else ""))
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
    seg = table[:, col["segment"]]
    with np.errstate(invalid="ignore"):
        sigma_h = np.sqrt(table[:, col["var_p_n_m2"]] + table[:, col["var_p_e_m2"]])  # as EKF2's eph
    title = f"{name}: {method}, {coupling} coupling"
    paths = [out_dir / "track.png", out_dir / "errors.png"]
    track_figure(paths[0], p_ne, tracks, title, seg)
    label = "mean per-satellite belief" if coupling == "tight" else "belief β"
    errors_figure(paths[1], t_s, p_ne, sigma_h, tracks, table[:, col["beta"]], label, title, seg)
    return paths


def read_estimates(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """``estimates.csv`` as written by the replay -> (t_s (N,), the columns after t_s (N, k))."""
    rows = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return rows[:, 0], rows[:, 1:]
