"""Per-flight statistics of a campaign: the unit is the flight, never the pooled 20 Hz sample.

Each flight (profile × seed × row) is reduced to its own statistics (``stats.flight_stats``:
median horizontal and 3-D error, NEES, NIS). A row's figure is the MEAN over its flights of
that per-flight value, with a percentile-bootstrap 95 % interval that resamples seeds within each
profile (the profiles are a fixed design; the seeds are the random sample). Paired differences
match flights by (profile, seed) — the same seed drives the same sensor noise for every row — and
resample the matched pairs the same way. A difference whose interval excludes 0 is significant
at about the 5 % level.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from gcs_tools.evaluate import stats
from gcs_tools.evaluate.aggregate import of_method
from gcs_tools.evaluate.campaign import JobResult

KEYS = ("est_h_median_m", "est_3d_median_m", "est_h_p95_m", "nees_mean", "nees_out95", "nis_mean",
        "track_median_m")
PAIRED_KEYS = ("est_h_median_m", "est_3d_median_m")
BOOTSTRAP_SEED = 20261123


def table_of(results: Sequence[JobResult], row: str) -> dict[tuple[int, int], dict[str, float]]:
    """(profile, seed) → that flight's statistics, for one row."""
    return {(r.job.profile_index, r.job.seed): r.flight for r in of_method(results, row)}


def row_entry(results: Sequence[JobResult], row: str, rng: np.random.Generator) -> dict[str, Any]:
    flights = table_of(results, row)
    keys = sorted(flights)
    strata = np.array([k[0] for k in keys])
    out: dict[str, Any] = {"flights": len(keys)}
    for key in KEYS:
        v = np.array([flights[k].get(key, np.nan) for k in keys], dtype=float)
        mean, lo, hi = stats.mean_ci(v, strata, rng)
        median = float(np.nanmedian(v)) if np.isfinite(v).any() else float("nan")
        out[key] = {"mean": mean, "ci95": [lo, hi], "median": median}
    return out


def paired(results: Sequence[JobResult], ref: str, other: str, rng: np.random.Generator) -> dict[str, Any]:
    """``ref − other`` per matched flight: mean with its interval, and the ratio of the means."""
    a, b = table_of(results, ref), table_of(results, other)
    keys = sorted(set(a) & set(b))
    strata = np.array([k[0] for k in keys])
    out: dict[str, Any] = {"pairs": len(keys)}
    for key in PAIRED_KEYS:
        va = np.array([a[k].get(key, np.nan) for k in keys], dtype=float)
        vb = np.array([b[k].get(key, np.nan) for k in keys], dtype=float)
        mean, lo, hi = stats.mean_ci(va - vb, strata, rng)
        ratio = float(np.nanmean(va) / np.nanmean(vb)) if keys and np.nanmean(vb) > 0 else float("nan")
        out[key] = {"mean_difference": mean, "ci95": [lo, hi], "ratio_of_means": ratio,
                    "significant": bool(np.isfinite(lo) and (lo > 0 or hi < 0))}
    return out


def build(results: Sequence[JobResult], rows: Sequence[str], reference: str,
          more_references: Sequence[str] = ()) -> dict[str, Any]:
    """The ``flights`` block of results.json: per row, paired ``reference − row`` for every row (and
    against each of ``more_references`` in ``paired_by_reference``), and every flight's statistics."""
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    per_row = {row: row_entry(results, row, rng) for row in rows}
    pairs = {row: paired(results, reference, row, rng) for row in rows if row != reference}
    by_ref = {ref: {row: paired(results, ref, row, rng) for row in rows if row != ref}
              for ref in more_references if ref != reference}
    return {
        "unit": "flight (profile x seed); row value = mean over flights of the per-flight statistic",
        "bootstrap": {"seed": BOOTSTRAP_SEED, "resamples": 2000, "strata": "profile", "resampled": "seeds"},
        "reference": reference,
        "rows": per_row,
        "paired_reference_minus_row": pairs,
        "paired_by_reference": {reference: pairs, **by_ref},
        "per_flight": {row: {f"{k[0]}/{k[1]}": {key: v.get(key) for key in KEYS}
                             for k, v in sorted(table_of(results, row).items())} for row in rows},
    }


def best_row(block: dict[str, Any], candidates: Sequence[str], key: str = "est_h_median_m") -> str:
    """The candidate row with the lowest mean per-flight ``key``."""
    rows = block["rows"]
    return min((c for c in candidates if c in rows), key=lambda c: rows[c][key]["mean"])


def markdown(block: dict[str, Any]) -> str:
    """Table: per row the per-flight means with intervals, NEES/NIS, and the paired difference."""
    ref = block["reference"]
    head = ["row", "flights", "horiz. error [m]", "3-D error [m]", "horiz. p95 [m]", "NEES (3)", "NEES>χ²₉₅",
            "NIS (3)", f"`{ref}` − row, horiz. [m]", "3-D [m]"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row, e in block["rows"].items():
        p = block["paired_reference_minus_row"].get(row)
        cells = [f"`{row}`", str(e["flights"]), _ci(e["est_h_median_m"]), _ci(e["est_3d_median_m"]),
                 f"{e['est_h_p95_m']['mean']:.3f}", f"{e['nees_mean']['mean']:.1f}",
                 f"{e['nees_out95']['mean']:.0%}", f"{e['nis_mean']['mean']:.1f}"]
        for key in PAIRED_KEYS:
            if p is None:
                cells.append("—")
                continue
            cells.append(_diff(p[key]))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def markdown_paired(block: dict[str, Any], ref: str) -> str:
    """Table: ``ref − row`` per matched flight for every other row (horizontal and 3-D)."""
    pairs = block.get("paired_by_reference", {}).get(ref)
    if pairs is None:
        return ""
    head = ["row", "pairs", f"`{ref}` − row, horiz. [m]", "ratio", "3-D [m]"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row, p in pairs.items():
        h, d = p["est_h_median_m"], p["est_3d_median_m"]
        cells = [f"`{row}`", str(p["pairs"]), _diff(h), f"{h['ratio_of_means']:.3f}", _diff(d)]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _diff(d: dict[str, Any]) -> str:
    star = " *" if d["significant"] else ""
    return f"{d['mean_difference']:+.3f} [{d['ci95'][0]:+.3f}, {d['ci95'][1]:+.3f}]{star}"


def _ci(e: dict[str, Any]) -> str:
    lo, hi = e["ci95"]
    return f"{e['mean']:.3f} [{lo:.3f}, {hi:.3f}]"
