"""Closed loop (``--feed gps-input``): ArduPilot flies on the companion's output.

The companion's estimator (``Navigator``, the chosen method) runs beside the session on the
same stream it would read as a companion computer: ArduPilot's HIGHRES_IMU with the latest
ATTITUDE_QUATERNION, and our degraded fixes at their release time. The raw fixes no longer go
to ArduPilot; instead, at the GNSS rate, the companion sends the CLEANED fix of
``companion.autopilot.feeds.gps_input`` (the filter's position, i.e. the fix with the estimated
multipath bias removed, its velocity, and accuracies from the filter covariance), stamped with
ArduPilot's own clock (GPS week/ms derived from ArduPilot boot time, so ArduPilot's jitter
correction sees a clock that runs at the simulation's speed). The estimate is current when
sent, so EKF3 is told it has no receiver delay (``GPS1_DELAY_MS`` 1).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from companion.autopilot.feeds import FeedConfig, gps_input
from companion.domain.geodesy import LocalNedFrame
from companion.domain.samples import AttitudeSample, ImuSample
from companion.estimator import EstimatorConfig, Navigator
from gcs_tools.ardupilot.gnss_source import SentFix

CLOCK_EPOCH_UNIX_S = 1_700_000_000.0  # ArduPilot boot time 0 on the GPS clock we send (any fixed epoch)


class LiveCompanion:
    """The companion's estimator fed as the session receives; cleaned fixes when due."""

    def __init__(self, cfg: EstimatorConfig, method: str, frame: LocalNedFrame, rate_hz: float) -> None:
        self.nav = Navigator(cfg, method=method, frame=frame)
        self.frame = frame
        self.feed_cfg = FeedConfig(gps_input_hz=rate_hz)
        self.period_us = round(1e6 / rate_hz)
        self._next_us = 0
        self.sent = 0

    def push_imu(self, t_us: int, acc_frd_m_s2: np.ndarray, q_ned_frd: np.ndarray) -> None:
        self.nav.push(AttitudeSample(t_us, q_ned_frd))
        self.nav.push(ImuSample(t_us, acc_frd_m_s2, np.zeros(3)))

    def push_fix(self, sf: SentFix) -> None:
        self.nav.push_fix_ned(sf.fix.t_validity_us, sf.p_ned_m)

    def due(self, t_us: int, satellites: int) -> Any | None:
        """The GPS_INPUT to send now (None between periods or before the first estimate)."""
        if t_us < self._next_us:
            return None
        est = self.nav.estimate()
        if est is None:
            return None
        self._next_us = t_us + self.period_us
        self.sent += 1
        return gps_input(est, self.frame, self.feed_cfg, satellites=satellites,
                         unix_s=CLOCK_EPOCH_UNIX_S + est.t_us * 1e-6)
