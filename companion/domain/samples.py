"""Domain types that cross the wire. Frames and units are in the field names.

Times are integers in microseconds of vehicle boot time (``t_us``); a GNSS fix carries the
time its position is VALID (``t_validity_us``), which is earlier than its arrival.
Vectors are ``numpy`` float arrays of shape (3,); quaternions are (w, x, y, z), body FRD
to NED.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import MISSING, dataclass, field, fields
from typing import Any

import numpy as np

Vec3 = np.ndarray


def _slots_function(cls: type, init: bool) -> Callable[..., Any]:
    """For a frozen dataclass with slots: ``cls(...)`` (``init`` False: a function of the constructor's
    arguments) or its ``__init__`` (True), the same arguments, defaults and object, each field set through
    its slot's descriptor instead of the dataclass ``__init__``'s ``object.__setattr__`` per field (half
    the cost for ``NavEstimate``'s 15: a navigator makes one per output). Only for classes without
    ``default_factory`` or ``__post_init__``."""
    ns: dict[str, Any] = {"_new": object.__new__, "_cls": cls}
    params, body = ["o"] if init else [], []
    for i, f in enumerate(fields(cls)):
        if f.default_factory is not MISSING or hasattr(cls, "__post_init__"):
            raise TypeError(f"{cls.__name__}: not a plain frozen dataclass with slots")
        ns[f"_set{i}"] = cls.__dict__[f.name].__set__
        if f.default is MISSING:
            params.append(f.name)
        else:
            ns[f"_d{i}"] = f.default
            params.append(f"{f.name}=_d{i}")
        body.append(f"    _set{i}(o, {f.name})\n")
    head, first, tail = ("__init__", "", "None") if init else ("new", "    o = _new(_cls)\n", "o")
    src = f"def {head}({', '.join(params)}):\n{first}{''.join(body)}    return {tail}\n"
    exec(src, ns)  # as dataclasses makes __init__
    fn = ns[head]
    if init:
        fn.__qualname__ = f"{cls.__qualname__}.__init__"
        fn.__doc__ = cls.__dict__["__init__"].__doc__
        fn.__annotations__ = {**{f.name: f.type for f in fields(cls)}, "return": None}
    return fn


def _slots_constructor(cls: type) -> Callable[..., Any]:
    """``cls(...)`` through its slots (``_slots_function``)."""
    return _slots_function(cls, init=False)


def _slots_init(cls: type) -> type:
    """The class with its dataclass ``__init__`` replaced by one that sets the fields through their slots
    (``_slots_function``): the per-sample types, which every source builds at 200 Hz."""
    cls.__init__ = _slots_function(cls, init=True)  # type: ignore[misc]
    return cls


@_slots_init
@dataclass(frozen=True, slots=True)
class ImuSample:
    """One IMU sample: specific force and angular rate in body FRD (≈ -9.81 on z at rest); with a
    barometer, its pressure altitude at the same time (m, any datum: None when there is none)."""

    t_us: int
    acc_frd_m_s2: Vec3
    gyro_frd_rad_s: Vec3
    pressure_alt_m: float | None = None


@_slots_init
@dataclass(frozen=True, slots=True)
class AttitudeSample:
    """Attitude of body FRD relative to NED as a unit quaternion (w, x, y, z)."""

    t_us: int
    q_ned_frd: np.ndarray


@dataclass(frozen=True, slots=True)
class GnssFix:
    """A GNSS position fix as received (GPS_RAW_INT), stamped with its validity time.

    ``h_acc_m``/``v_acc_m`` (1-σ accuracies) and ``hdop`` are NaN when the receiver does not
    report them. ``v_ned_m_s`` is the receiver's velocity valid at the same time (None when the
    source gives none; a component it does not report, e.g. GPS_RAW_INT's vertical, is NaN) and
    ``vel_acc_m_s`` its 1-σ speed accuracy (NaN when not reported).
    """

    t_validity_us: int
    lat_deg: float
    lon_deg: float
    alt_m: float
    fix_type: int
    satellites_visible: int
    h_acc_m: float = float("nan")
    v_acc_m: float = float("nan")
    hdop: float = float("nan")
    v_ned_m_s: Vec3 | None = None
    vel_acc_m_s: float = float("nan")


Sample = ImuSample | AttitudeSample | GnssFix


@dataclass(frozen=True, slots=True)
class NavEstimate:
    """The companion's navigation output (ODOMETRY + belief) in the local NED frame."""

    t_us: int
    p_ned_m: Vec3
    v_ned_m_s: Vec3
    b_ned_m: Vec3
    cov_diag: np.ndarray  # (9,) variances of [p, v, b] in m², (m/s)², m²
    beta: float  # GNSS trust belief in [0, 1]
    nis: float  # NIS of the last fused fix (NaN before the first)
    method: str
    # GNSS innovation gate and validity (estimator: ``EstimatorConfig`` gate/time-out fields):
    pos_horiz_test_ratio: float = float("nan")  # horizontal NIS / gate² of the last fix tested (NaN = none)
    gnss_glitch: bool = False  # the last fix failed the gate (rejected, or fused relative to a GNSS offset)
    pos_valid: bool = True  # False when no fix was fused for longer than the validity time-out
    gnss_rejected_innovation: int = 0  # fixes rejected by the innovation gate so far
    gnss_resets: int = 0  # resets to the GNSS (position, velocity, IMU error states) after the filter lost it
    vel_test_ratio: float = float("nan")  # horizontal GNSS-velocity NIS / gate² of the last fix (NaN = none)
    imu_gnss_disagreement: bool = False  # the IMU-propagated motion persistently disagrees with GNSS


# ``NavEstimate(...)``, faster (the navigators' per-output path): the same object, built through the slots
new_nav_estimate: Callable[..., NavEstimate] = _slots_constructor(NavEstimate)


@dataclass(frozen=True, slots=True)
class Setpoint:
    """Reference of the minimum-jerk trajectory (SET_POSITION_TARGET_LOCAL_NED)."""

    t_us: int
    p_ned_m: Vec3
    v_ned_m_s: Vec3
    a_ned_m_s2: Vec3


@dataclass(frozen=True, slots=True)
class TruthState:
    """Simulation truth (SIM_STATE): never reaches the estimator."""

    t_us: int
    p_ned_m: Vec3
    v_ned_m_s: Vec3
    q_ned_frd: np.ndarray
    gnss_bias_ned_m: Vec3 = field(default_factory=lambda: np.zeros(3))
    gnss_latency_s: float = 0.0
    clearance_m: float = float("inf")
