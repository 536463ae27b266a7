"""The companion's local NED frame, and the fixes too far from it to be believed (pure: no I/O).

The frame's origin is ``--home`` if given (fixed from the start), else the autopilot's EKF origin
(GPS_GLOBAL_ORIGIN), else its HOME_POSITION, else the first good fix. Nothing is believed alone:

- without ``--home`` the frame is fixed only once ``fixes_to_agree`` consecutive good fixes
  (fix type >= 3) lie within ``agree_m`` of each other, so one forged or wild first fix cannot
  place the frame (a run of them that disagree starts the count again);
- an origin the autopilot reports is used only if those fixes lie within ``max_home_distance_m``
  of it (else ``rejected_origin_far_from_fixes``: a forged origin cannot place the frame either);
- once the frame is fixed, a fix farther than ``max_home_distance_m`` from its origin (the
  codec's limit, 50 km) is rejected before the filter (``rejected_gnss_far_from_home``).

Implausible origins (latitude beyond ±90°, altitude outside -1 km..20 km) are refused as they come.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from companion.domain.geodesy import LocalNedFrame
from companion.domain.samples import GnssFix
from companion.mavlink.codec import LIMITS

MIN_FIX_TYPE = 3
ORIGIN_SOURCES = ("GPS_GLOBAL_ORIGIN", "HOME_POSITION")  # in order of preference


@dataclass(frozen=True, slots=True)
class FrameConfig:
    fixes_to_agree: int = 3  # good fixes in a row that fix the frame (without --home)
    agree_m: float = 1_000.0  # ... lying this close to the first of them
    max_home_distance_m: float = LIMITS.max_home_distance_m  # a fix or origin farther is not believed


def plausible(lat_deg: float, lon_deg: float, alt_m: float) -> bool:
    """A position on (or near) the Earth: the only kind used as a frame origin or a reference."""
    return abs(lat_deg) <= 90 and abs(lon_deg) <= 180 and -1_000 <= alt_m <= 20_000


def _distance_m(frame: LocalNedFrame, lat_deg: float, lon_deg: float, alt_m: float) -> float:
    return float(np.linalg.norm(frame.to_ned_m(lat_deg, lon_deg, alt_m)))


@dataclass(slots=True)
class FrameChooser:
    config: FrameConfig = field(default_factory=FrameConfig)
    home: LocalNedFrame | None = None  # --home
    frame: LocalNedFrame | None = None
    source: str = ""
    origins: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    counters: Counter[str] = field(default_factory=Counter)
    _pending: list[GnssFix] = field(default_factory=list)

    def __post_init__(self) -> None:
        if self.home is not None:
            self.frame, self.source = self.home, "option --home"

    def origin(self, kind: str, lla: tuple[float, float, float]) -> bool:
        """An origin the autopilot reports (``kind`` in :data:`ORIGIN_SOURCES`); False if implausible."""
        if not plausible(*lla):
            self.counters[f"rejected_{kind.lower()}"] += 1
            return False
        self.origins[kind] = lla
        return True

    def fix(self, fix: GnssFix) -> bool:
        """Whether ``fix`` may reach the filter (counted when not). Fixes before the frame is fixed
        only count towards it (and are not used)."""
        if self.frame is None:
            if fix.fix_type < MIN_FIX_TYPE:
                return False
            self._pending.append(fix)
            if not self._agree():
                self._pending = [fix]
            if len(self._pending) < self.config.fixes_to_agree:
                return False
            self._choose()
            self._pending.clear()
        assert self.frame is not None
        distance_m = _distance_m(self.frame, fix.lat_deg, fix.lon_deg, fix.alt_m)
        if not distance_m <= self.config.max_home_distance_m:
            self.counters["rejected_gnss_far_from_home"] += 1
            return False
        return True

    def _agree(self) -> bool:
        first = self._pending[0]
        near = LocalNedFrame(first.lat_deg, first.lon_deg, first.alt_m)
        last = self._pending[-1]
        return _distance_m(near, last.lat_deg, last.lon_deg, last.alt_m) <= self.config.agree_m

    def _choose(self) -> None:
        limit = self.config.max_home_distance_m
        for kind in ORIGIN_SOURCES:
            lla = self.origins.get(kind)
            if lla is None:
                continue
            candidate = LocalNedFrame(*lla)
            if all(_distance_m(candidate, f.lat_deg, f.lon_deg, f.alt_m) <= limit for f in self._pending):
                self.frame, self.source = candidate, kind
                return
            self.counters["rejected_origin_far_from_fixes"] += 1
        first = self._pending[0]
        self.frame, self.source = LocalNedFrame(first.lat_deg, first.lon_deg, first.alt_m), "first good fix"
