"""``beliefnav evaluate --vehicle px4``: EKF2 beside the companion's methods over profiles and seeds.

The campaign itself is ``gcs_tools.evaluate.autopilot`` (one PX4 SITL flight per profile, seed and
loop, on the first free instance; statistics, report); this module names PX4's loops:

- ``none``: open loop, EKF2 fed our raw fixes as HIL_GPS WITH a Doppler velocity (truth + 0.1 m/s
  noise; ``EKF2_GPS_CTRL`` 7);
- ``none-posonly``: open loop, EKF2 fed positions only (``EKF2_GPS_CTRL`` 3); only its EKF2 row is
  kept (``px4-ekf2-posonly``);
- ``odometry``: closed loop, PX4 flies on the second-order companion PROCESS's ODOMETRY, fused by
  EKF2 as external vision with no GNSS; row ``companion-live`` = what it sent.
"""

from __future__ import annotations

from gcs_tools.evaluate.autopilot import CLOSED_LOOP_METHOD, Loop, VehicleCampaign, open_loops
from simvehicle.harness.px4.config import Px4FlightConfig

POSONLY_ROW = "px4-ekf2-posonly"  # EKF2 without the GNSS velocity
CAMPAIGN = VehicleCampaign(
    vehicle="px4", title="PX4", ekf="EKF2", autopilot_row="px4-ekf2",
    loops=(*open_loops("EKF2", POSONLY_ROW),
           Loop("odometry", f"EKF2 on {CLOSED_LOOP_METHOD}'s ODOMETRY (external vision)", "odometry")),
    figure_title="PX4 SITL (SIH) on our urban GNSS: EKF2 vs the companion (open loop; whiskers p5-p95)",
    config_class=Px4FlightConfig, speed_field="speed_factor",
    rescorer="simvehicle.harness.px4.rescore:rescore_px4")
