"""What a log reader yields besides the estimator's samples, and what every reader reports.

A reader is an iterable of, in arrival order, the domain samples of
:mod:`companion.domain.samples` (``ImuSample``, ``AttitudeSample``, ``GnssFix`` with its validity
time) and :class:`Reference` / :class:`LocalReference` positions (the autopilot's own estimate,
ground truth) that the replay compares the estimate with and never gives the estimator.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Protocol

from companion.domain.geodesy import LocalNedFrame
from companion.domain.samples import AttitudeSample, GnssFix, ImuSample

AUTOPILOT = "autopilot_estimate"
TRUTH = "truth"
MIN_FIX_TYPE_3D = 3


@dataclass(frozen=True, slots=True)
class Reference:
    """A reference position given geodetically (degrees, degrees, metres MSL unless noted)."""

    kind: str  # AUTOPILOT or TRUTH
    t_us: int
    lat_deg: float
    lon_deg: float
    alt_m: float
    source: str = ""  # message/topic: a reader may yield several sources of one kind


@dataclass(frozen=True, slots=True)
class LocalReference:
    """A reference position in NED metres in a local frame: about an origin the log does not state
    (its ``ReferenceInfo.alignment`` fits one), or the replay's own frame (alignment ``geodetic``:
    a reader with an ``anchor``, whose local data define the frame)."""

    kind: str
    t_us: int
    p_ned_m: tuple[float, float, float]
    source: str = ""


Event = ImuSample | AttitudeSample | GnssFix | Reference | LocalReference


@dataclass(frozen=True)
class ReferenceInfo:
    """Where a reference came from and how its origin is aligned (``companion.metrics``)."""

    source: str  # message/topic name(s)
    alignment: str  # companion.metrics.ALIGNMENTS
    note: str


@dataclass
class ReaderStats:
    """Counters every reader keeps while it is iterated."""

    decoded: Counter[str] = field(default_factory=Counter)  # samples yielded, by group (imu, ...)
    rejected: Counter[str] = field(default_factory=Counter)  # decoded but refused, by reason
    skipped: Counter[str] = field(default_factory=Counter)  # unreadable spans, by reason
    skipped_bytes: int = 0
    records: int = 0  # records (frames, messages) read
    position: int = 0  # bytes, for progress
    size: int = 0


class LogReader(Protocol):
    format: str  # "tlog", "dataflash", "ulog", "ansfl"
    stats: ReaderStats
    sources: dict[str, str | None]  # imu / attitude / gnss -> the message or topic used
    references: dict[str, ReferenceInfo]  # kind -> the source the summary reports (final after iterating)

    @property
    def anchor(self) -> LocalNedFrame | None:
        """The frame the log's local data are in (a log with no geodetic position, e.g. ANSFL):
        the replay's home; None: the home is the log's first 3-D fix."""
        ...

    def __iter__(self) -> Iterator[Event]: ...

    def first_fix(self) -> GnssFix | None: ...

    def describe_empty(self) -> str: ...
