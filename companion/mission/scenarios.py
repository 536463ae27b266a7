"""Named sensor-realism scenarios, the ONE table: what each lays under a mission's own sections.

A mission picks one with ``scenario:`` (or ``--scenario`` on fly / sitl / evaluate); a field the
mission's own ``imu:`` / ``gnss:`` / ``ahrs:`` / ``estimator:`` section sets wins over the scenario's
(``Mission.settings(section)``). Each scenario holds the simulated sensors (read by
``simvehicle.config``) AND what the filter is told about them (its ``estimator`` section, read by
``companion.wiring.mission_estimator_config``), so the two cannot drift apart.

- ``paper``: the paper's idealised sensors (white-noise IMU, TRUE attitude sent, the GNSS
  degradation of eq. 22-27, which is exactly the Gauss-Markov bias the filter carries). The
  default; bit-identical to the simulator before scenarios existed.
- ``realistic``: a consumer MEMS IMU, TDK InvenSense ICM-42688-P (datasheet DS-000347):
  accelerometer noise density 70 µg/√Hz, gyro 0.0028 °/s/√Hz, accelerometer zero-g offset
  ±20 mg, gyro zero-rate offset ±0.5 °/s, sensitivity tolerance ±0.5 % (tolerances read as ±3σ
  of the turn-on draw). The datasheet gives no in-run bias stability: the random walks are ours,
  typical of the class (accelerometer 0.5 mg after 100 s, gyro 0.01 °/s after 100 s). The
  paper's 0.08 m/s² and our 0.003 rad/s white noise stay as airframe vibration. The attitude
  sent is an onboard complementary filter's estimate on that IMU (``simvehicle.ahrs``). GNSS as
  in ``paper``, with the receiver's Doppler velocity (``simvehicle.gnss``: white noise plus a
  reflection error proportional to the speed in canyons), as real receivers report it.
- ``mismatch``: ``realistic`` plus GNSS the filter does not model (``simvehicle.nlos``): NLOS
  reflections stepping the fix when a building blocks a satellite, satellite-count-dependent
  noise, Student-t (3 dof) noise, and a canyon bias correlation time of 10 s where the filter
  assumes 3 s.
- ``canyon``: ``realistic`` plus a raw GNSS receiver in the 3-D city (``simvehicle.receiver``):
  per-satellite line of sight, roof-edge diffraction, facade reflections (NLOS and multipath),
  C/N0, tracking noise and a receiver clock on nominal GPS + GLONASS orbits; the fixes are its
  single-point solutions (5 Hz) with their own reported accuracies, and the raw epochs come out
  beside them (``StepOutput.gnss_raw``, UBX in SITL). Calibrated against the smartLoc Berlin
  drive (docs/simcal.md).
"""

from __future__ import annotations

import math
from typing import Any

from companion.domain.physics import STANDARD_GRAVITY_M_S2 as G0_M_S2
from companion.errors import not_one_of

_DEG = math.pi / 180.0

ICM_42688_P: dict[str, Any] = {
    "acc_noise_density_m_s2_rt_hz": 70e-6 * G0_M_S2,  # 70 µg/√Hz
    "gyro_noise_density_rad_s_rt_hz": 0.0028 * _DEG,  # 0.0028 °/s/√Hz
    "acc_bias_turn_on_m_s2": 20e-3 * G0_M_S2 / 3.0,  # ±20 mg zero-g offset = ±3σ
    "gyro_bias_turn_on_rad_s": 0.5 * _DEG / 3.0,  # ±0.5 °/s zero-rate offset = ±3σ
    "acc_bias_walk_m_s2_rt_s": 0.5e-3 * G0_M_S2 / 10.0,  # (ours) 0.5 mg after 100 s
    "gyro_bias_walk_rad_s_rt_s": 0.01 * _DEG / 10.0,  # (ours) 0.01 °/s after 100 s
    "acc_scale_factor": 0.005 / 3.0,  # ±0.5 % sensitivity tolerance = ±3σ
    "gyro_scale_factor": 0.005 / 3.0,
}

UNMODELLED_GNSS: dict[str, Any] = {
    "nlos": True,
    "nlos_delay_mean_m": 1.0,  # an urban receiver's NLOS delays reach tens of metres; 1 m keeps it flyable
    "satellite_noise": True,
    "heavy_tail_dof": 3.0,
    "gamma_canyon_s": 10.0,  # the filter's bias_tau_s is 3 s
}

# What the filter is told about the simulated IMU of each scenario (under the mission's own
# ``estimator:`` section, which wins). The paper's IMU is white noise with no bias, so the filter
# carries no IMU error states there (a bias state with a real MEMS prior can only add noise: measured
# in docs/estimator.md, "What the paper scenario's filter is told"), and its 0.08 m/s² per 200 Hz
# sample with the true attitude is a noise density of 0.08 / √200 ≈ 0.006 m/s²/√Hz. The realistic
# scenarios' MEMS IMU has a bias (the EstimatorConfig defaults, real-log values, stay) and an
# onboard AHRS's attitude errors: the density is the ablation tuning sweep's choice for both
# (docs/results/ablation/rows-*.yaml).
PAPER_IMU_PRIOR: dict[str, Any] = {
    "sigma_acc_m_s2": 0.006, "sigma_acc_bias0_m_s2": 0.0, "sigma_acc_bias_rw_m_s2_sqrt_s": 0.0,
    "sigma_acc_ned0_m_s2": 0.0, "sigma_acc_ned_rw_m_s2_sqrt_s": 0.0,
}
MEMS_IMU_PRIOR: dict[str, Any] = {"sigma_acc_m_s2": 0.4}

# A real receiver reports a Doppler velocity (simvehicle.gnss); the paper's gives positions only.
RECEIVER_VELOCITY: dict[str, Any] = {"velocity": True}
# C/N0 that tells a signal's error as on the smartLoc drive (docs/simcal.md, "C/N0 that tells the error"):
# diffuse multipath (Rician fading), unmapped reflections weaker the longer their path, reacquisition from
# 18 dB-Hz.
# Not the canyon's default yet: to make it so, RAW_RECEIVER = {"enabled": True, **CN0_REALISM}.
CN0_REALISM: dict[str, Any] = {"diffuse_fading": True, "cn0_acquire_dbhz": 18.0,
                               "unmapped_spreading_ref_m": 40.0, "unmapped_delay_mean_m": 80.0}
RAW_RECEIVER: dict[str, Any] = {"enabled": True}  # its values: simvehicle.config.ReceiverConfig

SCENARIO_SECTIONS: dict[str, dict[str, dict[str, Any]]] = {
    "paper": {"estimator": PAPER_IMU_PRIOR},
    "realistic": {"imu": ICM_42688_P, "ahrs": {"enabled": True}, "gnss": RECEIVER_VELOCITY,
                  "estimator": MEMS_IMU_PRIOR},
    "mismatch": {"imu": ICM_42688_P, "ahrs": {"enabled": True},
                 "gnss": {**UNMODELLED_GNSS, **RECEIVER_VELOCITY}, "estimator": MEMS_IMU_PRIOR},
    "canyon": {"imu": ICM_42688_P, "ahrs": {"enabled": True}, "receiver": RAW_RECEIVER,
               "estimator": MEMS_IMU_PRIOR},
}
SCENARIOS: tuple[str, ...] = tuple(SCENARIO_SECTIONS)  # the names (``paper`` is the default)


def scenario_sections(name: str) -> dict[str, dict[str, Any]]:
    """The sections of scenario ``name`` (copies); unknown names are a one-line error."""
    if name not in SCENARIO_SECTIONS:
        raise not_one_of("scenario", name, SCENARIOS)
    return {section: dict(fields) for section, fields in SCENARIO_SECTIONS[name].items()}
