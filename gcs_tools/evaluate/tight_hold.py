"""``python -m gcs_tools.evaluate.tight_hold``: the tight filter with lost IMU samples, with and without
the held-time process noise (``TightConfig.imu_hold_acc_rw_m_s2_sqrt_s``; history.py, "Held time").

Each flight (mission, profile, seed) is flown in process under the ``canyon`` sensor scenario with the
loose second-order filter in the loop (as ``tight_sim`` flies it); its IMU, attitude and raw receiver
epochs go, in arrival order, to three tightly coupled navigators (``second-order``, no map, open loop):

* ``clean``: every IMU sample;
* ``lossy-before``: each control step's IMU and attitude samples (one datagram, as lockstep SITL's
  ``--drop-probability`` loses them) dropped with probability ``--drop-probability`` (seeded per flight),
  the held-time noise off (the filter as it was before it had the noise);
* ``lossy``: the same samples dropped, the filter as configured.

Defaults: mission ``test``, profile 2, seeds 0-19, drop probability 0.1 (what lockstep SITL measured the
loose filter on).

At every control step whose samples were kept (the estimate is then at the truth's time), each row's
state (``TightEngine.state_now``: mean and P) is compared with the truth: horizontal and vertical position
error, velocity error and the NEES per degree of freedom of position and of velocity (P alone, 3 dof each).
Per flight: mean |vertical error|, median horizontal error, RMS velocity error and the mean NEES/dof;
paired differences ``lossy − lossy-before`` over flights with a bootstrap interval (seeded).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from companion.tight import RawGnss, TightConfig
from companion.tight.engine import TightEngine
from gcs_tools import choices
from gcs_tools.evaluate.tight import table_lines
from gcs_tools.jsonvalues import write_results_or_error

ROWS = ("clean", "lossy-before", "lossy")
STATS = ("vertical_mean_abs_m", "horizontal_median_m", "velocity_rms_m_s", "nees_p_per_dof", "nees_v_per_dof")
START_S = 2.0  # steps scored from this long after the first estimate


def without_hold_noise(e: TightEngine) -> TightEngine:
    """``e`` with its held-time noise off: the prediction and the output as before the filter had it."""
    from companion.estimator.model import BlockPropagator

    e._q_hold = (0.0, 0.0, 0.0, 0.0)
    e._prop = BlockPropagator(e._q[0], e._q[2], e._q[3])
    return e


def fly(mission: str, profile: int, seed: int, drop_probability: float,
        max_duration_s: float | None = None) -> dict[str, dict[str, float]]:
    """Per row, the flight's statistics (``STATS``) and the share of IMU samples the lossy rows lost."""
    from companion.mission import load_mission
    from companion.wiring import navigator_for, tight_navigator_for
    from gcs_tools.evaluate.attitude_check import flown_on_estimate
    from simvehicle.harness.fly import planned_route
    from simvehicle.rawgnss import RawGnssModel
    from simvehicle.vehicle import SimVehicle

    m = load_mission(mission, "canyon")
    nav = navigator_for(m, "second-order")
    route = planned_route(m, profile, 1.0)
    sim = SimVehicle(m, profile, seed)
    gnss = sim.gnss
    assert isinstance(gnss, RawGnssModel)
    store = gnss.store
    tight = {r: tight_navigator_for(m, "second-order", config=TightConfig(), ephemerides=store, city=None)
             for r in ROWS}
    without_hold_noise(tight["lossy-before"].engine)
    loss = np.random.default_rng([profile, seed, 77])
    end_us = round(min(1.0 + route.duration_s * 1.5, max_duration_s or 1e9) * 1e6)
    rec: dict[str, list[tuple[float, ...]]] = {r: [] for r in ROWS}
    n_imu = n_lost = 0
    t_first = None
    for out in flown_on_estimate(sim, nav, route, end_us):
        if gnss.store is not store:  # the sky's ephemerides extended
            store = gnss.store
            for t in tight.values():
                t.update_ephemerides(store)
        lost = bool(loss.random() < drop_probability)
        n_imu += len(out.imu)
        n_lost += len(out.imu) if lost else 0
        raws = sorted(out.gnss_raw, key=lambda o: o.arrival_us)
        j = 0
        for att, imu in zip(out.attitude, out.imu, strict=True):
            for r, t in tight.items():
                if not (lost and r != "clean"):
                    t.push(att)
                    t.push(imu)
            while j < len(raws) and raws[j].arrival_us <= imu.t_us:
                for t in tight.values():
                    t.push(RawGnss(raws[j].t_us, raws[j].epoch))
                j += 1
        if lost:
            continue
        states = {r: t.engine.state_now() for r, t in tight.items()}
        if any(s is None for s in states.values()):
            continue
        tr = out.final_truth
        t_now = out.t_us * 1e-6
        t_first = t_now if t_first is None else t_first
        if t_now - t_first < START_S:
            continue
        p, v = np.asarray(tr.p_ned_m, float), np.asarray(tr.v_ned_m_s, float)
        for r, s in states.items():
            assert s is not None
            _, x, P, _ = s
            dp, dv = x[0:3] - p, x[3:6] - v
            rec[r].append((abs(dp[2]), math.hypot(dp[0], dp[1]), float(dv @ dv),
                           float(dp @ np.linalg.solve(P[0:3, 0:3], dp)) / 3.0,
                           float(dv @ np.linalg.solve(P[3:6, 3:6], dv)) / 3.0))
    res: dict[str, dict[str, float]] = {}
    for r, rows in rec.items():
        a = np.asarray(rows)
        res[r] = {"vertical_mean_abs_m": float(a[:, 0].mean()),
                  "horizontal_median_m": float(np.median(a[:, 1])),
                  "velocity_rms_m_s": float(np.sqrt(a[:, 2].mean())), "nees_p_per_dof": float(a[:, 3].mean()),
                  "nees_v_per_dof": float(a[:, 4].mean()), "steps": float(len(a))}
    res["imu"] = {"lost_fraction": n_lost / max(n_imu, 1)}
    return res


def run(mission: str, profiles: Sequence[int], seeds: Sequence[int], drop_probability: float,
        max_duration_s: float | None = None, n_resamples: int = 2000, rng_seed: int = 0) -> dict[str, Any]:
    flights: list[dict[str, Any]] = [{"profile": p, "seed": s, **fly(mission, p, s, drop_probability,
                                                                      max_duration_s)}
                                     for p in profiles for s in seeds]
    rng = np.random.default_rng(rng_seed)
    idx = rng.integers(0, len(flights), size=(n_resamples, len(flights)))
    rows = {r: {k: float(np.mean([f[r][k] for f in flights])) for k in STATS} for r in ROWS}
    paired = []
    for k in STATS:
        d = np.array([f["lossy"][k] - f["lossy-before"][k] for f in flights])
        lo, hi = np.percentile(d[idx].mean(axis=1), [2.5, 97.5])
        paired.append({"stat": k, "mean_diff": float(d.mean()),
                       "se": float(d.std(ddof=1) / math.sqrt(len(d))) if len(d) > 1 else math.nan,
                       "ci": [float(lo), float(hi)], "better": int(np.sum(d < 0)), "flights": len(d)})
    return {"mission": mission, "scenario": "canyon", "profiles": list(profiles), "seeds": list(seeds),
            "drop_probability": drop_probability, "flights": flights, "rows": rows, "paired": paired,
            "method": "per flight: mean |vertical error|, median horizontal error, RMS velocity error, mean "
                      "NEES/dof (P alone) at the control steps whose IMU was kept, from 2 s after the first "
                      "estimate; mean over flights, paired lossy − lossy-before with a bootstrap over "
                      f"flights ({n_resamples} resamples, seed {rng_seed})"}


def markdown(r: dict[str, Any]) -> str:
    lost = np.mean([f["imu"]["lost_fraction"] for f in r["flights"]])
    lines = [f"{r['mission']} / canyon, profiles {r['profiles']}, seeds {r['seeds']}, drop probability "
             f"{r['drop_probability']} ({lost:.1%} of the IMU lost): {r['method']}.", ""]
    lines += table_lines(("row", *STATS),
                         ((n, *(f"{s[k]:.3f}" for k in STATS)) for n, s in r["rows"].items()))
    head = ("lossy − lossy-before", "mean", "standard error", "95 % CI", "lower on")
    lines += ["", *table_lines(head,
                               ((c["stat"], f"{c['mean_diff']:+.3f}", f"{c['se']:.3f}",
                                 f"[{c['ci'][0]:+.3f}, {c['ci'][1]:+.3f}]", f"{c['better']} / {c['flights']}")
                                for c in r["paired"]))]
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(allow_abbrev=False, prog="python -m gcs_tools.evaluate.tight_hold",
                                description=(__doc__ or "").splitlines()[0])
    p.add_argument("--mission", default="test", help="mission name or YAML path (flown in scenario canyon)")
    p.add_argument("--profiles", default="2", help="mission profiles, e.g. 2 or 0-3")
    p.add_argument("--seeds", default="0-19", help="the simulator's seeds, e.g. 0-19")
    p.add_argument("--drop-probability", type=float, default=0.1,
                   help="each control step's IMU datagram lost with this probability (lossy rows)")
    p.add_argument("--max-duration-s", type=float, default=None, help="simulated time limit per flight")
    p.add_argument("--out", type=Path, default=Path("runs/tight-hold"))
    args = p.parse_args(argv)

    def compute() -> dict[str, Any]:
        if not 0.0 < args.drop_probability < 1.0:
            from companion.errors import UserError

            raise UserError(f"--drop-probability must be in (0, 1), got {args.drop_probability}")
        return run(args.mission, choices.seeds(args.profiles, "--profiles"), choices.seeds(args.seeds),
                   args.drop_probability, choices.positive(args.max_duration_s, "--max-duration-s"))

    return write_results_or_error(args.out, compute, markdown)


if __name__ == "__main__":
    raise SystemExit(main())
