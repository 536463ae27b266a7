"""``python -m gcs_tools.evaluate.tight_sim``: the tight-coupling rows on the calibrated simulator.

Each flight (mission, profile, seed) is flown in process under the ``canyon`` sensor scenario (the
raw GNSS receiver calibrated to smartLoc, docs/simcal.md) with the loosely coupled second-order
filter in the loop, as ``fly`` does; the same IMU, attitude and raw receiver epochs
(``StepOutput.gnss_raw``, satellite states from the sky's broadcast ephemerides) go, in arrival
order, to one tightly coupled navigator per row (open loop: they estimate, the loose filter flies).
Every control step each row's position is compared with the truth (horizontal distance):

* ``spp``: the receiver's latest single-point fix as it arrived (what a consumer of the fixes has);
* ``loose``: the filter flying the vehicle (its single-point fixes, second-order);
* ``tight-<row>``: ``companion.tight`` with each weighting, IMU-driven (``TightConfig()``), no map;
* ``tight-second-order-map``: the belief with the mission's map as its line-of-sight prior
  (``companion.wiring.tight_navigator_for``), and ``tight-second-order-imperfect-map`` with an
  imperfect map: every building's height off by N(0, 2.5²) m and its footprint moved by N(0, 1.5²) m per
  axis, drawn per flight from ``[MAP_SEED, profile, seed]`` (``City.perturbed``);
* ``tight-second-order-map-sm`` and ``tight-second-order-imperfect-map-sm`` (``--rows``, flown on request):
  those two with shadow matching as a horizontal position fix (``TightConfig.shadow_matching``,
  ``companion.tight.shadow``); every run also reports each tight row's |error| along and across the
  truth's horizontal velocity (the street the route follows: per-flight medians, their mean);
* ``tight-second-order-map-free``: that belief's estimate constrained to the map's free space as the
  companion feeds it with ``--mission --free-space`` (``companion.estimator.freespace``: an estimate
  inside a building moved to its reported Gaussian's mean outside them). This simulator's vehicle,
  flown on the loose filter's 15-20 m errors, passes through buildings (a third of the steps on
  profiles 3-4), where the premise "a position inside a building is impossible" does not hold; so both
  rows are also scored on the steps whose truth is outside every building (``... (truth outside
  buildings)``).

``--cn0-missing``: every epoch reaches the tight rows without C/N0 (NaN, as ``tight_variants``'
``cn0-missing`` does to a real drive; the receiver and its fixes unchanged): what C/N0 is worth to each row.

``--baro relative|absolute``: the simulator's barometer (``simvehicle.baro``) rides on the IMU samples and
the tight rows fuse it (their baro offset state, started relative to their own height; ``absolute``: the
barometer zeroed at home, as ArduPilot's at arming, and its datum known to them); without it the samples
carry none. The flight, the receiver and the loose
filter are the same either way (the barometer has its own random stream), so the two runs pair. Every
run also reports each row's vertical |error| (median and p95 per flight, their mean).

``--fly-on-truth``: the vehicle flies its planned route on the truth (as ``simcal`` flies it), the loose
filter only estimating, so the receiver's path stays in the streets whatever the filters do (the packaged
``mild`` city is reported so: docs/tight.md, "A milder city"). ``--rows`` takes ``naive`` and
``first-order`` too (not flown by default). ``--sigma-acc A``: the tight rows' white acceleration density;
``--rate-hz R``: the tight rows get only the first raw epoch of every 1/R s; ``--ahrs``: the simulated
autopilot's gravity reference (``accelerometer`` or ``gnss-velocity``: ``AhrsConfig``).

Intervals: per-flight medians and 95th percentiles, bootstrap over flights (seeded), and paired
differences between rows over the same flights.

Reported accuracy (``coverage``, per tight row): the fraction of steps whose horizontal error lies
inside the reported 1-σ and 2-σ ellipses (NEES_h = e_N²/σ_N² + e_E²/σ_E² ≤ 1 and ≤ 4; a consistent
2-D Gaussian: 39.3 % and 86.5 %), for the covariance reported (``NavEstimate.cov_diag``, the filter's
P inflated by its measured consistency) and for P alone, with the medians of the error and of the
reported ``horiz_accuracy`` = sqrt(σ_N² + σ_E²).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from companion.domain.samples import NavEstimate
from companion.errors import UserError
from companion.tight import RawGnss, TightConfig
from gcs_tools import choices
from gcs_tools.evaluate.tight import table_lines
from gcs_tools.jsonvalues import write_results_or_error

if TYPE_CHECKING:
    from companion.mission import Mission
    from simvehicle.config import SimConfig

ROWS = ("cn0-elevation", "fde", "student-t", "second-order")
EXTRA_ROWS = ("naive", "first-order")  # flown on request (``--rows``): fixed weights, the first-order belief
MAP_ROWS = ("second-order-map", "second-order-imperfect-map")  # the belief with the map's prior
# flown on request (``--rows``): the map rows with shadow matching as a position fix (shadow_matching)
SHADOW_ROWS = ("second-order-map-sm", "second-order-imperfect-map-sm")
FREE_ROW = "tight-second-order-map-free"  # the map belief's estimate kept out of the buildings (as fed)
OUTSIDE = " (truth outside buildings)"  # the free-space rows again, on the steps whose truth is outside
BELIEF_ROWS = ("tight-second-order", *(f"tight-{r}" for r in (*MAP_ROWS, *SHADOW_ROWS)))
MAP_SEED = 7
MAP_SIGMA_HEIGHT_M = 2.5
MAP_SIGMA_SHIFT_M = 1.5
# the simulated autopilot's gravity reference as ``--ahrs`` names it: AhrsConfig.gnss_velocity_reference
# set to this (None: the mission's own)
AHRS_REFERENCES: dict[str, bool | None] = {"mission": None, "accelerometer": False, "gnss-velocity": True}
# --baro: the tight rows' barometer; "absolute": its datum known (TightConfig.baro_datum_m, σ
# baro_datum_sigma_m)
BARO_MODES = ("relative", "absolute")


def sim_config(mission: Mission, ahrs_gnss_velocity: bool | None, baro: str | None = "relative") -> SimConfig:
    """The mission's ``simvehicle`` configuration, its AHRS's GNSS-velocity reference switched on (True)
    or off (False) when told (None: as the mission has it); ``baro`` (``BARO_MODES``) None: the IMU samples
    carry no barometer (its own random stream: the flight is the same), "absolute": its datum is home's
    altitude (zeroed there, as ArduPilot's at arming: no datum error, the drift from boot on)."""
    from simvehicle.config import sim_config_for

    cfg = sim_config_for(mission)
    if baro is None and cfg.imu.baro:
        cfg = dataclasses.replace(cfg, imu=dataclasses.replace(cfg.imu, baro=False))
    elif baro == "absolute":
        cfg = dataclasses.replace(cfg, imu=dataclasses.replace(cfg.imu, baro=True, baro_datum_sigma_m=0.0))
    if ahrs_gnss_velocity is None:
        return cfg
    ahrs = dataclasses.replace(cfg.ahrs, gnss_velocity_reference=ahrs_gnss_velocity)
    return dataclasses.replace(cfg, ahrs=ahrs)


def fly_rows(mission: str, profile: int, seed: int, rows: Sequence[str] = ROWS,
             max_duration_s: float | None = None, maps: bool = True,
             accuracy: dict[str, list[tuple[float, ...]]] | None = None,
             on_raw: Callable[[str, Any, Any], None] | None = None,
             fly_on_truth: bool = False, cn0_missing: bool = False, tight_config: TightConfig | None = None,
             rate_hz: float | None = None, ahrs_gnss_velocity: bool | None = None, baro: str | None = None,
             vertical: dict[str, list[float]] | None = None,
             across: dict[str, list[tuple[float, float]]] | None = None) -> dict[str, np.ndarray]:
    """Horizontal errors (m) per control step of each row on one flight (``maps``: and the belief with
    the exact and an imperfect map); ``accuracy`` (if given) collects per tight row and step (NEES_h
    reported, NEES_h of P alone, reported horiz_accuracy); ``on_raw(row, raw, navigator)`` (if given) is
    called after each row's navigator was given a raw epoch (``simvehicle.receiver.RawObservation``,
    with the simulator's truth per satellite); ``fly_on_truth``: the vehicle flies its planned route on
    the truth (as ``simcal`` flies it), the loose filter only estimates, so the receiver's path depends on
    no estimator and stays in the streets; ``cn0_missing``: the tight rows get every epoch without C/N0;
    ``tight_config``: the tight rows' configuration (default ``TightConfig()``); ``rate_hz``: the tight rows
    get only the first raw epoch of every 1 / rate_hz (the receiver and the loose filter unchanged);
    ``ahrs_gnss_velocity``: the simulated autopilot's attitude with (True) or without (False) its
    GNSS-velocity reference (``AhrsConfig``; None: the mission's); ``baro`` (``BARO_MODES``; None: none):
    the simulator's barometer with the IMU samples, the tight rows fuse it (the loose filter and the flight
    are unchanged), "absolute" with its datum at home's altitude and known to the tight rows;
    ``vertical`` (if given) collects each row's |vertical error| (m) per scored step (the free-space row's
    is its map row's); ``across`` (if given) each tight row's |horizontal error| (m) along and across the
    truth's horizontal velocity (the street, as the route follows it) on the steps faster than 1 m/s.
    ``rows`` may name ``SHADOW_ROWS`` (with ``maps``): the map rows with shadow matching."""
    from companion.estimator.freespace import constrain
    from companion.mission import load_mission
    from companion.wiring import mission_city, navigator_for, tight_navigator_for
    from simvehicle.harness.fly import planned_route
    from simvehicle.rawgnss import RawGnssModel
    from simvehicle.vehicle import SimVehicle

    m = load_mission(mission, "canyon")
    nav = navigator_for(m, "second-order")
    route = planned_route(m, profile, 1.0)
    sim = SimVehicle(m, profile, seed, sim_config(m, ahrs_gnss_velocity, baro))
    tcfg = tight_config or TightConfig()
    if baro == "absolute":
        tcfg = dataclasses.replace(tcfg, baro_datum_m=float(m.frame.home_alt_m))
    period_us = None if rate_hz is None else round(1e6 / rate_hz)
    last_slot = None
    gnss = sim.gnss
    assert isinstance(gnss, RawGnssModel)  # the canyon scenario's receiver
    store = gnss.store
    tight = {r: tight_navigator_for(m, r, config=tcfg, ephemerides=store, city=None) for r in rows
             if r not in SHADOW_ROWS}
    if maps:
        city = mission_city(m)
        imperfect = city.perturbed(np.random.default_rng([MAP_SEED, profile, seed]), MAP_SIGMA_HEIGHT_M,
                                   MAP_SIGMA_SHIFT_M)
        for name, c in zip(MAP_ROWS, (city, imperfect), strict=True):
            tight[name] = tight_navigator_for(m, "second-order", config=tcfg, ephemerides=store,
                                              city=c)
        sm_cfg = dataclasses.replace(tcfg, shadow_matching=True)
        for name, c in zip(SHADOW_ROWS, (city, imperfect), strict=True):
            if name in rows:
                tight[name] = tight_navigator_for(m, "second-order", config=sm_cfg, ephemerides=store, city=c)
    end_us = round(min(1.0 + route.duration_s * 1.5, max_duration_s or 1e9) * 1e6)
    outside_rows = (f"tight-{MAP_ROWS[0]}", FREE_ROW) if maps else ()
    errors: dict[str, list[float]] = {k: [] for k in ("spp", "loose", *(f"tight-{r}" for r in tight),
                                                      *outside_rows, *(r + OUTSIDE for r in outside_rows))}
    last_fix = None
    est = fly = None
    while sim.t_us < end_us:
        out = sim.advance(fly, route.setpoint(sim.t_us))
        if gnss.store is not store:  # the sky's ephemerides extended
            store = gnss.store
            for t in tight.values():
                t.update_ephemerides(store)
        fixes = list(zip(out.gnss_arrival_us, out.gnss_ned, strict=True))
        raws = sorted(out.gnss_raw, key=lambda o: o.arrival_us)
        if period_us is not None:  # the first epoch of every period only
            first = []
            for o in raws:
                if o.t_us // period_us != last_slot:
                    last_slot = o.t_us // period_us
                    first.append(o)
            raws = first
        k = j = 0
        for att, imu in zip(out.attitude, out.imu, strict=True):
            nav.push(att)
            nav.push(imu)
            for t in tight.values():
                t.push(att)
                t.push(imu)
            while k < len(fixes) and fixes[k][0] <= imu.t_us:
                f = fixes[k][1]
                nav.push_fix_ned(f.t_validity_us, f.p_ned_m, *sim.gnss.reported_accuracies_m(f))
                last_fix = np.asarray(f.p_ned_m, float)
                k += 1
            while j < len(raws) and raws[j].arrival_us <= imu.t_us:
                epoch = raws[j].epoch
                if cn0_missing:
                    epoch = epoch.replace(cn0_dbhz=np.full(epoch.n, np.nan))
                for name, t in tight.items():
                    t.push(RawGnss(raws[j].t_us, epoch))
                    if on_raw is not None:
                        on_raw(name, raws[j], t)
                j += 1
        est = nav.estimate()
        tr = out.final_truth
        fly = est if not fly_on_truth else NavEstimate(out.t_us, tr.p_ned_m, tr.v_ned_m_s, tr.gnss_bias_ned_m,
                                                        np.zeros(9), 1.0, math.nan, "truth")
        truth = np.asarray(tr.p_ned_m, float)
        if est is None or last_fix is None:
            continue
        rows_now: dict[str, Any] = {"spp": last_fix, "loose": est.p_ned_m}
        ests = {r: t.estimate() for r, t in tight.items()}
        for r, e in ests.items():
            rows_now[f"tight-{r}"] = None if e is None else e.p_ned_m
        if maps:
            e = ests[MAP_ROWS[0]]
            kept = None if e is None else constrain(np.asarray(e.p_ned_m)[:2], np.asarray(e.cov_diag)[:2],
                                                    m.world.clearance_m)
            rows_now[FREE_ROW] = None if e is None else e.p_ned_m if kept is None else kept.p_ne_m
        if any(v is None for v in rows_now.values()):
            continue
        for name, p in rows_now.items():
            errors[name].append(float(np.hypot(p[0] - truth[0], p[1] - truth[1])))
            if vertical is not None:
                pv = rows_now[f"tight-{MAP_ROWS[0]}"] if name == FREE_ROW else p
                vertical.setdefault(name, []).append(abs(float(pv[2]) - float(truth[2])))
        v_h = np.asarray(tr.v_ned_m_s[0:2], float)
        if across is not None and float(np.hypot(*v_h)) > 1.0:
            u = v_h / float(np.hypot(*v_h))
            for r in ests:
                d = np.asarray(rows_now[f"tight-{r}"][0:2], float) - truth[0:2]
                along_across = (abs(float(d @ u)), abs(float(d[1] * u[0] - d[0] * u[1])))
                across.setdefault(f"tight-{r}", []).append(along_across)
        if outside_rows and m.world.clearance_m(truth[0], truth[1]) > 0.0:
            for name in outside_rows:
                errors[name + OUTSIDE].append(errors[name][-1])
        if accuracy is not None:
            for r, e in ests.items():
                assert e is not None
                d2 = (np.asarray(e.p_ned_m[0:3]) - truth[0:3]) ** 2
                cov = np.asarray(e.cov_diag[0:3])
                now = tight[r].engine.output_now()  # P alone: the filter's own variances
                p_alone = cov if now is None else now[1][9:12]
                accuracy.setdefault(f"tight-{r}", []).append(
                    (float(np.sum(d2[0:2] / cov[0:2])), float(np.sum(d2[0:2] / p_alone[0:2])),
                     float(np.sqrt(cov[0] + cov[1])), float(d2[2] / cov[2]), float(d2[2] / p_alone[2])))
    return {k: np.asarray(v) for k, v in errors.items()}


def run(mission: str, profiles: Sequence[int], seeds: Sequence[int], rows: Sequence[str] = ROWS,
        n_resamples: int = 2000, rng_seed: int = 0, max_duration_s: float | None = None,
        fly_on_truth: bool = False, cn0_missing: bool = False, sigma_acc_m_s2: float | None = None,
        rate_hz: float | None = None, ahrs_gnss_velocity: bool | None = None, baro: str | None = None
        ) -> dict[str, Any]:
    tcfg = TightConfig() if sigma_acc_m_s2 is None else TightConfig(sigma_acc_m_s2=sigma_acc_m_s2)
    flights: list[dict[str, Any]] = []
    acc: dict[str, list[tuple[float, ...]]] = {}
    err: dict[str, list[np.ndarray]] = {}
    for p in profiles:
        for s in seeds:
            vert: dict[str, list[float]] = {}
            acr: dict[str, list[tuple[float, float]]] = {}
            e = fly_rows(mission, p, s, rows, max_duration_s, accuracy=acc, fly_on_truth=fly_on_truth,
                         cn0_missing=cn0_missing, tight_config=tcfg, rate_hz=rate_hz,
                         ahrs_gnss_velocity=ahrs_gnss_velocity, baro=baro, vertical=vert, across=acr)
            for k, v in e.items():
                err.setdefault(k, []).append(v)
            flights.append({"profile": p, "seed": s, "steps": int(len(e["spp"])),
                            "median_m": {k: float(np.median(v)) for k, v in e.items()},
                            "p95_m": {k: float(np.percentile(v, 95)) for k, v in e.items()},
                            "vertical_median_m": {k: float(np.median(v)) for k, v in vert.items()},
                            "vertical_p95_m": {k: float(np.percentile(v, 95)) for k, v in vert.items()},
                            # |error| along / across the truth's velocity (the street), per-flight median
                            "along_median_m": {k: float(np.median(np.asarray(v)[:, 0]))
                                               for k, v in acr.items()},
                            "across_median_m": {k: float(np.median(np.asarray(v)[:, 1]))
                                                for k, v in acr.items()}})
    names = list(flights[0]["median_m"])
    rng = np.random.default_rng(rng_seed)
    idx = rng.integers(0, len(flights), size=(n_resamples, len(flights)))
    out_rows: dict[str, dict[str, Any]] = {}
    paired: list[dict[str, Any]] = []

    def pair(stat: str, row: str, ref: str) -> None:  # row − reference over the same flight resamples
        d = table[row] - table[ref]
        lo, hi = np.percentile(d[idx].mean(axis=1), [2.5, 97.5])
        paired.append({"stat": stat, "row": row, "reference": ref, "mean_diff_m": float(d.mean()),
                       "ci": [float(lo), float(hi)]})

    for stat in ("median_m", "p95_m"):
        table = {n: np.array([f[stat][n] for f in flights]) for n in names}
        for n, v in table.items():
            lo, hi = np.percentile(v[idx].mean(axis=1), [2.5, 97.5])
            out_rows.setdefault(n, {})[stat] = {"mean": float(v.mean()), "ci": [float(lo), float(hi)]}
        for row in (b for b in BELIEF_ROWS if b in table):
            for ref in names:
                if not (ref in BELIEF_ROWS or ref == FREE_ROW or ref.endswith(OUTSIDE)):
                    pair(stat, row, ref)
        for sm, ref in ((f"tight-{SHADOW_ROWS[0]}", f"tight-{MAP_ROWS[0]}"),
                        (f"tight-{SHADOW_ROWS[1]}", f"tight-{MAP_ROWS[1]}"),
                        (f"tight-{SHADOW_ROWS[0]}", "tight-second-order")):
            if sm in table and ref in table:  # what shadow matching adds to the map row it extends
                pair(stat, sm, ref)
        map_row = f"tight-{MAP_ROWS[0]}"
        for sfx in ("", OUTSIDE):  # what the free-space constraint adds to the map belief it constrains
            if FREE_ROW + sfx in table:
                pair(stat, FREE_ROW + sfx, map_row + sfx)
    for stat in ("vertical_median_m", "vertical_p95_m", "along_median_m", "across_median_m"):  # means over
        # flights (reported, not paired)
        for n in flights[0][stat]:
            out_rows[n][stat] = float(np.mean([f[stat][n] for f in flights]))
    # (absent: flown on the loose filter, the defaults)
    flown: dict[str, Any] = {"fly_on_truth": True} if fly_on_truth else {}
    if cn0_missing:
        flown["cn0_missing"] = True
    if baro is not None:
        flown["baro"] = baro
    for key, val in (("sigma_acc_m_s2", sigma_acc_m_s2), ("rate_hz", rate_hz),
                     ("ahrs_gnss_velocity", ahrs_gnss_velocity)):
        if val is not None:
            flown[key] = val
    return {"mission": mission, "scenario": "canyon", "profiles": list(profiles), "seeds": list(seeds),
            **flown,
            "flights": flights, "rows": out_rows, "paired": paired,
            "coverage": {k: coverage(np.asarray(v), np.concatenate(err[k])) for k, v in acc.items()},
            "method": "per-flight median and p95 of the horizontal error at every control step; mean over "
                      f"flights with a bootstrap over flights ({n_resamples} resamples, seed {rng_seed})"}


def coverage(acc: np.ndarray, errors_m: np.ndarray) -> dict[str, float]:
    """Pooled over steps: fractions inside the 1-σ / 2-σ ellipses (reported and P alone), the same
    vertically (|e_D| ≤ σ_D, 2 σ_D: 68.3 % / 95.4 % for a consistent Gaussian), medians."""
    return {"reported_1sigma": float(np.mean(acc[:, 0] <= 1.0)),
            "reported_2sigma": float(np.mean(acc[:, 0] <= 4.0)),
            "p_1sigma": float(np.mean(acc[:, 1] <= 1.0)), "p_2sigma": float(np.mean(acc[:, 1] <= 4.0)),
            "vertical_reported_1sigma": float(np.mean(acc[:, 3] <= 1.0)),
            "vertical_reported_2sigma": float(np.mean(acc[:, 3] <= 4.0)),
            "vertical_p_1sigma": float(np.mean(acc[:, 4] <= 1.0)),
            "vertical_p_2sigma": float(np.mean(acc[:, 4] <= 4.0)),
            "median_error_m": float(np.median(errors_m)),
            "median_horiz_accuracy_m": float(np.median(acc[:, 2]))}


def markdown(r: dict[str, Any]) -> str:
    def ci(v: list[float], sign: str = "") -> str:
        return f"[{v[0]:{sign}.2f}, {v[1]:{sign}.2f}]"

    flown = ", the vehicle flown on the truth" if r.get("fly_on_truth") else ""
    flown += ", the tight rows without C/N0" if r.get("cn0_missing") else ""
    flown += f", the tight rows with the barometer ({r['baro']})" if r.get("baro") else ""
    flown += "".join(f", {k} {r[k]}" for k in ("sigma_acc_m_s2", "rate_hz", "ahrs_gnss_velocity") if k in r)
    lines = [f"{r['mission']} / canyon, profiles {r['profiles']}, seeds {r['seeds']}{flown}: {r['method']}.",
             ""]
    lines += table_lines(("row", "median (m)", "95 % CI", "p95 (m)", "95 % CI"),
                         ((n, f"{s['median_m']['mean']:.2f}", ci(s["median_m"]["ci"]),
                           f"{s['p95_m']['mean']:.2f}", ci(s["p95_m"]["ci"])) for n, s in r["rows"].items()))
    vert = [(n, v) for n, v in r["rows"].items() if "vertical_median_m" in v]
    if vert:
        lines += ["", "Vertical |error|, mean over flights of the per-flight median and p95 (m):", "",
                  *table_lines(("row", "vertical median (m)", "vertical p95 (m)"),
                               ((n, f"{v['vertical_median_m']:.2f}", f"{v['vertical_p95_m']:.2f}")
                                for n, v in vert))]
    street = [(n, v) for n, v in r["rows"].items() if "across_median_m" in v]
    if street:
        lines += ["", "|Error| along and across the truth's velocity (the street), mean over flights of the "
                  "per-flight median (m):", "",
                  *table_lines(("row", "along (m)", "across (m)"),
                               ((n, f"{v['along_median_m']:.2f}", f"{v['across_median_m']:.2f}")
                                for n, v in street))]
    lines += ["", *table_lines(("row − reference", "statistic", "mean difference (m)", "95 % CI"),
                               ((f"{c['row']} − {c['reference']}", c["stat"].removesuffix("_m"),
                                 f"{c['mean_diff_m']:+.2f}", ci(c["ci"], "+")) for c in r["paired"]))]
    lines += ["", "Reported accuracy, pooled over steps (a consistent 2-D Gaussian: 39.3 % inside 1 σ, "
              "86.5 % inside 2 σ):", "",
              *table_lines(("row", "inside 1 σ", "inside 2 σ", "P alone: 1 σ", "2 σ", "median error (m)",
                            "median horiz_accuracy (m)", "vertical 1 σ / 2 σ", "P alone"),
                           ((n, f"{c['reported_1sigma']:.1%}", f"{c['reported_2sigma']:.1%}",
                             f"{c['p_1sigma']:.1%}", f"{c['p_2sigma']:.1%}", f"{c['median_error_m']:.2f}",
                             f"{c['median_horiz_accuracy_m']:.2f}",
                             f"{c['vertical_reported_1sigma']:.1%} / {c['vertical_reported_2sigma']:.1%}",
                             f"{c['vertical_p_1sigma']:.1%} / {c['vertical_p_2sigma']:.1%}")
                            for n, c in r["coverage"].items()))]
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(allow_abbrev=False, prog="python -m gcs_tools.evaluate.tight_sim",
                                description=(__doc__ or "").splitlines()[0])
    p.add_argument("--mission", default="default")
    p.add_argument("--profiles", default="3,4")
    p.add_argument("--seeds", default="0,1,2")
    p.add_argument("--out", type=Path, default=Path("runs/tight-sim"))
    p.add_argument("--max-duration-s", type=float, default=None)
    p.add_argument("--fly-on-truth", action="store_true",
                   help="the vehicle flies its planned route on the truth (the loose filter only estimates)")
    p.add_argument("--cn0-missing", action="store_true",
                   help="the tight rows get every epoch without C/N0 (NaN; the receiver unchanged)")
    p.add_argument("--sigma-acc", type=float, default=None,
                   help="the tight rows' white acceleration density sigma_acc_m_s2 (default: TightConfig's)")
    p.add_argument("--rate-hz", type=float, default=None,
                   help="the tight rows get only the first raw epoch of every 1/RATE s (default: all)")
    p.add_argument("--ahrs", choices=tuple(AHRS_REFERENCES), default="mission",
                   help="the simulated autopilot's gravity reference (ahrs.gnss_velocity_reference; "
                        "default: the mission's)")
    p.add_argument("--baro", choices=BARO_MODES, default=None,
                   help="the simulator's barometer with the IMU samples, the tight rows fuse it (the flight "
                        "is the same); absolute: its datum at home, known to them (default: no barometer)")
    p.add_argument("--rows", default=",".join(ROWS),
                   help=f"tight weightings, comma-separated (also: {', '.join((*EXTRA_ROWS, *SHADOW_ROWS))}: "
                        "the map rows with shadow matching)")
    args = p.parse_args(argv)

    def compute() -> dict[str, Any]:
        profiles, seeds = choices.seeds(args.profiles, "--profiles"), choices.seeds(args.seeds)
        rows = [v for v in args.rows.split(",") if v]
        bad = sorted(set(rows) - set(ROWS) - set(EXTRA_ROWS) - set(SHADOW_ROWS))
        if bad or not rows:
            raise UserError(f"--rows: choose from {', '.join((*ROWS, *EXTRA_ROWS, *SHADOW_ROWS))}")
        return run(args.mission, profiles, seeds, rows,
                   max_duration_s=choices.positive(args.max_duration_s, "--max-duration-s"),
                   fly_on_truth=args.fly_on_truth, cn0_missing=args.cn0_missing,
                   sigma_acc_m_s2=choices.positive(args.sigma_acc, "--sigma-acc"),
                   rate_hz=choices.positive(args.rate_hz, "--rate-hz"),
                   ahrs_gnss_velocity=AHRS_REFERENCES[args.ahrs], baro=args.baro)

    return write_results_or_error(args.out, compute, markdown)

if __name__ == "__main__":
    raise SystemExit(main())
