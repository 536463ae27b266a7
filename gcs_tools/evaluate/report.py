"""Write a campaign's ``results.json``, ``report.md`` and figures into one directory.

The tuning protocol lives here: hyper-parameters of the estimator were tuned only on
``tuning_set()`` (mission profiles and seeds that are never reported); a run that overlaps it
says so in its report.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from companion.errors import UserError
from companion.estimator.methods import DEFAULT_METHOD
from gcs_tools.evaluate import aggregate, flights, plots, tuning
from gcs_tools.evaluate.campaign import JobResult


@dataclass(frozen=True)
class TuningSet:
    """Where hyper-parameters were tuned (never the reported profiles/seeds)."""

    mission: str
    profiles: tuple[int, ...]
    seeds: tuple[int, ...]

    def overlap(self, mission: str, profiles: Sequence[int], seeds: Sequence[int]) -> bool:
        """True when a run shares a tuning profile or a tuning seed."""
        same_profiles = mission == self.mission and bool(set(profiles) & set(self.profiles))
        return same_profiles or bool(set(seeds) & set(self.seeds))


def tuning_set() -> TuningSet:
    return TuningSet(tuning.TUNING_MISSION, tuning.profiles(), tuning.TUNING_SEEDS)


def write(
    out_dir: Path,
    results: Sequence[JobResult],
    methods: Sequence[str],
    campaign: dict[str, Any],
    mission: Any = None,
) -> dict[str, Any]:
    """Aggregate, draw and write everything; returns the results mapping."""
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"--out: cannot create {out_dir}: {exc.strerror or exc}") from None
    seeds = campaign["seeds"]
    profiles = campaign["profiles"]
    tuned = tuning_set()
    campaign = {
        **campaign,
        "tuning": {"mission": tuned.mission, "profiles": list(tuned.profiles), "seeds": list(tuned.seeds)},
        "overlaps_tuning_set": tuned.overlap(campaign["mission"], profiles, seeds),
    }
    res = aggregate.build_results(results, methods, seeds, campaign)
    if results and all(r.flight for r in results):
        reference = campaign.get("reference") or (DEFAULT_METHOD if DEFAULT_METHOD in methods else methods[0])
        res["flights"] = flights.build(results, methods, reference, campaign.get("more_references", ()))
    figures = plots.draw_all(results, methods, mission, profiles, seeds[0], out_dir)
    res["figures"] = figures
    (out_dir / "results.json").write_text(json.dumps(_finite_or_null(res), indent=2) + "\n", encoding="utf-8")
    (out_dir / "report.md").write_text(markdown(res), encoding="utf-8")
    return res


def table(res: dict[str, Any]) -> str:
    """The results table (markdown)."""
    seeds_ci = len(res["campaign"]["seeds"]) >= 2
    head = ["method", "est. median [m]", "est. IQR", "est. p95", "Δ est. vs naive",
            "track median [m]", "track IQR", "track p95", "Δ track vs naive",
            "goal", "collisions", "β settle [s]", "β osc. RMS"]
    rows = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for method, e in res["methods"].items():
        est, trk = e["estimation_error_m"], e["tracking_error_m"]
        rows.append("| " + " | ".join([
            f"`{method}`",
            f"{est['median']:.3f}", f"{est['iqr']:.3f}", f"{est['p95']:.3f}", _delta(est, seeds_ci, method),
            f"{trk['median']:.3f}", f"{trk['iqr']:.3f}", f"{trk['p95']:.3f}", _delta(trk, seeds_ci, method),
            f"{e['goal_reached_rate']:.0%}", f"{e['collisions']}",
            f"{e['belief_settling_time_s']['median']:.1f}", f"{e['belief_oscillation_rms']['median']:.3f}",
        ]) + " |")
    return "\n".join(rows) + "\n"


def markdown(res: dict[str, Any]) -> str:
    c = res["campaign"]
    claims = res["paper_claims"]
    lines = [
        "# Evaluation campaign",
        "",
        f"Mission `{c['mission']}`, profiles {_ranges(c['profiles'])}, seeds {_ranges(c['seeds'])}, "
        f"methods {', '.join(f'`{m}`' for m in c['methods'])}; {c['flights']} flights, "
        f"max duration {c['max_duration_s']} s, {c['wall_s']:.1f} s wall on {c['workers']} worker(s).",
        "",
        f"Hyper-parameters may be tuned only on mission `{c['tuning']['mission']}` profiles "
        f"{_ranges(c['tuning']['profiles'])} with seeds {_ranges(c['tuning']['seeds'])}; "
        + ("**this run overlaps that tuning set, so it is not an honest test.**"
           if c["overlaps_tuning_set"] else "this run shares neither with it."),
        "",
        table(res),
        "Errors are pooled over time (20 Hz), profiles and seeds. Δ = median / naive median − 1"
        + ("; brackets: 95 % percentile-bootstrap CI over seeds (paired with naive)." if len(c["seeds"]) >= 2
           else "."),
        "",
    ]
    if "flights" in res:
        lines += [
            "## Per-flight statistics",
            "",
            flights.markdown(res["flights"]),
            "Each flight (profile × seed) is reduced to its own median error, mean NEES and NIS; a row's "
            "value is the mean over its flights, brackets the 95 % bootstrap interval (seeds resampled "
            "within each profile). The last two columns are paired differences (same profile and seed) "
            f"`{res['flights']['reference']}` − row; * = the interval excludes 0. NEES and NIS have 3 "
            "dof: a consistent filter averages 3.",
            "",
        ]
    lines += [
        "## The paper's claims (second-order vs naive)",
        "",
    ]
    for key, value in claims.items():
        if isinstance(value, dict):
            ci = value.get("measured_over_seeds_ci95")
            ci_text = f" (CI over seeds {ci[0]:+.0%} … {ci[1]:+.0%})" if ci and None not in ci else ""
            verdict = "reproduced" if value["reproduced"] else "NOT reproduced"
            lines.append(f"- {key}: claimed {value['claimed']:+.0%}, "
                         f"measured {value['measured']:+.0%}{ci_text} — {verdict}")
        else:
            lines.append(f"- {key}: {'holds' if value else 'does NOT hold'}")
    lines += ["", "## Figures", ""]
    captions = {
        "fig3": "Fig. 3 — belief β over time, first- vs second-order, one line per profile",
        "fig4": "Fig. 4 — true trajectories on the map: naive, first-, second-order",
        "fig5": "Fig. 5 — tracking error ‖p − p_ref‖ per method",
        "fig6": "Fig. 6 — estimation error ‖p̂ − p‖ per method",
    }
    for key, name in res["figures"].items():
        lines += [f"![{captions[key]}]({name})", "", f"*{captions[key]}*", ""]
    lines += ["## Parameters", "", "```json", json.dumps(c.get("parameters", {}), indent=1), "```", ""]
    lines += ["## Definitions", ""] + [f"- `{k}`: {v}" for k, v in res["definitions"].items()] + [""]
    return "\n".join(lines)


def _delta(e: dict[str, Any], with_ci: bool, method: str) -> str:
    if "reduction_vs_naive" not in e or method == aggregate.BASELINE:
        return "—"
    text = f"{e['reduction_vs_naive']:+.0%}"
    ci = e.get("seed_reduction_vs_naive_ci95")
    if with_ci and ci and all(math.isfinite(v) for v in ci):
        text += f" [{ci[0]:+.0%}, {ci[1]:+.0%}]"
    return text


def _ranges(values: Sequence[int]) -> str:
    """[0,1,2,5] → '0–2, 5'."""
    v = sorted(values)
    parts, i = [], 0
    while i < len(v):
        j = i
        while j + 1 < len(v) and v[j + 1] == v[j] + 1:
            j += 1
        parts.append(f"{v[i]}" if i == j else f"{v[i]}–{v[j]}")
        i = j + 1
    return ", ".join(parts)


def _finite_or_null(value: Any) -> Any:
    """JSON has no NaN: write null instead."""
    if isinstance(value, dict):
        return {k: _finite_or_null(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite_or_null(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def readme_section(res: dict[str, Any], out_dir: Path, readme: Path) -> str:
    """The README block for one results directory: headline, table, figures, link to the report."""
    c = res["campaign"]
    rel = Path(_relpath(out_dir, readme.parent))
    claims = res["paper_claims"]
    est = claims["second_order_estimation_error_m_reduction"]
    trk = claims["second_order_tracking_error_m_reduction"]
    lines = [
        f"Mission `{c['mission']}`, profiles {_ranges(c['profiles'])}, seeds {_ranges(c['seeds'])} "
        f"({c['flights']} flights; tuning set, never reported: profiles "
        f"{_ranges(c['tuning']['profiles'])} of "
        f"`{c['tuning']['mission']}` with seeds {_ranges(c['tuning']['seeds'])}). "
        f"Second-order vs naive: estimation {est['measured']:+.0%} (paper {est['claimed']:+.0%}), "
        f"tracking {trk['measured']:+.0%} (paper {trk['claimed']:+.0%}). "
        f"Full report: [{rel / 'report.md'}]({rel / 'report.md'}).",
        "",
        table(res),
    ]
    if len(c["seeds"]) == 1:
        lines += [" ".join(f"![{key}]({rel / name})" for key, name in res["figures"].items()), ""]
    return "\n".join(lines)


def splice_readme(readme: Path, key: str, body: str) -> None:
    """Replace the block between ``<!-- results:KEY -->`` and ``<!-- /results:KEY -->``.

    The block is appended at the end of the file the first time.
    """
    begin, end = f"<!-- results:{key} -->", f"<!-- /results:{key} -->"
    try:
        text = readme.read_text(encoding="utf-8")
    except OSError as exc:
        raise UserError(f"--readme: cannot read {readme}: {exc.strerror or exc}") from None
    block = f"{begin}\n{body.rstrip()}\n{end}"
    if begin in text and end in text:
        head, _, rest = text.partition(begin)
        _, _, tail = rest.partition(end)
        text = head + block + tail
    else:
        text = text.rstrip("\n") + "\n\n" + block + "\n"
    readme.write_text(text, encoding="utf-8")


def _relpath(path: Path, start: Path) -> str:
    return os.path.relpath(path.resolve(), start.resolve())
