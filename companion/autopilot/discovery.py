"""The autopilot is the one the link carries consistently; one forged HEARTBEAT cannot take its place.

A *candidate* is a sender whose HEARTBEAT says it is a flight controller: component 1
(MAV_COMP_ID_AUTOPILOT1), ``autopilot`` not MAV_AUTOPILOT_INVALID and a vehicle ``type`` (not a
ground station, companion, gimbal, camera, ...). ``target_system`` (``--target-system``) pins
the system id: then no other system can be a candidate at all, and the pinned one is chosen as
soon as it qualifies (nothing to elect).

The election: from the first candidate HEARTBEAT on, every frame of every candidate is counted
for ``election_s`` (wall time). A candidate qualifies with ``min_heartbeats`` HEARTBEATs of one
type and autopilot, at least ``heartbeat_spacing_s`` apart (a HEARTBEAT that changes them starts
its count again; a burst of them counts as one). When the window is
over and a candidate qualifies, the one whose link carries the most frames wins (a real
autopilot streams; a forged HEARTBEAT is a frame or two). A qualified candidate with ten times
the frames of all the others together wins at once if it has ``decisive_frames``
frames or ``decisive_heartbeats`` HEARTBEATs, once its first HEARTBEAT is ``decisive_after_s`` old
(an autopilot streaming, or a SITL at x10 sending HEARTBEATs ten times a wall second, is not kept
waiting; a forged burst that arrives before the autopilot's first frame decides nothing). Nothing
is sent before that.

After the election the choice is never changed. Messages of other systems (ground stations,
other vehicles: ArduPilot routes them between its ports) or other components are not used and
are counted (``other_system``, ``other_component``; ``before_discovery`` while electing). A
second autopilot is an alarm, not a switch: its HEARTBEATs are counted
(``conflicting_autopilot``), their system ids kept (:attr:`Discovery.conflicting_systems`, at
most :data:`MAX_LISTED`) and the first one reported (:attr:`Discovery.alarms`, once). So is a
HEARTBEAT of the chosen autopilot with another type or autopilot (``inconsistent_heartbeat``:
not used, it does not keep the autopilot alive). With
``target_system`` other vehicles are expected (a swarm on one network): counted only.

The autopilot is lost after ``heartbeat_timeout_s`` without its HEARTBEAT (a reboot, a link
gap) and given up for good after ``lost_timeout_s`` (the process then ends with an error).
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

AUTOPILOT_COMPONENT = mavlink.MAV_COMP_ID_AUTOPILOT1
MAX_LISTED = 32  # conflicting system ids listed in the summary (all are counted)
NOT_VEHICLES = frozenset((  # HEARTBEAT types that are not a flight controller
    mavlink.MAV_TYPE_GCS, mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_TYPE_GIMBAL,
    mavlink.MAV_TYPE_ADSB, mavlink.MAV_TYPE_CAMERA, mavlink.MAV_TYPE_CHARGING_STATION,
    mavlink.MAV_TYPE_FLARM, mavlink.MAV_TYPE_SERVO, mavlink.MAV_TYPE_ODID, mavlink.MAV_TYPE_BATTERY,
    mavlink.MAV_TYPE_PARACHUTE, mavlink.MAV_TYPE_LOG, mavlink.MAV_TYPE_OSD, mavlink.MAV_TYPE_IMU,
    mavlink.MAV_TYPE_GPS, mavlink.MAV_TYPE_WINCH,
))


@dataclass(frozen=True, slots=True)
class Autopilot:
    system_id: int
    component_id: int
    autopilot_type: int  # MAV_AUTOPILOT_* (3 = ArduPilot, 12 = PX4)
    vehicle_type: int  # MAV_TYPE_* (2 = quadrotor)

    def as_dict(self) -> dict[str, Any]:
        return {
            "system_id": self.system_id, "component_id": self.component_id,
            "autopilot_type": self.autopilot_type,
            "autopilot": enum_name("MAV_AUTOPILOT", self.autopilot_type),
            "vehicle_type": self.vehicle_type, "vehicle": enum_name("MAV_TYPE", self.vehicle_type),
        }


def enum_name(enum: str, value: int) -> str:
    entry = mavlink.enums.get(enum, {}).get(value)
    return entry.name if entry is not None else str(value)


@dataclass(frozen=True, slots=True)
class DiscoveryConfig:
    target_system: int | None = None  # --target-system: only this system id can be the autopilot
    election_s: float = 1.5  # wall time candidates are compared from the first one's HEARTBEAT
    min_heartbeats: int = 2  # consistent HEARTBEATs a candidate needs to be chosen
    decisive_frames: int = 100  # ... with this many frames (10x the rest) it wins before the window ends,
    decisive_heartbeats: int = 3  # ... or with this many HEARTBEATs (10x the rest's frames),
    decisive_after_s: float = 0.25  # ... once its first HEARTBEAT is this old (a burst decides nothing)
    heartbeat_spacing_s: float = 0.05  # HEARTBEATs closer than this count as one (a SITL at x20: 0.05 s)
    max_candidates: int = 16  # candidates tracked while electing (more are counted, not tracked)
    heartbeat_timeout_s: float = 3.0  # wall time without the autopilot's HEARTBEAT = lost (reboot or link)
    lost_timeout_s: float = 15.0  # ... and given up for good (the run ends with an error)

    def __post_init__(self) -> None:
        if self.target_system is not None and not 1 <= self.target_system <= 255:
            raise ValueError(f"target system {self.target_system}: must be 1..255")


@dataclass(slots=True)
class _Candidate:
    autopilot: Autopilot
    first_heartbeat_s: float
    heartbeats: int = 0  # consistent ones, at least heartbeat_spacing_s apart
    last_counted_s: float = -math.inf
    frames: int = 0


def _is_candidate(msg: Any) -> bool:
    return (msg.get_type() == "HEARTBEAT" and msg.get_srcComponent() == AUTOPILOT_COMPONENT
            and msg.autopilot != mavlink.MAV_AUTOPILOT_INVALID and msg.type not in NOT_VEHICLES)


@dataclass(slots=True)
class Discovery:
    config: DiscoveryConfig = field(default_factory=DiscoveryConfig)
    autopilot: Autopilot | None = None
    counters: Counter[str] = field(default_factory=Counter)
    alarms: list[str] = field(default_factory=list)  # what a reviewer must see (each kind reported once)
    conflicting_systems: set[int] = field(default_factory=set)  # other autopilots heard (at most MAX_LISTED)
    last_heartbeat_s: float = math.nan  # wall clock of the autopilot's last HEARTBEAT
    election_started_s: float = math.nan
    _candidates: dict[tuple[int, int], _Candidate] = field(default_factory=dict)
    _alarmed: set[str] = field(default_factory=set)

    def accept(self, msg: Any, now_s: float) -> bool:
        """Whether ``msg`` comes from the autopilot (electing it first, see the module doc)."""
        if self.autopilot is None:
            self._elect(msg, now_s)
            if self.autopilot is None:
                self.counters["before_discovery"] += 1
                return False
        ap = self.autopilot
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        if src != (ap.system_id, ap.component_id):
            target = self.config.target_system
            if _is_candidate(msg) and (target is None or src[0] == target):
                self.counters["conflicting_autopilot"] += 1
                self._conflicting(src[0])
                self._alarm("conflicting", f"a second autopilot (system {src[0]}, "
                            f"{enum_name('MAV_AUTOPILOT', msg.autopilot)}) on the link beside system "
                            f"{ap.system_id}: not used; pin the autopilot with --target-system")
            self.counters["other_system" if src[0] != ap.system_id else "other_component"] += 1
            return False
        if msg.get_type() == "HEARTBEAT":
            if (int(msg.autopilot), int(msg.type)) != (ap.autopilot_type, ap.vehicle_type):
                self.counters["inconsistent_heartbeat"] += 1
                self._alarm("inconsistent", f"a HEARTBEAT of system {ap.system_id} says "
                            f"autopilot {msg.autopilot}, type {msg.type} (not {ap.autopilot_type}, "
                            f"{ap.vehicle_type}): not used")
                return False
            self.last_heartbeat_s = now_s
        return True

    def _elect(self, msg: Any, now_s: float) -> None:
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        target = self.config.target_system
        candidate = self._candidates.get(src)
        if _is_candidate(msg) and (target is None or src[0] == target):
            ap = Autopilot(src[0], src[1], int(msg.autopilot), int(msg.type))
            if candidate is None:
                if len(self._candidates) >= self.config.max_candidates:
                    self.counters["candidates_not_tracked"] += 1
                    return
                candidate = self._candidates[src] = _Candidate(ap, now_s)
            if candidate.autopilot != ap:  # its type or autopilot changed: count again
                self.counters["inconsistent_heartbeat"] += 1
                candidate.autopilot, candidate.heartbeats, candidate.first_heartbeat_s = ap, 0, now_s
            if now_s - candidate.last_counted_s >= self.config.heartbeat_spacing_s:  # a burst is one
                candidate.heartbeats += 1
                candidate.last_counted_s = now_s
            if math.isnan(self.election_started_s):
                self.election_started_s = now_s
            self.last_heartbeat_s = now_s
        if candidate is not None:
            candidate.frames += 1
        if math.isnan(self.election_started_s):
            return
        qualified = [c for c in self._candidates.values() if c.heartbeats >= self.config.min_heartbeats]
        if not qualified:
            return
        winner = max(qualified, key=lambda c: c.frames)
        others = sum(c.frames for c in self._candidates.values()) - winner.frames
        cfg = self.config
        if cfg.target_system is None:  # pinned: no rival can exist, nothing to elect
            settled = now_s - winner.first_heartbeat_s >= cfg.decisive_after_s
            decisive = settled and winner.frames >= 10 * others and (
                winner.frames >= cfg.decisive_frames or winner.heartbeats >= cfg.decisive_heartbeats)
            if now_s - self.election_started_s < cfg.election_s and not decisive:
                return
        self.autopilot = winner.autopilot
        for c in self._candidates.values():
            if c is not winner:
                s = c.autopilot.system_id
                self._conflicting(s)
                self._alarm("conflicting", f"{len(self._candidates)} autopilots answered discovery: "
                            f"system {winner.autopilot.system_id} chosen ({winner.frames} frames), system "
                            f"{s} ({c.frames} frames) not used; pin the autopilot with --target-system")
        self._candidates.clear()

    def _alarm(self, kind: str, text: str) -> None:
        if kind not in self._alarmed:
            self._alarmed.add(kind)
            self.alarms.append(text)

    def _conflicting(self, system_id: int) -> None:
        if len(self.conflicting_systems) < MAX_LISTED:
            self.conflicting_systems.add(system_id)

    def heartbeat_lost(self, now_s: float) -> bool:
        return self.autopilot is not None and now_s - self.last_heartbeat_s > self.config.heartbeat_timeout_s

    def given_up(self, now_s: float) -> bool:
        """The autopilot has been silent for ``lost_timeout_s``: it is not coming back."""
        return self.autopilot is not None and now_s - self.last_heartbeat_s > self.config.lost_timeout_s
