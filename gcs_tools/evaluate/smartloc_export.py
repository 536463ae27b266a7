"""``python -m gcs_tools.evaluate.smartloc_export``: the calibrated simulator's flights as smartLoc drives.

Each flight (mission, profile, seed) is flown on the truth under the ``canyon`` sensor scenario (the raw
receiver calibrated to smartLoc), as ``simcal`` flies it (``simcal.receiver_flight``: the planned route
from a 2 s hover to its arrival), and written as ``<mission>_p<profile>_s<seed>_Input.txt`` and
``…_GT.txt`` in the smartLoc format (``gcs_tools.gnss.smartloc.write_input`` / ``write_truth``), so that
``python -m gcs_tools.evaluate.tight --smartloc`` runs on it exactly as on a real drive:

* ``pseudorange3``: every tracked signal of every 5 Hz epoch, with the satellite clock (broadcast) and the
  modelled atmosphere (Klobuchar, Saastamoinen) removed, as the receiver removes them before its own
  solution: the simulator's residual common errors (orbits, ionosphere model error, GLONASS biases),
  reflections, diffraction, multipath and tracking noise stay in; the satellite position at transmission,
  the receiver's reported variance (u-blox ``prStd``: its tracking noise, not smartLoc's metre-scale
  column), C/N0 and elevation in whole dB-Hz and degrees (as the receiver reports them). The receiver's
  Doppler is dropped: smartLoc has none. Times are seconds from the first epoch (the true measurement
  time; the receiver clock's offset stays in the pseudoranges).
* ``odom3``: what a car's odometry would give on this path, derived from the true velocity at each epoch:
  the horizontal speed and the counter-clockwise rate of the course (direction of travel), each with
  white noise of the σ the data set states (0.05 m/s, 0.002 rad/s), seeded per flight. The course is
  held through the hover and the stops (below ``MIN_SPEED_M_S``) and its turn at a stop spread over the
  stop. A car's odometry measures its body's heading rate, which is its course rate only without side
  slip; the quadrotor's vertical motion (none on these routes after the hover: they fly level) is in no
  odometry, as on a car. No scale error or yaw-rate bias is added (``evaluate.tight --sensitivity`` adds
  them).
* ``point3``: the true antenna position at each epoch (5 Hz).

``export.json`` beside them lists each drive with the receiver's own fix errors on that flight (horizontal
median and p95 over the epochs with a fix): ``evaluate.tight``'s ``spp`` row on the drive reproduces them
(the same solver and weighting, on the same corrected pseudoranges).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from companion.gnss.observations import GnssEpoch
from gcs_tools import choices
from gcs_tools.evaluate.simcal import SCENARIO, Series, simulate
from gcs_tools.evaluate.tight import table_lines
from gcs_tools.gnss import smartloc
from gcs_tools.jsonvalues import write_results_or_error

ODOM_SEED = 11
MIN_SPEED_M_S = 0.5  # below it the course is not defined: held, and its turn spread over the stop
SIGMA_SPEED_M_S = math.sqrt(smartloc.ODOM_COV[0])
SIGMA_YAW_RATE_RAD_S = math.sqrt(smartloc.ODOM_COV[5])


def course_odometry(t_s: np.ndarray, v_ned_m_s: np.ndarray, rng: np.random.Generator | None = None
                    ) -> np.ndarray:
    """(n, 3): t_s, horizontal speed (m/s), counter-clockwise course rate (rad/s) from true velocities,
    with the data set's noise when ``rng`` is given. The course (NED, clockwise from north) is taken where
    the speed is at least ``MIN_SPEED_M_S``, unwrapped, linearly interpolated in time in between (held
    before the first and after the last such epoch), and differentiated (central differences)."""
    t_s = np.asarray(t_s, dtype=float)
    v = np.asarray(v_ned_m_s, dtype=float)
    speed = np.hypot(v[:, 0], v[:, 1])
    moving = speed >= MIN_SPEED_M_S
    if moving.sum() >= 1:
        course = np.unwrap(np.arctan2(v[moving, 1], v[moving, 0]))
        course = np.interp(t_s, t_s[moving], course)
    else:
        course = np.zeros(len(t_s))
    rate = np.gradient(course, t_s) if len(t_s) > 1 else np.zeros(len(t_s))
    if rng is not None:
        speed = np.maximum(speed + SIGMA_SPEED_M_S * rng.standard_normal(len(t_s)), 0.0)
        rate = rate + SIGMA_YAW_RATE_RAD_S * rng.standard_normal(len(t_s))
    return np.column_stack([t_s, speed, -rate])


def drive(series: Series, rng: np.random.Generator | None) -> tuple[list[GnssEpoch], np.ndarray, np.ndarray]:
    """One flight as a drive: (epochs on the file's time, odometry (n, 3), truth times (n,))."""
    t = series.t_s - series.t_s[0]
    epochs = [e.replace(t_gps_s=float(ti), time_base="dataset")
              for e, ti in zip(series.epochs, t, strict=True)]
    return epochs, course_odometry(t, series.truth_v_ned_m_s, rng), t


def export(out_dir: Path, mission: str, profiles: Sequence[int], seeds: Sequence[int],
           max_duration_s: float | None = None) -> dict[str, Any]:
    out_dir.mkdir(parents=True, exist_ok=True)
    drives = []
    for p in profiles:
        for s in seeds:
            (series,) = simulate(mission, SCENARIO, [p], [s], max_duration_s)
            epochs, odo, t = drive(series, np.random.default_rng([ODOM_SEED, p, s]))
            name = f"{mission}_p{p}_s{s}"
            smartloc.write_input(out_dir / f"{name}_Input.txt", epochs, odo)
            smartloc.write_truth(out_dir / f"{name}_GT.txt", t, series.truth_ecef_m)
            h = series.horizontal_m
            drives.append({"input": f"{name}_Input.txt", "mission": mission, "profile": p, "seed": s,
                           "epochs": len(epochs), "duration_s": float(t[-1]), "fixes": int(h.size),
                           "receiver_fix_median_m": float(np.median(h)),
                           "receiver_fix_p95_m": float(np.percentile(h, 95)),
                           "altitude_span_m": float(np.ptp(_up_m(series.truth_ecef_m)))})
    return {"scenario": SCENARIO, "flown": "on the truth (simcal.receiver_flight)",
            "odometry_seed": ODOM_SEED, "drives": drives}


def _up_m(p_ecef_m: np.ndarray) -> np.ndarray:
    """Height change (m) from the first position along its local vertical."""
    p = np.asarray(p_ecef_m, dtype=float)
    up = p[0] / np.linalg.norm(p[0])
    return (p - p[0]) @ up


def markdown(r: dict[str, Any]) -> str:
    lines = [f"smartLoc drives from the simulator (scenario {r['scenario']}, flown {r['flown']}):", ""]
    lines += table_lines(("input", "epochs", "duration (s)", "receiver fix median (m)", "p95 (m)",
                          "altitude span (m)"),
                         ((d["input"], str(d["epochs"]), f"{d['duration_s']:.0f}",
                           f"{d['receiver_fix_median_m']:.2f}", f"{d['receiver_fix_p95_m']:.2f}",
                           f"{d['altitude_span_m']:.1f}") for d in r["drives"]))
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(allow_abbrev=False, prog="python -m gcs_tools.evaluate.smartloc_export",
                                description=(__doc__ or "").splitlines()[0])
    p.add_argument("--out", type=Path, required=True, help="directory for the *_Input.txt / *_GT.txt drives")
    p.add_argument("--mission", default="mild", help="flown under the canyon scenario")
    p.add_argument("--profiles", default="3,4", help="e.g. 0-9 or 3,4")
    p.add_argument("--seeds", default="0", help="e.g. 0-2 (tuning: 1000 on)")
    p.add_argument("--max-duration-s", type=float, default=None, help="cut each flight there")
    args = p.parse_args(argv)

    def compute() -> dict[str, Any]:
        profiles, seeds = choices.seeds(args.profiles, "--profiles"), choices.seeds(args.seeds)
        max_duration_s = choices.positive(args.max_duration_s, "--max-duration-s")
        return export(args.out, args.mission, profiles, seeds, max_duration_s)

    return write_results_or_error(args.out, compute, markdown)


if __name__ == "__main__":
    raise SystemExit(main())
