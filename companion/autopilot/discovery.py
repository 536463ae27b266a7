"""The autopilot found by its HEARTBEAT; everything from other systems ignored and counted.

The first HEARTBEAT whose ``autopilot`` is not MAV_AUTOPILOT_INVALID (a flight controller, not
a ground station or another companion) fixes the target system and component. After that only
messages from that system and component are used: the rest are counted by reason
(``other_system``, ``other_component``, ``before_discovery``). A reboot of the autopilot is
seen as its boot time going back by more than :attr:`DiscoveryConfig.reboot_backstep_s`, or as
a HEARTBEAT gap longer than :attr:`DiscoveryConfig.heartbeat_timeout_s` (wall time).
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

from pymavlink.dialects.v20 import common as mavlink


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
            "autopilot": _enum_name("MAV_AUTOPILOT", self.autopilot_type),
            "vehicle_type": self.vehicle_type, "vehicle": _enum_name("MAV_TYPE", self.vehicle_type),
        }


def _enum_name(enum: str, value: int) -> str:
    entry = mavlink.enums.get(enum, {}).get(value)
    return entry.name if entry is not None else str(value)


@dataclass(frozen=True, slots=True)
class DiscoveryConfig:
    heartbeat_timeout_s: float = 3.0  # wall time without the autopilot's HEARTBEAT = lost (reboot or link)
    reboot_backstep_s: float = 1.0  # boot time going back by more than this = the autopilot rebooted


@dataclass(slots=True)
class Discovery:
    config: DiscoveryConfig = field(default_factory=DiscoveryConfig)
    autopilot: Autopilot | None = None
    counters: Counter[str] = field(default_factory=Counter)
    last_heartbeat_s: float = math.nan  # wall clock of the autopilot's last HEARTBEAT
    last_boot_us: int = -1
    reboots: int = 0

    def accept(self, msg: Any, now_s: float) -> bool:
        """Whether ``msg`` comes from the autopilot (discovering it on its first HEARTBEAT)."""
        src_system, src_component = msg.get_srcSystem(), msg.get_srcComponent()
        if self.autopilot is None:
            if msg.get_type() == "HEARTBEAT" and msg.autopilot != mavlink.MAV_AUTOPILOT_INVALID:
                self.autopilot = Autopilot(src_system, src_component, int(msg.autopilot), int(msg.type))
                self.last_heartbeat_s = now_s
                return True
            self.counters["before_discovery"] += 1
            return False
        if src_system != self.autopilot.system_id:
            self.counters["other_system"] += 1
            return False
        if src_component != self.autopilot.component_id:
            self.counters["other_component"] += 1
            return False
        if msg.get_type() == "HEARTBEAT":
            self.last_heartbeat_s = now_s
        return True

    def heartbeat_lost(self, now_s: float) -> bool:
        return self.autopilot is not None and now_s - self.last_heartbeat_s > self.config.heartbeat_timeout_s

    def boot_time(self, t_boot_us: int) -> bool:
        """Note the autopilot's boot time from a stamped message; True when it went back (reboot)."""
        rebooted = self.last_boot_us - t_boot_us > self.config.reboot_backstep_s * 1e6
        if rebooted:
            self.reboots += 1
        if rebooted or t_boot_us > self.last_boot_us:
            self.last_boot_us = t_boot_us
        return rebooted
