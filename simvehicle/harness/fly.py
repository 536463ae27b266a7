"""In-process flight: vehicle, planner, autopilot and estimator closed in one process.

Per control period (20 Hz): ``out = sim.advance(est, sp)``; the period's attitude, IMU and
released GNSS samples go to the ``Navigator`` in arrival order (fixes as ``out.gnss_ned`` via
``push_fix_ned``: in one process both sides share the mission frame, so the geodetic wire form,
exact to ~1 µm, is skipped; SITL flies it), each with the accuracy the receiver reports on the wire
(GPS_RAW_INT ``h_acc``/``v_acc``, NaN when the mission's GNSS reports none), so the filter gets the
per-fix R the SITL companion gets; ``est = nav.estimate()``;
``sp = route.setpoint(t)``. The flight ends once the reference has arrived and the vehicle is
within ``goal_radius_m`` of the goal and slower than ``goal_speed_m_s``, or at the timeout.
No files here: ``gcs_tools.fly.output`` writes them. ``InProcessBackend`` is this loop as a
``VehicleBackend`` (``backend("inprocess")``).
"""

from __future__ import annotations

import time
from array import array
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from companion.domain.statistics import describe
from companion.errors import UserError
from companion.estimator.navigator import Navigator
from companion.mission import Mission, load_mission, with_scenario
from companion.planning import Route, plan_route
from companion.wiring import navigator_for
from simvehicle import SimVehicle
from simvehicle.harness.backend import FlightRequest, FlightResult
from simvehicle.recording import COLUMNS, ROW_FLOATS, Goal, row, series_from_rows


@dataclass(frozen=True)
class FlyConfig:
    """How a flight starts and ends."""

    start_delay_s: float = 2.0  # hover at the start before the route moves (estimator initialises)
    # reached: after the reference arrived, the TRUE position within goal_radius_m of the goal
    # and slower than goal_speed_m_s. The vehicle flies its estimate onto the goal, and near
    # buildings the GNSS multipath bias has a 1.2 m std per axis, so a tighter radius would
    # time out on estimation error rather than say whether the vehicle got there.
    goal_radius_m: float = 2.0
    goal_speed_m_s: float = 1.0
    timeout_margin_s: float = 30.0  # timeout = start delay + route duration + max(margin, 50 % of duration)



_ROUTES: dict[tuple[int, int, float], tuple[Mission, Route]] = {}
_ROUTES_KEPT = 16


def planned_route(mission: Mission, profile_index: int, t_start_s: float) -> Route:
    """``plan_route``, remembered for the last few (mission, profile, start) in this process.

    A campaign flies each profile with every method: the route (a pure function of the frozen
    mission) is planned once per worker instead of once per flight. The entry holds the
    mission itself, so its ``id`` cannot be reused while the entry lives.
    """
    key = (id(mission), profile_index, t_start_s)
    hit = _ROUTES.get(key)
    if hit is not None and hit[0] is mission:
        return hit[1]
    route = plan_route(mission, profile_index, t_start_s=t_start_s)
    if len(_ROUTES) >= _ROUTES_KEPT:
        del _ROUTES[next(iter(_ROUTES))]
    _ROUTES[key] = (mission, route)
    return route


def fly(mission: Mission | str, profile_index: int, method: str, seed: int,
        max_duration_s: float | None = None, config: FlyConfig | None = None,
        on_navigator: Callable[[Navigator], None] | None = None) -> FlightResult:
    """Fly one profile of ``mission`` with estimator ``method``; deterministic given ``seed``.
    ``on_navigator``: called with the flight's navigator before the first sample (a diagnostic may
    observe its engine, e.g. ``gcs_tools.evaluate.trust_probe``)."""
    cfg = config or FlyConfig()
    m = load_mission(mission) if isinstance(mission, str) else mission
    if seed < 0:
        raise UserError(f"--seed must be >= 0, got {seed}")
    nav = navigator_for(m, method)  # checks the method first
    if on_navigator is not None:
        on_navigator(nav)
    route = planned_route(m, profile_index, cfg.start_delay_s)
    sim = SimVehicle(m, profile_index, seed)
    end_s = cfg.start_delay_s + route.duration_s + max(cfg.timeout_margin_s, 0.5 * route.duration_s)
    if max_duration_s is not None:
        end_s = min(end_s, max_duration_s)
    end_us = round(end_s * 1e6)
    goal = Goal(route.waypoints_ned_m[-1], cfg.goal_radius_m, cfg.goal_speed_m_s,
                arrive_after_s=route.t_start_s + route.duration_s)
    push, push_fix_ned = nav.push, nav.push_fix_ned
    accuracies_m = sim.gnss.reported_accuracies_m  # what the model's to_fix puts on the wire
    vel_accuracy = sim.gnss.reported_velocity_accuracy_m_s
    rows = array("d")  # recording.ROW_FLOATS floats per control step: 216 B, not two domain objects (~2 kB)
    fix_rows = array("d")  # FIX_FIELDS floats per fix received
    engine, rejected_before = nav.engine, 0  # its gate counter, read after each fix
    est, collisions, in_contact, reached = None, 0, False, False
    wall0 = time.perf_counter()
    while sim.t_us < end_us:
        out = sim.advance(est, route.setpoint(sim.t_us))
        fixes = list(zip(out.gnss_arrival_us, out.gnss_ned, strict=True))
        k = 0
        for att, imu in zip(out.attitude, out.imu, strict=True):
            push(att)
            push(imu)
            while k < len(fixes) and fixes[k][0] <= imu.t_us:
                fix = fixes[k][1]
                h_acc, v_acc = accuracies_m(fix)  # in the mission frame: no geodesy
                push_fix_ned(fix.t_validity_us, fix.p_ned_m, h_acc, v_acc, fix.v_ned_m_s, vel_accuracy(fix))
                n_rejected = engine.counts["gnss_rejected_innovation"]
                fix_rows.extend((fixes[k][0], fix.t_validity_us, *fix.p_ned_m, h_acc,
                                 n_rejected - rejected_before))
                rejected_before = n_rejected
                k += 1
        est = nav.estimate()
        truth = out.final_truth
        rows.extend(row(out.t_us, truth, est))  # p_ref: filled from the route below
        collisions += out.collided and not in_contact
        in_contact = out.collided
        if goal.reached(out.t_us * 1e-6, truth.p_ned_m, truth.v_ned_m_s):
            reached = True
            break
    wall_s = time.perf_counter() - wall0
    r = np.frombuffer(rows, dtype=float).reshape(-1, ROW_FLOATS)
    r[:, COLUMNS["p_ref_ned_m"]] = route.reference(r[:, COLUMNS["t_s"].start])[0]
    series = series_from_rows(rows)
    counters = nav.counters()
    summary = {
        "mission": m.name,
        "profile": profile_index,
        "method": method,
        "seed": seed,
        "reached_goal": reached and collisions == 0,  # never after a collision
        "collisions": int(collisions),
        "duration_s": sim.t_us * 1e-6,
        "route_duration_s": route.duration_s,
        "wall_s": wall_s,
        "estimation_error_m": describe(series["est_error_m"]),
        "tracking_error_m": describe(series["track_error_m"]),
        "min_clearance_m": float(np.min(series["clearance_m"])),
        "gnss": {
            "sent": sim.gnss.sent,
            "fused": counters.get("gnss_fused", 0),
            "rejected": sum(v for k, v in counters.items() if k.startswith("gnss_rejected")),
        },
        "estimator_counters": counters,
    }
    return FlightResult(summary, series, route, fixes=_fixes(fix_rows))


FIX_FIELDS = 7  # t_arrival_us, t_validity_us, p_ned_m(3), h_acc_m, rejected


def _fixes(fix_rows: array) -> dict[str, np.ndarray]:
    """Every fix the filter received: arrival and validity times [s], position in the mission
    frame [m], the accuracy it reported [m] and whether the innovation gate rejected it (the
    change of the gate's count as it arrived: they add up to ``gnss_rejected_innovation``)."""
    r = np.frombuffer(fix_rows, dtype=float).reshape(-1, FIX_FIELDS)
    return {"t_s": r[:, 0] * 1e-6, "t_validity_s": r[:, 1] * 1e-6, "p_ned_m": r[:, 2:5], "h_acc_m": r[:, 5],
            "rejected": r[:, 6]}


class InProcessBackend:
    """Our simulator in this process (``fly``); the request's mission may be a loaded ``Mission``
    (a campaign's, with its overrides)."""

    name = "inprocess"

    def __init__(self, config: FlyConfig | None = None) -> None:
        self.config = config

    def fly(self, request: FlightRequest) -> FlightResult:
        m = request.mission
        if isinstance(m, str):
            m = load_mission(m)
        if request.scenario is not None:
            m = with_scenario(m, request.scenario)
        return fly(m, request.profile, request.method, request.seed, request.max_duration_s, self.config)
