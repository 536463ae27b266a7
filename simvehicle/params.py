"""The vehicle's parameters as a ground station sees them (MAVLink parameter protocol).

The table publishes the companion estimator's parameters (handed to the vehicle process by
whoever starts both, ``--estimator-param NAME=VALUE``: the vehicle itself knows nothing of the
estimator) and the GNSS degradation parameters of the simulated vehicle, all read-only: the
estimator reads its parameters once at start, and changing the degradation model mid-flight
would silently change the seeded experiment. One parameter is writable because changing it in
flight is the point: ``SIM_GPS_DISABLE`` (1 = the vehicle withholds every GNSS fix, a total
outage; 0 = fixes flow again).

:class:`ParamServer` is pure: it answers PARAM_REQUEST_LIST / PARAM_REQUEST_READ / PARAM_SET
messages with the PARAM_VALUE messages to send (the caller sends them). As the protocol says,
a PARAM_SET that is refused (read-only, out of range) is answered with the unchanged value;
an unknown name or index gets no answer (counted). Every value is a REAL32 parameter.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

PARAM_ID_CHARS = 16

# name -> (section, field): estimator fields of companion.estimator.EstimatorConfig, GNSS
# degradation fields of simvehicle.config.GnssConfig. Units are the fields' (see those classes).
ESTIMATOR_PARAMS = {
    "EST_ACC_NOISE": "sigma_acc_m_s2",
    "EST_BIAS_TAU": "bias_tau_s",
    "EST_BIAS_MAX": "sigma_bias_max_m",
    "EST_BIAS_FLOOR": "sigma_bias_floor_m",
    "EST_GPS_H_NOISE": "sigma_gnss_horizontal_m",
    "EST_GPS_V_NOISE": "sigma_gnss_vertical_m",
    "EST_R_INFL_MAX": "r_inflation_max",
    "EST_HISTORY": "history_s",
    "EST_ETA": "eta",
    "EST_LAMBDA_REG": "lambda_reg",
    "EST_ALPHA_FAST": "alpha_fast",
    "EST_ALPHA_SLOW": "alpha_slow",
    "EST_OMEGA_FAST": "omega_fast",
    "EST_CHI2_GATE": "chi2_095",
}
DEGRADATION_PARAMS = {
    "SIMG_NOISE": "sigma_noise_m",
    "SIMG_R_URBAN": "r_urban",
    "SIMG_D_NEAR": "d_near_m",
    "SIMG_RAMP": "proximity_ramp_m",
    "SIMG_GAMMA_OPEN": "gamma_open_s",
    "SIMG_GAMMA_CANY": "gamma_canyon_s",
    "SIMG_BIAS_OPEN": "sigma_bias_open_m",
    "SIMG_BIAS_MAX": "sigma_bias_max_m",
    "SIMG_LAT_OPEN": "latency_open_s",
    "SIMG_LAT_CANYON": "latency_canyon_s",
    "SIMG_LAT_TAU": "latency_tau_s",
    "SIMG_LAT_NOISE": "latency_noise_s",
    "SIMG_LAT_CAP": "latency_cap_s",
}
GPS_DISABLE = "SIM_GPS_DISABLE"


@dataclass(slots=True)
class Param:
    name: str
    value: float
    writable: bool = False
    valid: Callable[[float], bool] = math.isfinite


def _text(raw: str | bytes) -> str:
    if isinstance(raw, bytes):
        raw = raw.split(b"\x00", 1)[0].decode("ascii", errors="replace")
    return raw.split("\x00", 1)[0]


def estimator_param_values(estimator: Any) -> dict[str, float]:
    """``EST_*`` name -> value of an EstimatorConfig (AttributeError if a field was renamed)."""
    return {name: float(getattr(estimator, f)) for name, f in ESTIMATOR_PARAMS.items()}


def mission_params(estimator: Any, gnss: Any) -> list[Param]:
    """The table for an EstimatorConfig and a GnssConfig (AttributeError if a field was renamed)."""
    return vehicle_params(estimator_param_values(estimator), gnss)


def vehicle_params(estimator_values: Mapping[str, float], gnss: Any) -> list[Param]:
    """The table: the estimator's values given (``EST_*`` names, in ``ESTIMATOR_PARAMS`` order; none
    when the vehicle flies without them), then the GnssConfig's degradation parameters."""
    params = [Param(name, float(estimator_values[name]))
              for name in ESTIMATOR_PARAMS if name in estimator_values]
    params += [Param(name, float(getattr(gnss, f))) for name, f in DEGRADATION_PARAMS.items()]
    params.append(Param(GPS_DISABLE, 0.0, writable=True, valid=lambda v: v in (0.0, 1.0)))
    for p in params:
        if len(p.name) > PARAM_ID_CHARS:
            raise ValueError(f"parameter name {p.name!r} longer than {PARAM_ID_CHARS} characters")
    return params


class ParamServer:
    """Answers the parameter protocol over a fixed table; ``changed`` lists accepted sets."""

    def __init__(self, params: list[Param], system_id: int, component_id: int) -> None:
        self.params = params
        self._index = {p.name: i for i, p in enumerate(params)}
        self.system_id = system_id
        self.component_id = component_id
        self.counters: dict[str, int] = {}

    def value(self, name: str) -> float:
        return self.params[self._index[name]].value

    def _count(self, name: str) -> None:
        self.counters[name] = self.counters.get(name, 0) + 1

    def _for_us(self, msg: Any) -> bool:
        return int(msg.target_system) in (0, self.system_id) and int(msg.target_component) in (
            0, self.component_id)

    def _param_value(self, i: int) -> mavlink.MAVLink_param_value_message:
        p = self.params[i]
        return mavlink.MAVLink_param_value_message(
            p.name.encode("ascii"), p.value, mavlink.MAV_PARAM_TYPE_REAL32, len(self.params), i)

    def _lookup(self, name: str, index: int) -> int | None:
        if index >= 0:
            return index if index < len(self.params) else None
        return self._index.get(name)

    def handle(self, msg: Any) -> tuple[list[mavlink.MAVLink_message], str | None]:
        """(PARAM_VALUE answers, a one-line note for the ground station or None)."""
        kind = msg.get_type()
        if not self._for_us(msg):
            return [], None
        if kind == "PARAM_REQUEST_LIST":
            self._count("param_list")
            return [self._param_value(i) for i in range(len(self.params))], None
        name = _text(msg.param_id)
        if kind == "PARAM_REQUEST_READ":
            i = self._lookup(name, int(msg.param_index))
            if i is None:
                self._count("param_unknown")
                return [], None
            return [self._param_value(i)], None
        if kind == "PARAM_SET":
            i = self._index.get(name)
            if i is None:
                self._count("param_unknown")
                return [], None
            p = self.params[i]
            value = float(msg.param_value)
            if not p.writable:
                self._count("param_read_only")
                return [self._param_value(i)], f"{name} is read-only in flight"
            if not p.valid(value):
                self._count("param_rejected")
                return [self._param_value(i)], f"{name}: {value:g} is not a valid value"
            p.value = value
            self._count("param_set")
            return [self._param_value(i)], f"{name} set to {value:g}"
        return [], None
