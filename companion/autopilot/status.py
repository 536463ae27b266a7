"""What a ground station shows first, from the autopilot's own messages: its flight mode and armed
state (HEARTBEAT) and its receiver's fix (GPS_RAW_INT, or GPS2_RAW with ``--gnss-instance 2``),
published as the ``status`` and ``gnss`` telemetry topics (:mod:`companion.telemetry.codec`) that
the dashboard and ``beliefnav top`` read.

Mode names are pymavlink's (``mavutil.mode_string_v10``), as MAVProxy shows them: ArduPilot's
per vehicle type (``STABILIZE``, ``GUIDED``, ``LOITER``, ...), PX4's from its custom main and sub
mode (``POSCTL``, ``OFFBOARD``, ``MISSION``, ``LOITER``, ...); armed is the HEARTBEAT's
``MAV_MODE_FLAG_SAFETY_ARMED``. ``status`` goes out once a second (wall clock) and at once when
the mode or the armed state changes.

``gnss`` goes out for every new fix the companion takes from the autopilot (the translator's fix,
its validity time on the boot clock: the dashboard's latency is the autopilot's receiver delay
plus the link), and, while the receiver has no new fix to give (no fix yet: ArduPilot stamps
nothing; a fix lost: its stamp repeats), the message as it stands once a second and at once
when its fix type or satellite count changes, stamped with the time it arrived (no latency).
Every stamp is the autopilot's boot time (the newest the link has shown).

With each ``status``, once the companion's local frame is fixed, a ``route`` without waypoints
carries that frame's origin (``home_lla``): the dashboard places the fixes on its map with it,
in the frame of the estimates.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from pymavlink import mavutil

from companion.domain.geodesy import LocalNedFrame
from companion.domain.samples import GnssFix
from companion.mavlink import codec as mc
from companion.telemetry.codec import FlightStatus, GnssReport, RouteInfo

STATUS_PERIOD_S = 1.0  # [s] wall clock between two ``status`` (and no-fix ``gnss``) publications


def flight_mode(heartbeat: Any) -> str:
    """The mode name of an autopilot's HEARTBEAT as MAVProxy shows it (``Mode(n)`` when unknown)."""
    return str(mavutil.mode_string_v10(heartbeat))


def armed(heartbeat: Any) -> bool:
    return bool(int(heartbeat.base_mode) & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED)


@dataclass
class AutopilotStatus:
    """Publishes ``status`` and ``gnss`` through ``publisher`` (anything with ``publish(topic, obj)``)."""

    publisher: Any
    period_s: float = STATUS_PERIOD_S
    _status: tuple[str, bool] | None = None
    _status_s: float = -math.inf
    _no_fix: tuple[int, int] | None = None
    _no_fix_s: float = -math.inf

    def heartbeat(self, msg: Any, t_us: int, now_s: float, frame: LocalNedFrame | None = None) -> None:
        """The autopilot's HEARTBEAT arrived at boot time ``t_us`` (wall clock ``now_s``); ``frame``:
        the companion's local frame once fixed."""
        status = (flight_mode(msg), armed(msg))
        if status == self._status and now_s - self._status_s < self.period_s:
            return
        self._status, self._status_s = status, now_s
        self.publisher.publish("status", FlightStatus(t_us, *status))
        if frame is not None:
            home = np.array([frame.home_lat_deg, frame.home_lon_deg, frame.home_alt_m])
            self.publisher.publish("route", RouteInfo(t_us, mission="", profile=0,
                                                      waypoints_ned_m=np.zeros((0, 3)), duration_s=0.0,
                                                      home_lla=home))

    def gnss(self, msg: Any, fix: GnssFix | None, t_us: int, now_s: float) -> None:
        """The autopilot's GNSS message arrived at boot time ``t_us``; ``fix`` is the new fix the
        translator took from it (None: none, e.g. no fix yet or a repeated one)."""
        if fix is not None:
            self._no_fix = None
            self.publisher.publish("gnss", GnssReport(t_us, fix))
            return
        if int(msg.fix_type) >= 2 and int(msg.time_usec) != 0:
            return  # a fix repeated (the autopilot streams faster than its receiver), or refused
        key = (int(msg.fix_type), int(msg.satellites_visible))
        if key == self._no_fix and now_s - self._no_fix_s < self.period_s:
            return
        try:
            raw = mc.GNSS_DECODERS[msg.get_type()](msg)
        except mc.CodecError:
            return  # nothing a ground station could show (the translator counted it)
        self._no_fix, self._no_fix_s = key, now_s
        self.publisher.publish("gnss", GnssReport(t_us, replace(raw, t_validity_us=t_us)))
