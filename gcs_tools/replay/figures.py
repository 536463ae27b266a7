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
from gcs_tools.replay.gnss_record import ACCEPTED, EPOCH_FILE, FIX_FILE

MAX_GAP_S = MAX_GAP_US / 1e6  # as the summary's comparisons
GNSS = "gnss"
LABELS = {TRUTH: "truth", AUTOPILOT: "the log's autopilot estimate", GNSS: "GNSS fixes"}
Record = dict[str, dict[str, np.ndarray]]  # gnss_record's files: name -> columns
STRIP_BINS = 150  # the not-fused strip's bins over the log (at least 1 s each): readable for an hour


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


def fix_classes(fixes: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Masks over ``gnss_fixes.csv``'s rows: ``rejected`` (refused by the gate or before it), ``step`` (held
    as a GNSS step: fused only relative to an open offset), ``reset`` (the state reset onto the fix)."""
    reason = np.asarray(fixes["reason"], dtype=str)
    taken = np.isin(reason, list(ACCEPTED))
    step = reason == "step"
    return {"rejected": ~taken & ~step & (reason != "unresolved"), "step": step, "reset": reason == "reset"}


def reason_counts(reasons: np.ndarray) -> str:
    """``['innovation', 'frozen', 'innovation']`` -> ``innovation 2, frozen 1`` (most first)."""
    names, counts = np.unique(np.asarray(reasons, dtype=str), return_counts=True)
    order = np.argsort(-counts, kind="stable")
    return ", ".join(f"{names[i].replace('_', ' ')} {counts[i]:,}" for i in order)


def _view(*points_ne: np.ndarray) -> tuple[float, float, float, float] | None:
    """(n_min, n_max, e_min, e_max) of the finite points, padded by 15 % (at least 5 m); None: none."""
    pts = np.concatenate([np.asarray(x, dtype=float).reshape(-1, 2) for x in points_ne])
    pts = pts[np.isfinite(pts).all(axis=1)]
    if not len(pts):
        return None
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = np.maximum(0.15 * (hi - lo).max(), 5.0)
    return lo[0] - pad, hi[0] + pad, lo[1] - pad, hi[1] + pad


def _mark_record(ax, record: Record, p_ne: np.ndarray, t_s: np.ndarray | None, seg: np.ndarray,
                 view: tuple[float, float, float, float] | None) -> None:
    """The fixes the estimator did not fuse (markers, by class) and its resets (on the estimate track);
    markers outside ``view`` (a fix hundreds of kilometres off) are counted in the label, not drawn."""
    q = palette.quantity
    fixes, epochs = record.get(FIX_FILE), record.get(EPOCH_FILE)
    resets = np.zeros((0, 2))  # (t_s, segment)
    if fixes is not None and len(fixes["t_s"]):
        classes = fix_classes(fixes)
        ne = np.column_stack([fixes["p_n_m"], fixes["p_e_m"]])
        inside = np.isfinite(ne).all(axis=1)
        if view is not None:
            n_min, n_max, e_min, e_max = view
            inside &= (ne[:, 0] >= n_min) & (ne[:, 0] <= n_max) & (ne[:, 1] >= e_min) & (ne[:, 1] <= e_max)
        for kind, label, style in (
                ("rejected", "fixes rejected", dict(marker="x", ms=5.0, mew=1.2, color=q("rejected"))),
                ("step", "fixes held as a GNSS step", dict(marker="o", ms=4.5, mfc="none", mew=1.0,
                                                            color=q("gnss_step")))):
            m = classes[kind]
            if not m.any():
                continue
            off = int((m & ~inside).sum())
            text = f"{label} ({reason_counts(fixes['reason'][m])})" if kind == "rejected" else \
                f"{label} ({int(m.sum()):,})"
            ax.plot(ne[m & inside, 1], ne[m & inside, 0], ls="none", zorder=5, alpha=0.85, **style,
                    label=text + (f"; {off:,} off the axes" if off else ""))
        r = classes["reset"]
        resets = ne[r]  # the state was reset onto the fix: the estimate's position just after
    if epochs is not None and len(epochs["t_s"]) and t_s is not None:
        # an epoch is fused on arrival: the first estimate row at or after it is the filter after it
        after = _row_after(np.asarray(t_s, dtype=float), seg, epochs["t_s"], epochs["segment"])
        ok = after >= 0
        r = (epochs["reset"] > 0) & ok
        none = (np.asarray(epochs["reason"], dtype=str) == "no_satellite_used") & ok
        resets = np.vstack([resets, p_ne[after[r]]])
        if none.any():
            ax.plot(p_ne[after[none], 1], p_ne[after[none], 0], "v", ms=3.5, color=q("rejected"), alpha=0.7,
                    ls="none", zorder=5, label=f"epochs with every satellite excluded ({int(none.sum()):,})")
    if len(resets):
        ax.plot(resets[:, 1], resets[:, 0], "D", ms=6.0, mfc=q("reset"), mec="white", mew=0.8, ls="none",
                zorder=6, label=f"resets of the estimate ({len(resets):,})")


def _row_after(t_s: np.ndarray, seg: np.ndarray, t_query_s: np.ndarray, seg_query: np.ndarray) -> np.ndarray:
    """The index of the first estimate row of the query's segment at or after its time (-1: none)."""
    out = np.full(len(t_query_s), -1)
    for s in np.unique(seg_query):
        mine = np.flatnonzero(seg == s)
        rows = seg_query == s
        if not len(mine):
            continue
        k = np.searchsorted(t_s[mine], t_query_s[rows], side="left")  # rows of a segment are in time order
        out[rows] = np.where(k < len(mine), mine[np.minimum(k, len(mine) - 1)], -1)
    return out


def _strip(ax, record: Record, t_line: np.ndarray) -> None:
    """Loose: the fixes not fused per time bin (rejected, held as a step), resets as lines. Tight: each
    epoch's satellites used, excluded and used down-weighted (belief < 0.5), resets as lines."""
    q = palette.quantity
    fixes, epochs = record.get(FIX_FILE), record.get(EPOCH_FILE)
    resets: list[float] = []
    if epochs is not None and len(epochs["t_s"]):
        t = epochs["t_s"]
        x, used, excl, low = broken(epochs["segment"], t, epochs["n_used"], epochs["n_excluded"],
                                    epochs["n_low_belief"])
        ax.step(x, used, where="post", color=q("sats_used"), lw=0.9,
                label=f"satellites used (median {np.nanmedian(epochs['n_used']):.0f})")
        ax.step(x, excl, where="post", color=q("rejected"), lw=0.9,
                label=f"satellites excluded ({int(np.nansum(epochs['n_excluded'])):,} in all)")
        ax.step(x, low, where="post", color=q("gnss_step"), lw=0.8, ls=(0, (3, 1.5)),
                label="satellites used down-weighted (belief < 0.5)")
        ax.set_ylabel("satellites per epoch")
        ax.set_ylim(-0.5, max(4.0, float(np.nanmax(epochs["n_sats"]))) * 1.6)  # room for the legend
        resets = list(t[epochs["reset"] > 0])
    elif fixes is not None and len(fixes["t_s"]):
        t = fixes["t_s"]
        classes = fix_classes(fixes)
        both = np.concatenate([t, np.asarray(t_line, dtype=float)])
        both = both[np.isfinite(both)]
        width = max(1.0, float(np.ceil((both.max() - both.min()) / STRIP_BINS)))
        edges = np.arange(np.floor(both.min() / width) * width, both.max() + 2 * width, width)
        rej, _ = np.histogram(t[classes["rejected"]], edges)
        held, _ = np.histogram(t[classes["step"]], edges)
        ax.bar(edges[:-1], rej, width=width, align="edge", color=q("rejected"), lw=0,
               label=f"fixes rejected ({int(classes['rejected'].sum()):,} of {len(t):,})")
        ax.bar(edges[:-1], held, width=width, align="edge", bottom=rej, color=q("gnss_step"), lw=0,
               label=f"fixes held as a GNSS step ({int(classes['step'].sum()):,})")
        ax.set_ylabel(f"fixes not fused\nper {width:g} s")
        ax.set_ylim(bottom=0.0, top=max(1.0, float((rej + held).max())) * 1.7)  # room for the legend
        resets = list(t[classes["reset"]])
    for k, tr in enumerate(resets):
        ax.axvline(tr, color=q("reset"), lw=0.8, ls=(0, (4, 2)),
                   label=f"resets of the estimate ({len(resets):,})" if k == 0 else None)
    ax.legend(loc="upper left", fontsize=7.5, framealpha=0.9, ncol=2)


def broken(segment: np.ndarray, *columns: np.ndarray) -> list[np.ndarray]:
    """``columns`` (N, …) with a NaN row inserted wherever ``segment`` (N,) changes: one line per segment."""
    seg = np.asarray(segment, dtype=float)
    at = np.flatnonzero(seg[1:] != seg[:-1]) + 1
    return [np.insert(np.asarray(c, dtype=float), at, np.nan, axis=0) for c in columns]


def track_figure(path: Path, p_ne_m: np.ndarray, tracks: dict[str, np.ndarray], title: str = "",
                 segment: np.ndarray | None = None, t_s: np.ndarray | None = None,
                 record: Record | None = None) -> None:
    """The estimate (N, 2: north, east; ``segment`` (N,) its log segments, ``t_s`` (N,) its times) with
    the references in ``tracks`` (kind -> (K, 4 or 5): t_s, n, e, d[, segment]; ``gnss`` drawn as dots,
    ``autopilot_estimate``, ``truth``) and, from ``record`` (``gnss_record``'s columns), the fixes the
    estimator did not fuse and its resets (on the estimate track); equal axes."""
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
    p_ne = np.asarray(p_ne_m, dtype=float).reshape(-1, 2)
    seg = np.zeros(len(p_ne)) if segment is None else np.asarray(segment, dtype=float)
    (p,) = broken(seg, p_ne)
    ax.plot(p[:, 1], p[:, 0], color=q("estimated"), lw=1.1, zorder=4, label="estimate")
    if record:
        refs = [references(tracks.get(k))[:, 1:3] for k in (GNSS, TRUTH, AUTOPILOT)]
        _mark_record(ax, record, p_ne, t_s, seg, _view(p_ne, *refs))
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
                  belief_label: str = "belief β", title: str = "", segment: np.ndarray | None = None,
                  record: Record | None = None) -> None:
    """Top: with a truth, the estimate's horizontal error and its reported 1σ horizontal accuracy
    ``sigma_h_m`` (N,) as a band, and the raw fixes' error; without, the estimate's horizontal
    distance to the log's autopilot estimate and to the fixes, beside the same band. Bottom (when
    ``belief`` (N,) has a finite value): the belief over time. Last (when ``record``, ``gnss_record``'s
    columns, has rows): a strip of the fixes not fused (loose) or each epoch's satellites used and
    excluded (tight), the estimate's resets as lines. ``segment`` (N,): the estimates' log segments
    (None: one)."""
    q = palette.quantity
    t = np.asarray(t_s, dtype=float)
    seg = np.zeros(len(t)) if segment is None else np.asarray(segment, dtype=float)
    p = np.asarray(p_ne_m, dtype=float).reshape(-1, 2)
    b = None if belief is None else np.asarray(belief, dtype=float)
    two = b is not None and bool(np.isfinite(b).any())
    strip = bool(record) and any(len(c["t_s"]) for c in (record or {}).values())
    ratios = (1.6, *((1.0,) if two else ()), *((0.8,) if strip else ()))
    fig, axes = plt.subplots(len(ratios), 1, figsize=(8.0, 4.2 + 2.2 * (len(ratios) - 1)), sharex=True,
                             squeeze=False, height_ratios=ratios if len(ratios) > 1 else None)
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
    if strip:
        assert record is not None
        _strip(axes[-1, 0], record, t)
    restarts = len(seg) > 1 and bool(np.nanmax(seg) > np.nanmin(seg))
    axes[-1, 0].set_xlabel("log time [s]" + (" (log segments drawn over each other)" if restarts else ""))
    for a in axes[:, 0]:
        a.grid(alpha=0.25)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def save(out_dir: Path, t_s: np.ndarray, table: np.ndarray, tracks: dict[str, np.ndarray], name: str,
         method: str, coupling: str, record: Record | None = None) -> list[Path]:
    """``track.png`` and ``errors.png`` in ``out_dir`` from the estimate rows (``t_s`` (N,), ``table``
    (N, k): ``core.CSV_COLUMNS`` after t_s), the replay's ``tracks`` and ``record`` (what the estimator
    did with each GNSS input: ``gnss_record``'s files, name -> columns; None: not marked); returns
    their paths."""
    col = {c: i - 1 for i, c in enumerate(CSV_COLUMNS)}
    table = np.asarray(table, dtype=float).reshape(len(t_s), -1)
    p_ne = table[:, [col["p_n_m"], col["p_e_m"]]]
    seg = table[:, col["segment"]]
    with np.errstate(invalid="ignore"):
        sigma_h = np.sqrt(table[:, col["var_p_n_m2"]] + table[:, col["var_p_e_m2"]])  # as EKF2's eph
    title = f"{name}: {method}, {coupling} coupling"
    paths = [out_dir / "track.png", out_dir / "errors.png"]
    track_figure(paths[0], p_ne, tracks, title, seg, t_s, record)
    label = "mean per-satellite belief" if coupling == "tight" else "belief β"
    errors_figure(paths[1], t_s, p_ne, sigma_h, tracks, table[:, col["beta"]], label, title, seg, record)
    return paths


def read_estimates(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """``estimates.csv`` as written by the replay -> (t_s (N,), the columns after t_s (N, k))."""
    rows = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return rows[:, 0], rows[:, 1:]


def read_record(out_dir: Path) -> Record:
    """``gnss_fixes.csv`` and ``gnss_epochs.csv`` in ``out_dir`` as the replay wrote them (those present)."""
    from gcs_tools.replay.gnss_record import read

    return {name: read(out_dir / name) for name in (FIX_FILE, EPOCH_FILE) if (out_dir / name).is_file()}
