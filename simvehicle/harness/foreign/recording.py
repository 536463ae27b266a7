"""What a flight beside a foreign autopilot records for its analysis, in the autopilot's boot time."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Recording:
    """The autopilot's IMU stream (with the attitude in force), its truth and its own estimate (µs)."""

    imu_t_us: list[int] = field(default_factory=list)
    imu_acc_frd_m_s2: list[np.ndarray] = field(default_factory=list)
    imu_q_ned_frd: list[np.ndarray] = field(default_factory=list)
    truth_t_us: list[int] = field(default_factory=list)
    truth_p_ned_m: list[np.ndarray] = field(default_factory=list)
    truth_v_ned_m_s: list[np.ndarray] = field(default_factory=list)
    truth_bias_ned_m: list[np.ndarray] = field(default_factory=list)
    truth_latency_s: list[float] = field(default_factory=list)
    truth_clearance_m: list[float] = field(default_factory=list)
    ekf_t_us: list[int] = field(default_factory=list)
    ekf_p_ned_m: list[np.ndarray] = field(default_factory=list)
    statustext: list[tuple[int, str]] = field(default_factory=list)
    counts: dict[str, int] = field(default_factory=dict)
    rejected: dict[str, int] = field(default_factory=dict)

    def count(self, name: str) -> None:
        self.counts[name] = self.counts.get(name, 0) + 1

    def reject(self, reason: str) -> None:
        self.rejected[reason] = self.rejected.get(reason, 0) + 1
