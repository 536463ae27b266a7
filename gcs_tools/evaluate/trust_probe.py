"""What an innovation-driven trust rule sees, with and without the receiver's Doppler velocity.

    python -m gcs_tools.evaluate.trust_probe --rows docs/results/ablation/rows-mismatch.yaml \\
        --row second-order --profiles 0-2 --seeds 1000 [--set estimator.lambda_bias_level=0]

Each (profile, seed) of the tuning mission is flown on ``mismatch`` with the row's settings twice:
with the receiver's velocity fused and without it (``gnss.velocity`` false; the positions are the
same, the velocity has its own random stream). A recorder around the row's adaptation rule keeps,
at every fix the rule learns from, the fix's ``InnovationTerms``, the β in force and the filter's
GNSS-bias estimate before the fix. Per flight (``probe_stats``):

- ``beta_mean``: the rule's mean β over its fixes;
- ``innovation_h_rms_m``: RMS horizontal innovation (the fix-to-fix surprise the rule learns from);
- ``nis_per_axis``: mean y²/S(β) per axis at the β in force (1 when consistent);
- ``beta_hindsight``: the β that minimises the rule's own loss (``cfg.loss``, without the
  smoothness term) summed over ALL the flight's fixes: the trust its consistency target aims at;
- ``bias_h_m``: median horizontal norm of the bias estimate b̂, and ``bias_over_sigma``: RMS of
  b̂_h / σ_b(β) per axis (about 1 when the bias the filter finds fits the bias range β allows);
- ``est_h_median_m``: the flight's score (median horizontal estimation error).

Nothing here changes the filter: the recorder only reads.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from companion.errors import UserError
from companion.estimator.belief import InnovationTerms
from companion.estimator.config import EstimatorConfig
from companion.estimator.windowed_ml import window_nll
from gcs_tools import choices
from gcs_tools.evaluate import campaign, stats, tuning
from gcs_tools.evaluate import rows as rows_mod

BETA_GRID = np.linspace(0.05, 0.99, 95)


class _Recorder:
    """Wraps an adaptation rule: every ``update`` records (terms, β in force, bias estimate before
    the fix), keyed by the previous fusion's time so a re-fused fix (out of sequence) is kept once."""

    def __init__(self, inner: Any, engine: Any, out: dict[int, tuple[InnovationTerms, float, Any]]) -> None:
        self._inner, self._engine, self._out = inner, engine, out

    def __getattr__(self, name: str) -> Any:
        return getattr(self._inner, name)

    def update(self, state: Any, terms: InnovationTerms) -> Any:
        prev = self._engine.fusions[-1]
        self._out[prev.t_us] = (terms, self._inner.beta(state), prev.x[6:9])
        return self._inner.update(state, terms)


def probe_stats(records: Sequence[tuple[InnovationTerms, float, Any]],
                cfg: EstimatorConfig) -> dict[str, float]:
    """The statistics above for one flight's records (terms, β in force, bias estimate b̂ NED)."""
    if not records:
        raise UserError("trust_probe: the rule saw no fix")
    terms = tuple(r[0] for r in records)
    beta = np.array([r[1] for r in records])
    y = np.array([t.y for t in terms])
    s0 = np.array([t.s0 for t in terms])
    r_nom = np.array([t.r_nominal[0] for t in terms])
    scale = np.array([t.bias_scale for t in terms])
    q_unit = np.array([t.q_bias_unit for t in terms])
    sb = (cfg.sigma_bias_max_m * (1.0 - beta) + cfg.sigma_bias_floor_m) * scale
    s_h = s0[:, :2] + (q_unit * sb * sb)[:, None] + (cfg.r_inflation_max ** (1.0 - beta) * r_nom)[:, None]
    b_h = np.array([r[2][:2] for r in records])
    nll = window_nll(BETA_GRID, terms, cfg)
    return {
        "fixes": len(records),
        "beta_mean": float(beta.mean()),
        "innovation_h_rms_m": float(np.sqrt(np.mean(np.sum(y[:, :2] ** 2, axis=1)))),
        "nis_per_axis": float(np.mean(y[:, :2] ** 2 / s_h)),
        "beta_hindsight": float(BETA_GRID[int(np.argmin(nll))]),
        "bias_h_m": float(np.median(np.linalg.norm(b_h, axis=1))),
        "bias_over_sigma": float(np.sqrt(np.mean(b_h**2 / (sb * sb)[:, None]))),
    }


def _fly_recorded(m: Any, row: rows_mod.Row, profile: int,
                  seed: int) -> tuple[Any, list[Any], EstimatorConfig]:
    """One flight with a recorder around the row's rule: (flight result, records in time order, config)."""
    from simvehicle.harness.fly import fly

    records: dict[int, tuple[InnovationTerms, float, Any]] = {}
    cfgs: list[EstimatorConfig] = []

    def observe(nav: Any) -> None:
        nav.engine.method = _Recorder(nav.engine.method, nav.engine, records)
        cfgs.append(nav.engine.cfg)

    res = fly(m, profile, row.method, seed, on_navigator=observe)
    return res, [records[k] for k in sorted(records)], cfgs[0]


def probe(row: rows_mod.Row, profiles: Sequence[int], seeds: Sequence[int],
          mission: str = tuning.TUNING_MISSION) -> list[dict[str, Any]]:
    """Fly each (profile, seed) without and with the receiver's velocity; one dict per flight."""
    out = []
    for velocity in (False, True):
        m = campaign.mission(mission, row.overrides + (("gnss.velocity", velocity),), "mismatch")
        tuning.check(m)
        for p in profiles:
            for s in seeds:
                res, records, cfg = _fly_recorded(m, row, p, s)
                out.append({"row": row.label, "velocity": velocity, "profile": p, "seed": s,
                            **probe_stats(records, cfg),
                            "est_h_median_m": stats.flight_stats(res.series)["est_h_median_m"]})
    return out


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(allow_abbrev=False, prog="python -m gcs_tools.evaluate.trust_probe",
                                 description=__doc__.split("\n")[0])
    ap.add_argument("--rows", required=True, help="ablation rows YAML (rows-mismatch.yaml)")
    ap.add_argument("--row", required=True, help="the row label to fly")
    ap.add_argument("--mission", default=tuning.TUNING_MISSION)
    ap.add_argument("--profiles", default=None,
                    help="a count N (0..N-1) or e.g. 0-3, 0,2 (default: every profile of --mission)")
    ap.add_argument("--seeds", default="1000")
    ap.add_argument("--set", action="append", default=[], metavar="SECTION.FIELD=VALUE",
                    help="on top of the row's settings (e.g. estimator.lambda_bias_level=0); repeatable")
    args = ap.parse_args(argv)
    try:
        rows = {r.label: r for r in rows_mod.load_rows(Path(args.rows))}
        if args.row not in rows:
            raise UserError(f"--row {args.row!r}: not in {args.rows} (rows: {', '.join(rows)})")
        available = len(campaign.mission(args.mission).profiles)
        profiles = choices.profiles(args.profiles or str(available), available)
        row = rows[args.row]
        extra = tuple(tuning.parse_override(v) for v in args.set)
        row = rows_mod.Row(row.label, row.method, row.overrides + extra)
        out = probe(row, profiles, choices.seeds(args.seeds), args.mission)
    except UserError as exc:
        print(f"trust_probe: error: {exc}", file=sys.stderr)
        return 2
    for entry in out:
        print(json.dumps({k: round(v, 4) if isinstance(v, float) else v for k, v in entry.items()}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
