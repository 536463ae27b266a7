"""How the ``mismatch`` scenario's NLOS error looks along flown paths: the simulator's truth.

    python -m gcs_tools.evaluate.nlos_probe --profiles 0-3 --seeds 1000-1001

Each (profile, seed) is flown with ``fixed-beta`` (β 0.5) on ``mismatch``; then a twin of the
flight's ``UnmodelledGnss`` (same seed, hence the same constellation and the same per-satellite
episode streams) is stepped along the recorded true path, one step per control period as the
vehicle samples its fixes, which reproduces the NLOS offset every fix carried. Per flight
(``nlos_stats``): the mean horizontal offset, the fraction of the flight it exceeds 0.5 m, its
correlation time (first lag at which the autocorrelation of each horizontal axis falls below
1/e, the mean of the two), the offset at take-off, and the fix-to-fix steps (how many exceed
0.5 m, the median of the non-zero ones). Nothing here is an estimate: it is what a filter would
have to separate from the truth.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from typing import Any

import numpy as np

from companion.errors import UserError
from gcs_tools import choices
from gcs_tools.evaluate import campaign, tuning

STEP_M = 0.5  # a "large" step / offset (m)


def nlos_stats(t_s: np.ndarray, offset_ned_m: np.ndarray) -> dict[str, float]:
    """Statistics of one flight's horizontal NLOS offset series (``offset_ned_m`` (n, 3), at ``t_s``)."""
    h = offset_ned_m[:, :2]
    norm = np.linalg.norm(h, axis=1)
    steps = np.linalg.norm(np.diff(h, axis=0), axis=1)
    moved = steps[steps > 1e-9]
    dt_s = float(np.median(np.diff(t_s))) if len(t_s) > 1 else float("nan")
    return {
        "mean_h_m": float(norm.mean()),
        "fraction_above_0_5_m": float(np.mean(norm > STEP_M)),
        "correlation_time_s": float(np.mean([_correlation_time(h[:, i], dt_s) for i in range(2)])),
        "takeoff_h_m": float(norm[0]),
        "steps_above_0_5_m": int(np.sum(steps > STEP_M)),
        "median_step_m": float(np.median(moved)) if moved.size else 0.0,
        "duration_s": float(t_s[-1] - t_s[0]) if len(t_s) else 0.0,
    }


def _correlation_time(x: np.ndarray, dt_s: float) -> float:
    """First lag (s) at which the autocorrelation of ``x`` falls below 1/e (NaN when it never does
    or ``x`` is constant)."""
    x = x - x.mean()
    var = float(x @ x)
    if var <= 0.0:
        return float("nan")
    ac = np.correlate(x, x, "full")[len(x) - 1:] / var
    below = np.flatnonzero(ac < np.exp(-1.0))
    return float(below[0] * dt_s) if below.size else float("nan")


def probe(profiles: Sequence[int], seeds: Sequence[int],
          mission: str = tuning.TUNING_MISSION) -> list[dict[str, Any]]:
    """Fly each (profile, seed) and return its ``nlos_stats`` (with ``profile`` and ``seed``)."""
    from simvehicle import SimVehicle
    from simvehicle.gnss import GnssModel
    from simvehicle.harness.fly import fly

    m = campaign.mission(mission, (("estimator.beta_fixed", 0.5),), "mismatch")
    out = []
    for p in profiles:
        for s in seeds:
            series = fly(m, p, "fixed-beta", s).series
            gnss = SimVehicle(m, p, s).gnss
            twin = gnss.unmodelled if isinstance(gnss, GnssModel) else None
            if twin is None:
                raise UserError(f"mission {mission!r}: the mismatch scenario has no unmodelled GNSS")
            offsets = np.array([twin.step(x).offset_ned_m for x in series["p_true_ned_m"]])
            out.append({"profile": p, "seed": s, **nlos_stats(series["t_s"], offsets)})
    return out


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(allow_abbrev=False, prog="python -m gcs_tools.evaluate.nlos_probe",
                                 description=__doc__.split("\n")[0])
    ap.add_argument("--mission", default=tuning.TUNING_MISSION)
    ap.add_argument("--profiles", default=None,
                    help="a count N (0..N-1) or e.g. 0-3, 0,2 (default: every profile of --mission)")
    choices.add_deprecated_alias(ap, "--missions", "--profiles", "profiles")
    ap.add_argument("--seeds", default="1000-1001")
    args = ap.parse_args(argv)
    try:
        available = len(campaign.mission(args.mission).profiles)
        profiles = choices.profiles(args.profiles or str(available), available)
        rows = probe(profiles, choices.seeds(args.seeds), args.mission)
    except UserError as exc:
        print(f"nlos_probe: error: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
