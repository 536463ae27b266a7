"""Raw observations of one receiver epoch, as arrays over satellites (structure of arrays).

One :class:`GnssEpoch` per receiver measurement time. Every array has one row per satellite
observation, in the same order; NaN marks a value the source does not give. Readers build epochs
(``gcs_tools.gnss``: RINEX, smartLoc, UBX); :func:`companion.gnss.ephemeris.attach_broadcast` fills
the satellite state from broadcast ephemerides; :mod:`companion.gnss.spp` solves them.

Sign conventions: ``pseudorange_rate_m_s`` = −λ·Doppler (positive when the range grows);
``sat_clock_s`` is the satellite clock offset to ADD to the pseudorange times c (it includes the
relativistic correction and the group delay of the observed signal), so that
``pseudorange + c · sat_clock_s`` is free of the satellite clock.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from companion.gnss.systems import System, sv_name


def _nan(n: int, *shape: int) -> np.ndarray:
    return np.full((n, *shape), np.nan)


@dataclass(frozen=True, slots=True, eq=False)
class GnssEpoch:
    """Observations at receiver time ``t_gps_s`` (receiver clock reading, GPS time scale)."""

    t_gps_s: float
    system: np.ndarray  # (n,) int8, companion.gnss.systems.System values
    prn: np.ndarray  # (n,) int16: PRN / slot number within the system
    pseudorange_m: np.ndarray  # (n,)
    pseudorange_var_m2: np.ndarray = field(
        default_factory=lambda: np.zeros(0)
    )  # (n,) given variance, NaN = none
    pseudorange_rate_m_s: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (n,) −λ·Doppler
    cn0_dbhz: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (n,)
    elevation_deg: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (n,) as given by the source
    azimuth_deg: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (n,)
    sat_pos_ecef_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (n, 3) at transmission
    sat_vel_ecef_m_s: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (n, 3)
    sat_clock_s: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (n,) add c·this to the pseudorange
    sat_clock_drift_s_s: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (n,)
    # True: pseudoranges already free of satellite clock AND atmosphere (smartLoc); the solver then
    # applies neither sat_clock_s nor an ionosphere/troposphere model
    corrected: bool = False
    # "gps": t_gps_s is GPS time; "dataset": a source's own relative time (smartLoc), no ephemeris use
    time_base: str = "gps"

    def __post_init__(self) -> None:
        self._check(_FIELDS)

    def _check(self, fields: tuple[tuple[str, tuple[int, ...]], ...]) -> None:
        """Each of these per-satellite fields: empty becomes NaN (n rows), another shape than n rows is a
        ValueError."""
        n = len(self.pseudorange_m)
        for name, shape in fields:
            v = getattr(self, name)
            if v.size == 0 and n:
                object.__setattr__(self, name, _nan(n, *shape))
            elif v.shape != (n, *shape):
                raise ValueError(f"GnssEpoch.{name}: shape {v.shape}, expected {(n, *shape)}")

    @property
    def n(self) -> int:
        return len(self.pseudorange_m)

    def names(self) -> list[str]:
        return [sv_name(s, p) for s, p in zip(self.system, self.prn, strict=True)]

    def select(self, mask: np.ndarray) -> GnssEpoch:
        """The epoch restricted to the rows where ``mask`` (bool (n,) or an index array)."""
        rows = {
            name: getattr(self, name)[mask]
            for name in ("system", "prn", "pseudorange_m", *(f for f, _ in _FIELDS))
        }
        return self.replace(**rows)

    def replace(self, **changes: object) -> GnssEpoch:
        """``dataclasses.replace`` (every field is an init field), without its per-field checks; with the
        same pseudoranges, the other fields set through their slots and only the changed ones checked
        (the same object as ``GnssEpoch(...)`` gives: the tight filter replaces the satellite states and
        C/N0 of every epoch)."""
        if "pseudorange_m" in changes or not _FIELD_SET.issuperset(changes):  # (an unknown name: TypeError)
            kw = {name: getattr(self, name) for name in _ALL_FIELDS}
            kw.update(changes)
            return GnssEpoch(**kw)
        new = _copy_with(self, changes)
        new._check(tuple(f for f in _FIELDS if f[0] in changes))
        return new

    def systems(self) -> tuple[System, ...]:
        return tuple(System(int(s)) for s in np.unique(self.system))


_FIELDS: tuple[tuple[str, tuple[int, ...]], ...] = (
    ("pseudorange_var_m2", ()),
    ("pseudorange_rate_m_s", ()),
    ("cn0_dbhz", ()),
    ("elevation_deg", ()),
    ("azimuth_deg", ()),
    ("sat_pos_ecef_m", (3,)),
    ("sat_vel_ecef_m_s", (3,)),
    ("sat_clock_s", ()),
    ("sat_clock_drift_s_s", ()),
)


_ALL_FIELDS: tuple[str, ...] = tuple(f.name for f in dataclasses.fields(GnssEpoch))
# (field, its slot's setter) for GnssEpoch.replace (a frozen dataclass's own __init__ goes through
# object.__setattr__ per field)
_SET_FIELD: tuple[tuple[str, Any], ...] = tuple(
    (name, GnssEpoch.__dict__[name].__set__) for name in _ALL_FIELDS
)
_NEW = object.__new__
_FIELD_SET = frozenset(_ALL_FIELDS)


def _copy_with_source() -> tuple[str, dict[str, Any]]:
    """The source of ``_copy_with(epoch, changes)``: a new GnssEpoch with each field ``changes``' or the
    epoch's, set through its slot, one line per field (a loop over the fields costs three times as much)."""
    ns: dict[str, Any] = {"_new": _NEW, "_cls": GnssEpoch}
    lines = ["def _copy_with(self, changes):", "    new = _new(_cls)", "    get = changes.get"]
    for i, (name, set_field) in enumerate(_SET_FIELD):
        ns[f"_set{i}"] = set_field
        lines.append(f"    _set{i}(new, get({name!r}, self.{name}))")
    return "\n".join([*lines, "    return new\n"]), ns


_src, _ns = _copy_with_source()
exec(_src, _ns)  # as dataclasses makes __init__
_copy_with: Any = _ns["_copy_with"]


def make_epoch(
    t_gps_s: float, system: object, prn: object, pseudorange_m: object, **arrays: object
) -> GnssEpoch:
    """Build an epoch from sequences (converted to the documented dtypes); other fields by name."""
    conv: dict[str, Any] = {}
    for k, v in arrays.items():
        conv[k] = np.asarray(v, dtype=float) if k not in ("corrected", "time_base") else v
    return GnssEpoch(
        float(t_gps_s),
        np.asarray(system, dtype=np.int8),
        np.asarray(prn, dtype=np.int16),
        np.asarray(pseudorange_m, dtype=float),
        **conv,
    )
