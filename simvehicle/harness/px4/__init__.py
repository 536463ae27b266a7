"""PX4 SITL (SIH quadrotor) beside the companion: EKF2 versus the belief-adaptive estimator on the same GNSS.

``sitl`` (the launcher, context manager: instance i = system i + 1, ports + i), ``config`` (run
parameters and the PX4 parameters they imply: HIL_GPS as EKF2's only GNSS, or the companion's
ODOMETRY as external vision), ``driver`` (OFFBOARD, arm, climb, then the shared route phase),
``session`` (the MAVLink loop on PX4's GCS link: truth from HIL_STATE_QUATERNION, our fixes as
HIL_GPS), ``flight`` (one profile end to end), ``backend`` (``Px4Backend``, ``backend("px4")``).
What PX4 shares with ArduPilot is in ``simvehicle.harness.foreign``. The command:
``gcs_tools.sitl.autopilot_cli``.
"""
