"""Synthetic ANSFL flights with known answers, and the real ANSFL corpus for tests.

``write_flight`` writes ``IMU_1.csv`` + ``GT.csv`` in the data set's own layout (sensor frame z up,
Euler angles w.r.t. ENU, degrees, deg/s; truth NED at 10 Hz on a clock ``offset_s`` behind the
IMU's) from an analytic trajectory, so the reader's frames, the clock fit and a replay can be
checked against exact values. ``real_flights()`` is the corpus beside the repository
(``../shared/data/real/ansfl``, or $BELIEFNAV_ANSFL): missing, tests skip, and FAIL in CI (CI=true).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

ANSFL = Path(os.environ.get("BELIEFNAV_ANSFL")
             or Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real" / "ansfl")
C_NED_ENU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
F_SENSOR_FRD = np.diag([1.0, -1.0, -1.0])
G = 9.80665


def real_flights() -> Path:
    if not (ANSFL / "path_1" / "IMU_1.csv").is_file():
        reason = f"the ANSFL corpus is not beside the repository ({ANSFL})"
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(f"required in CI: {reason}")
        pytest.skip(reason)
    return ANSFL


@dataclass(frozen=True)
class Trajectory:
    """p(t) = (v t + A sin(w1 t), B sin(w2 t), C sin(w3 t)) in NED, t on the IMU clock (s);
    yaw (NED) turning slowly, roll/pitch small oscillations."""

    v_m_s: float = 3.0
    a_m: float = 1.5
    b_m: float = 2.5
    c_m: float = 0.5
    w1: float = 1.8
    w2: float = 1.2
    w3: float = 0.3

    def p(self, t: np.ndarray) -> np.ndarray:
        return np.column_stack((self.v_m_s * t + self.a_m * np.sin(self.w1 * t),
                                self.b_m * np.sin(self.w2 * t),
                                self.c_m * np.sin(self.w3 * t)))

    def v(self, t: np.ndarray) -> np.ndarray:
        return np.column_stack((self.v_m_s + self.a_m * self.w1 * np.cos(self.w1 * t),
                                self.b_m * self.w2 * np.cos(self.w2 * t),
                                self.c_m * self.w3 * np.cos(self.w3 * t)))

    def a(self, t: np.ndarray) -> np.ndarray:
        return np.column_stack((-self.a_m * self.w1**2 * np.sin(self.w1 * t),
                                -self.b_m * self.w2**2 * np.sin(self.w2 * t),
                                -self.c_m * self.w3**2 * np.sin(self.w3 * t)))

    @staticmethod
    def attitude(t: np.ndarray) -> Rotation:
        """R_ned_frd: yaw 30° + 20° sin(0.2 t), roll 5° sin(1.1 t), pitch −4° cos(0.9 t)."""
        yaw = 30.0 + 20.0 * np.sin(0.2 * t)
        roll, pitch = 5.0 * np.sin(1.1 * t), -4.0 * np.cos(0.9 * t)
        return Rotation.from_euler("ZYX", np.column_stack((yaw, pitch, roll)), degrees=True)


def write_flight(directory: Path, *, seconds: float = 40.0, offset_s: float = 0.3,
                 heading_error_deg: float = 0.0, acc_noise_m_s2: float = 0.0, truth_noise_m: float = 0.0,
                 seed: int = 0,
                 trajectory: Trajectory | None = None) -> Trajectory:
    """An ANSFL flight: IMU at 120 Hz on t ∈ [0, seconds), truth at 10 Hz on a clock ``offset_s``
    behind (truth time τ is IMU time τ + offset_s), positions about the first truth point. The
    recorded heading is the true one minus ``heading_error_deg``."""
    traj = trajectory or Trajectory()
    rng = np.random.default_rng(seed)
    directory.mkdir(parents=True, exist_ok=True)
    t = np.arange(0.0, seconds, 1 / 120)
    r_true = traj.attitude(t)
    f_frd = r_true.inv().apply(traj.a(t) - np.array([0.0, 0.0, G]))  # specific force
    r_rec = Rotation.from_euler("Z", -heading_error_deg, degrees=True) * r_true  # recorded attitude
    r_enu_sensor = Rotation.from_matrix(C_NED_ENU) * r_rec * Rotation.from_matrix(F_SENSOR_FRD)
    yaw, pitch, roll = r_enu_sensor.as_euler("ZYX", degrees=True).T
    acc_s = f_frd * [1, -1, -1] + acc_noise_m_s2 * rng.standard_normal(f_frd.shape)
    gyro_s = np.degrees(np.column_stack((0.1 * np.sin(t), 0.2 * np.cos(t), 0.05 + 0 * t))) * [1, -1, -1]
    imu = np.column_stack((t, roll, pitch, yaw, acc_s, gyro_s))
    header = "time,Euler_X,Euler_Y,Euler_Z,Acc_X,Acc_Y,Acc_Z,Gyr_X,Gyr_Y,Gyr_Z"
    np.savetxt(directory / "IMU_1.csv", imu, delimiter=",", header=header, comments="", fmt="%.10g")
    tau = np.arange(0.0, seconds - offset_s, 0.1)  # truth clock
    p = traj.p(tau + offset_s)
    p = p - p[0] + truth_noise_m * rng.standard_normal(p.shape)
    speed = np.linalg.norm(traj.v(tau + offset_s)[:, :2], axis=1)
    gt = np.column_stack((tau, np.zeros_like(tau), speed, np.zeros((len(tau), 4)), p))
    header = ("time,distance(meters),speed(m/s), compass_heading(degrees), pitch(degrees), roll(degrees),"
              "height_above_takeoff(meters),North,East,Down")
    np.savetxt(directory / "GT.csv", gt, delimiter=",", header=header, comments="", fmt="%.10g")
    return traj


SMARTLOC = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "urban" / "smartloc"


def smartloc_drive_slice(out: Path, seconds: float = 60.0) -> Path:
    """The smartLoc Berlin drive's first ``seconds`` (input and truth, for placing its satellites on a
    flight) written to ``out``: its ``*_Input.txt``. Missing beside the repository: skip (fail in CI)."""
    src = SMARTLOC / "Berlin_Potsdamer_Platz_Input.txt"
    if not src.is_file():
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(f"required in CI: the smartLoc drive beside the repository ({src})")
        pytest.skip(f"the smartLoc drive is not beside the repository ({src})")
    for name, limit in (("Berlin_Potsdamer_Platz_Input.txt", seconds), ("Berlin_Potsdamer_Platz_GT.txt",
                                                                          seconds + 1.0)):
        lines = (SMARTLOC / name).read_text(encoding="ascii").splitlines()
        (out / name).write_text("\n".join(ln for ln in lines if float(ln.split()[1]) < limit) + "\n")
    return out / "Berlin_Potsdamer_Platz_Input.txt"
