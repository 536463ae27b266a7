"""``python -m gcs_tools.evaluate.attitude_check``: the attitude an IMU is integrated with, simulator vs real.

    python -m gcs_tools.evaluate.attitude_check --corpus ansfl/ --flights 1,2,3,5 \\
        --mission default-tuning --profiles 0-3 --seeds 1000-1001 --ahrs gnss-velocity --out DIR

The measure (what a filter's white acceleration density has to cover): the IMU's specific force rotated
to NED with the attitude the autopilot sends, plus gravity, integrated over a window of T seconds,
minus the true velocity change over it; per horizontal axis, a constant removed (what the filters' bias
states absorb), its RMS divided by √T (m/s²/√Hz; a white density gives the same number at every T, an
attitude error correlated over seconds a number growing with T). Per flight, at T = 0.2, 1, 2, 5 s.

* Real: the ANSFL quadrotor flights (:mod:`gcs_tools.replay.ansfl`), the IMU's own attitude, the RTK
  truth's velocity by a central difference over ±0.5 s of its 10 Hz positions (so T = 0.2 s and 1 s
  there also measure the truth's smoothing: read 2 s and 5 s).
* Simulator: each flight flown as ``tight_sim`` flies it (the loose filter in the loop; ``--scenario``,
  default ``canyon``), the attitude sent (``simvehicle.ahrs``: ``--ahrs`` picks its gravity reference)
  against the simulator's true velocity; also the attitude's tilt error (angle between the sent and the
  true down axis), RMS per flight. ANSFL has no truth attitude: the tilt is the simulator's only.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from companion.domain.physics import STANDARD_GRAVITY_M_S2
from companion.domain.rotation import rotation_matrix
from companion.errors import UserError
from gcs_tools import choices
from gcs_tools.evaluate.tight import table_lines
from gcs_tools.evaluate.tight_sim import AHRS_REFERENCES, sim_config
from gcs_tools.jsonvalues import write_results_or_error

if TYPE_CHECKING:
    from companion.estimator.navigator import Navigator
    from companion.planning import Route
    from simvehicle.vehicle import SimVehicle, StepOutput

WINDOWS_S = (0.2, 1.0, 2.0, 5.0)
GRID_S = 0.1  # window starts


def velocity_error_density(t_s: np.ndarray, a_ned_m_s2: np.ndarray, t_v_s: np.ndarray, v_ned_m_s: np.ndarray,
                           window_s: float, grid_s: float = GRID_S) -> float:
    """RMS over window starts (every ``grid_s``) and both horizontal axes of ∫a dt − Δv_true over
    ``window_s``, a constant removed per axis, divided by √window (module docstring). ``a`` at ``t_s``
    (held over each sample interval), the true velocity at ``t_v_s`` (interpolated)."""
    t = np.asarray(t_s, float)
    a = np.asarray(a_ned_m_s2, float)[:, :2]
    cum = np.vstack([np.zeros((1, 2)), np.cumsum(a[:-1] * np.diff(t)[:, None], axis=0)])
    t_v, v = np.asarray(t_v_s, float), np.asarray(v_ned_m_s, float)[:, :2]
    x = np.arange(max(t[0], t_v[0]), min(t[-1], t_v[-1]) - window_s, grid_s)
    if x.size < 2:
        raise UserError(f"a record of {t[-1] - t[0]:.1f} s is too short for a {window_s} s window")

    def at(tt: np.ndarray, y: np.ndarray, q: np.ndarray) -> np.ndarray:
        return np.column_stack([np.interp(q, tt, y[:, i]) for i in range(y.shape[1])])

    e = (at(t, cum, x + window_s) - at(t, cum, x)) - (at(t_v, v, x + window_s) - at(t_v, v, x))
    e = e - e.mean(axis=0)
    return float(np.sqrt(np.mean(e ** 2)) / np.sqrt(window_s))


def central_velocity(t_s: np.ndarray, p_m: np.ndarray, at_s: np.ndarray, half_s: float = 0.5) -> np.ndarray:
    """Velocity at ``at_s`` from positions (interpolated) differenced over ±``half_s``."""
    t, p = np.asarray(t_s, float), np.asarray(p_m, float)
    return np.column_stack([(np.interp(at_s + half_s, t, p[:, i]) - np.interp(at_s - half_s, t, p[:, i]))
                            / (2 * half_s) for i in range(p.shape[1])])


def tilt_error_rad(q_est: np.ndarray, q_true: np.ndarray) -> np.ndarray:
    """Angle between the estimated and the true down axis (roll/pitch error, yaw ignored), per row."""
    d_est = rotation_matrix(np.asarray(q_est, float))[:, 2, :]
    d_true = rotation_matrix(np.asarray(q_true, float))[:, 2, :]
    return np.arccos(np.clip(np.sum(d_est * d_true, axis=1), -1.0, 1.0))


def densities(t_s: np.ndarray, a_ned: np.ndarray, t_v: np.ndarray, v_ned: np.ndarray) -> dict[str, float]:
    return {f"{w:g}": velocity_error_density(t_s, a_ned, t_v, v_ned, w) for w in WINDOWS_S}


def real_flight(path: Path) -> dict[str, Any]:
    from gcs_tools.replay.ansfl import flight_files, load_flight

    files = flight_files(path)
    if files is None:
        raise UserError(f"{path}: not an ANSFL flight directory")
    f = load_flight(*files)
    t_v = np.arange(f.t_truth_s[0] + 0.5, f.t_truth_s[-1] - 0.5, 0.05)
    v = central_velocity(f.t_truth_s, f.p_truth_ned_m, t_v)
    return {"flight": path.name, "duration_s": round(float(f.t_s[-1] - f.t_s[0]), 1),
            "density": densities(f.t_s, f.a_ned_m_s2(), t_v, v)}


def flown_on_estimate(sim: SimVehicle, nav: Navigator, route: Route, end_us: int) -> Iterator[StepOutput]:
    """Each control period of ``sim`` to ``end_us``, flown on ``nav``'s estimate: the period's attitude,
    IMU and released fixes (with the receiver's reported accuracies) pushed in arrival order."""
    est = None
    while sim.t_us < end_us:
        out = sim.advance(est, route.setpoint(sim.t_us))
        fixes = list(zip(out.gnss_arrival_us, out.gnss_ned, strict=True))
        k = 0
        for att, imu in zip(out.attitude, out.imu, strict=True):
            nav.push(att)
            nav.push(imu)
            while k < len(fixes) and fixes[k][0] <= imu.t_us:
                f = fixes[k][1]
                nav.push_fix_ned(f.t_validity_us, f.p_ned_m, *sim.gnss.reported_accuracies_m(f))
                k += 1
        est = nav.estimate()
        yield out


def sim_flight(mission: str, profile: int, seed: int, ahrs_gnss_velocity: bool | None,
               max_duration_s: float | None = None, scenario: str = "canyon") -> dict[str, Any]:
    """One flight flown as ``tight_sim`` flies it (the loose second-order filter in the loop) under
    ``scenario`` (one with an AHRS: ``realistic``, ``mismatch``, ``canyon``), measured."""
    from companion.mission import load_mission
    from companion.wiring import navigator_for
    from simvehicle.harness.fly import planned_route
    from simvehicle.vehicle import SimVehicle

    m = load_mission(mission, scenario)
    cfg = sim_config(m, ahrs_gnss_velocity)
    if not cfg.ahrs.enabled:
        raise UserError(f"scenario {scenario!r} sends the true attitude: choose one with an AHRS")
    nav = navigator_for(m, "second-order")
    route = planned_route(m, profile, 1.0)
    sim = SimVehicle(m, profile, seed, cfg)
    end_us = round(min(1.0 + route.duration_s * 1.5, max_duration_s or 1e9) * 1e6)
    t: list[np.ndarray] = []
    a: list[np.ndarray] = []
    v: list[np.ndarray] = []
    tilt: list[np.ndarray] = []
    g = np.array([0.0, 0.0, STANDARD_GRAVITY_M_S2])
    for out in flown_on_estimate(sim, nav, route, end_us):
        q = out.q_att_ned_frd
        t.append(np.asarray(out.tick_us, float) * 1e-6)
        a.append(np.einsum("nij,nj->ni", rotation_matrix(q), out.acc_frd_m_s2) + g)
        v.append(out.v_ned_m_s)
        tilt.append(tilt_error_rad(q[-1:], out.q_ned_frd[-1:]))
    tt = np.concatenate(t)
    tilt_deg = np.degrees(np.concatenate(tilt))
    return {"profile": profile, "seed": seed, "duration_s": round(float(tt[-1] - tt[0]), 1),
            "tilt_rms_deg": float(np.sqrt(np.mean(tilt_deg ** 2))),
            "tilt_p95_deg": float(np.percentile(tilt_deg, 95)),
            "density": densities(tt, np.concatenate(a), tt, np.concatenate(v))}


def _range(rows: list[dict[str, Any]]) -> dict[str, list[float]]:
    return {w: [min(r["density"][w] for r in rows), float(np.median([r["density"][w] for r in rows])),
                max(r["density"][w] for r in rows)] for w in rows[0]["density"]} if rows else {}


def markdown(r: dict[str, Any]) -> str:
    heads = ("flight", *(f"T = {w} s" for w in r["windows_s"]), "tilt RMS (°)")
    body: list[tuple[str, ...]] = []
    for f in r["real"]:
        body.append((f"real {f['flight']}", *(f"{f['density'][f'{w:g}']:.2f}" for w in r["windows_s"]), "—"))
    for f in r["sim"]:
        body.append((f"sim {r['mission']} p{f['profile']} s{f['seed']}",
                     *(f"{f['density'][f'{w:g}']:.2f}" for w in r["windows_s"]), f"{f['tilt_rms_deg']:.2f}"))
    for side in ("real", "sim"):
        rng = r["range"][side]
        if rng:
            body.append((f"{side}: min / median / max", *("{:.2f} / {:.2f} / {:.2f}".format(*rng[f"{w:g}"])
                                                          for w in r["windows_s"]), ""))
    return (f"Velocity-error density (m/s²/√Hz) of the IMU integrated with the attitude sent; simulator: "
            f"{r['mission']} / {r.get('scenario', 'canyon')}, gravity reference {r['ahrs']}.\n\n"
            + "\n".join(table_lines(heads, body)) + "\n")


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(allow_abbrev=False, prog="python -m gcs_tools.evaluate.attitude_check",
                                description=(__doc__ or "").splitlines()[0])
    p.add_argument("--corpus", type=Path, default=None,
                   help="the ANSFL corpus directory (none: no real flights)")
    p.add_argument("--flights", default="1,2,3,5", help="ANSFL path numbers (path_N), comma-separated")
    p.add_argument("--mission", default="default-tuning")
    p.add_argument("--profiles", default="0-3")
    p.add_argument("--seeds", default="1000-1001", help="simulator seeds (none: no simulator flights)")
    p.add_argument("--scenario", default="canyon", help="the simulator's sensor scenario (one with an AHRS)")
    p.add_argument("--ahrs", choices=tuple(AHRS_REFERENCES), default="mission")
    p.add_argument("--max-duration-s", type=float, default=None)
    p.add_argument("--out", type=Path, default=Path("runs/attitude-check"))
    args = p.parse_args(argv)

    def compute() -> dict[str, Any]:
        real = ([real_flight(args.corpus / f"path_{n}") for n in choices.seeds(args.flights, "--flights")]
                if args.corpus is not None else [])
        ahrs = AHRS_REFERENCES[args.ahrs]
        max_duration_s = choices.positive(args.max_duration_s, "--max-duration-s")
        sim = ([sim_flight(args.mission, pr, s, ahrs, max_duration_s, args.scenario)
                for pr in choices.seeds(args.profiles, "--profiles") for s in choices.seeds(args.seeds)]
               if args.seeds not in ("", "none") else [])
        return {"mission": args.mission, "scenario": args.scenario, "ahrs": args.ahrs,
                "windows_s": list(WINDOWS_S), "real": real, "sim": sim,
                "range": {"real": _range(real), "sim": _range(sim)},
                "sim_tilt_rms_deg": [min((f["tilt_rms_deg"] for f in sim), default=float("nan")),
                                     max((f["tilt_rms_deg"] for f in sim), default=float("nan"))]}

    return write_results_or_error(args.out, compute, markdown)


if __name__ == "__main__":
    raise SystemExit(main())
