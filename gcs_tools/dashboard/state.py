"""Live telemetry state shared by the dashboard and ``beliefnav top`` (no I/O, thread-safe).

``ingest`` is called from Zenoh threads with decoded messages; ``take_frame`` (10 Hz or faster)
returns what arrived since the previous frame as plain JSON-able data and keeps a bounded history
that ``snapshot`` hands to a newly connected viewer.

Besides the plotted series a vehicle has its ``latest`` headline values, what a ground station
shows first: flight mode and armed state (``vehicle/status``), GNSS fix type, satellites, HDOP and
reported accuracy (``vehicle/gnss``), altitude above home, the estimate's horizontal variances
(the map's uncertainty ellipse), β, NIS, errors. GNSS fixes are placed on the map in the local
frame of the route's home (``bridge/route`` ``home_lla``); a fix is marked rejected when the next
estimate's ``gnss_rejected_innovation`` count went up (the fix the filter just refused).
"""

from __future__ import annotations

import math
import threading
import time
from collections import Counter, deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from companion.domain.geodesy import LocalNedFrame
from companion.domain.samples import NavEstimate, Setpoint, TruthState
from companion.telemetry import codec as zc
from companion.telemetry.pubsub import Received

SERIES = ("truth", "est", "ref", "beta", "err", "latency", "fix", "rejected")
TRUTH_MATCH_US = 30_000  # an estimate is compared with truth stamped within this much of it
STALE_S = 2.0  # [s] without any message a vehicle is shown stale (the page's STALE_S too)
AT_GOAL_M = 3.0  # [m] last true position this close to the route's goal: arrived (fly's 2 m radius + margin)
HISTORY_LEN = 30_000  # points per series kept for a new viewer (10 min of 50 Hz estimates)
MAX_UNPLACED_FIXES = 600  # fixes kept until the route's home places them on the map (30 s at 20 Hz)
FIX_TYPES = {0: "no GPS", 1: "no fix", 2: "2D fix", 3: "3D fix", 4: "DGPS", 5: "RTK float", 6: "RTK fixed"}


def _num(x: float) -> float | None:
    return round(float(x), 4) if math.isfinite(x) else None


@dataclass
class VehicleView:
    history_len: int
    series: dict[str, deque] = field(default_factory=dict)
    pending: dict[str, list] = field(default_factory=dict)
    truth_recent: deque = field(default_factory=lambda: deque(maxlen=64))  # (t_us, p_ned_m)
    counters: dict[str, dict[str, int]] = field(default_factory=dict)  # process -> counters
    status: dict[str, str] = field(default_factory=dict)
    route: dict[str, Any] | None = None
    route_new: bool = False
    latest: dict[str, Any] = field(default_factory=dict)  # headline numbers (status bar, `top`)
    messages: Counter = field(default_factory=Counter)
    last_mono_s: float = 0.0  # monotonic time of the last message (any process)
    process_mono_s: dict[str, float] = field(default_factory=dict)  # process -> monotonic time of its last
    last_truth_ned_m: np.ndarray | None = None
    goal_ned_m: np.ndarray | None = None
    frame: LocalNedFrame | None = None  # the route's home: places the fixes
    unplaced: deque = field(default_factory=lambda: deque(maxlen=MAX_UNPLACED_FIXES))  # GnssReports
    last_fix: list | None = None  # [t_s, n, e] of the newest placed fix
    rejected_count: int | None = None  # the estimate's gnss_rejected_innovation so far

    def at_goal(self) -> bool:
        if self.last_truth_ned_m is None or self.goal_ned_m is None or not np.isfinite(self.goal_ned_m).all():
            return False
        return float(np.linalg.norm(self.last_truth_ned_m - self.goal_ned_m)) <= AT_GOAL_M

    def __post_init__(self) -> None:
        for name in SERIES:
            self.series[name] = deque(maxlen=self.history_len)
            self.pending[name] = []

    def add(self, name: str, point: list) -> None:
        self.pending[name].append(point)

    def place(self, report: zc.GnssReport) -> None:
        """A fix on the map (local NED about the route's home), or kept until that home is known."""
        if self.frame is None:
            self.unplaced.append(report)
            return
        f = report.fix
        n, e, _ = (float(v) for v in self.frame.to_ned_m(f.lat_deg, f.lon_deg, f.alt_m))
        self.last_fix = [round(report.t_us * 1e-6, 4), _num(n), _num(e)]
        self.add("fix", self.last_fix)


class LiveState:
    """Per-vehicle bounded histories of tracks, fixes, belief, errors, latency and counters."""

    def __init__(self, history_len: int = HISTORY_LEN):
        self.history_len = history_len
        self.vehicles: dict[str, VehicleView] = {}
        self.malformed: Counter[str] = Counter()
        self.last_malformed = ""
        self.received = 0
        self._lock = threading.Lock()
        self._t0 = time.monotonic()

    def ingest(self, msg: Received) -> None:
        with self._lock:
            self.received += 1
            v = self.vehicles.get(msg.vehicle)
            if v is None:
                v = self.vehicles[msg.vehicle] = VehicleView(self.history_len)
            v.messages[f"{msg.process}/{msg.topic}"] += 1
            v.last_mono_s = v.process_mono_s[msg.process] = time.monotonic()
            self._ingest(v, msg.process, msg.topic, msg.obj)

    def ingest_malformed(self, key: str, payload: bytes, error: str) -> None:
        with self._lock:
            self.malformed[key] += 1
            self.last_malformed = f"{key}: {error}"[:200]

    @staticmethod
    def _ingest(v: VehicleView, process: str, topic: str, obj: Any) -> None:
        t_s = round(obj.t_us * 1e-6, 4)
        if isinstance(obj, TruthState):
            v.truth_recent.append((obj.t_us, obj.p_ned_m))
            v.last_truth_ned_m = obj.p_ned_m
            v.add("truth", [t_s, _num(obj.p_ned_m[0]), _num(obj.p_ned_m[1])])
            v.latest["clearance_m"] = obj.clearance_m
        elif isinstance(obj, NavEstimate):
            v.add("est", [t_s, _num(obj.p_ned_m[0]), _num(obj.p_ned_m[1])])
            v.latest.update(t_s=t_s, beta=obj.beta, nis=obj.nis, method=obj.method,
                            altitude_m=-float(obj.p_ned_m[2]), var_n_m2=float(obj.cov_diag[0]),
                            var_e_m2=float(obj.cov_diag[1]), est_n_m=float(obj.p_ned_m[0]),
                            est_e_m=float(obj.p_ned_m[1]))
            match = min(v.truth_recent, key=lambda tp: abs(tp[0] - obj.t_us), default=None)
            if match is not None and abs(match[0] - obj.t_us) <= TRUTH_MATCH_US:
                err = float(np.linalg.norm(obj.p_ned_m - match[1]))
                v.add("err", [t_s, _num(err)])
                v.latest["est_error_m"] = err
            count = obj.gnss_rejected_innovation
            if v.rejected_count is not None and count > v.rejected_count and v.last_fix is not None:
                v.add("rejected", list(v.last_fix))  # the fix just refused by the gate
            v.rejected_count = count
        elif isinstance(obj, zc.Belief):
            v.add("beta", [t_s, _num(obj.beta), _num(obj.nis)])
        elif isinstance(obj, zc.GnssReport):
            fix = obj.fix
            v.latest.update(fix_type=fix.fix_type, satellites=fix.satellites_visible, hdop=fix.hdop,
                            h_acc_m=fix.h_acc_m, gnss_alt_m=fix.alt_m)
            if fix.fix_type >= 2:  # a position, with its latency (a no-fix report has neither)
                v.add("latency", [t_s, _num(obj.latency_s)])
                v.latest["gnss_latency_s"] = obj.latency_s
                v.place(obj)
        elif isinstance(obj, zc.FlightStatus):
            v.latest.update(mode=obj.mode, armed=obj.armed)
        elif isinstance(obj, Setpoint):
            v.add("ref", [t_s, _num(obj.p_ned_m[0]), _num(obj.p_ned_m[1])])
        elif isinstance(obj, zc.Health):
            v.counters[process] = dict(obj.counters)
            v.status[process] = obj.status
        elif isinstance(obj, zc.RouteInfo):
            route = {"mission": obj.mission, "profile": obj.profile,
                     "waypoints_ne_m": [[_num(p[0]), _num(p[1])] for p in obj.waypoints_ned_m],
                     "buildings_ne_m": [[_num(x) for x in b] for b in obj.buildings_ne_m]}
            v.goal_ned_m = obj.goal_ned_m
            if v.frame is None and np.isfinite(obj.home_lla).all():
                v.frame = LocalNedFrame(*(float(x) for x in obj.home_lla))
                while v.unplaced:
                    v.place(v.unplaced.popleft())
            if route != v.route:
                v.route, v.route_new = route, True

    def _vehicle_json(self, v: VehicleView, series: dict[str, list], route: bool) -> dict[str, Any]:
        now = time.monotonic()
        return {
            "series": series,
            "counters": v.counters,
            "status": v.status,
            "latest": {k: (_num(x) if isinstance(x, float) else x) for k, x in v.latest.items()},
            "messages": dict(v.messages),
            "route": v.route if route else None,
            # freshness, on the server's clock (the page's clock may differ): seconds since the last message
            "age_s": round(now - v.last_mono_s, 2),
            "process_age_s": {p: round(now - t, 2) for p, t in v.process_mono_s.items()},
            "at_goal": v.at_goal(),
        }

    def take_frame(self) -> dict[str, Any]:
        """What arrived since the last frame (moved into the history)."""
        with self._lock:
            out = {}
            for name, v in self.vehicles.items():
                series = {}
                for s in SERIES:
                    series[s] = v.pending[s]
                    v.series[s].extend(v.pending[s])
                    v.pending[s] = []
                out[name] = self._vehicle_json(v, series, v.route_new)
                v.route_new = False
            return {"type": "frame", "vehicles": out, **self._totals()}

    def snapshot(self) -> dict[str, Any]:
        """The retained history (for a viewer that just connected); pending data is NOT included."""
        with self._lock:
            out = {name: self._vehicle_json(v, {s: list(v.series[s]) for s in SERIES}, True)
                   for name, v in self.vehicles.items()}
            return {"type": "snapshot", "vehicles": out, **self._totals()}

    def _totals(self) -> dict[str, Any]:
        return {"received": self.received, "malformed": sum(self.malformed.values()),
                "malformed_by_key": dict(self.malformed), "last_malformed": self.last_malformed,
                "uptime_s": round(time.monotonic() - self._t0, 1)}

    def summary(self) -> dict[str, dict[str, Any]]:
        """Headline numbers per vehicle (for ``beliefnav top``)."""
        with self._lock:
            now = time.monotonic()
            return {name: {**v.latest, "counters": {p: dict(c) for p, c in v.counters.items()},
                           "status": dict(v.status), "messages": dict(v.messages),
                           "age_s": now - v.last_mono_s,
                           "at_goal": v.at_goal()} for name, v in self.vehicles.items()}


def ended(at_goal: bool, status: dict[str, str]) -> bool:
    """The run is over (not stale): the vehicle arrived, or the estimator said it stopped cleanly."""
    return at_goal or "ended" in status.values()
