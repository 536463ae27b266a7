"""ArduPilot SITL beside the companion: EKF3 versus the belief-adaptive estimator on the same GNSS.

``config`` (run parameters, the ArduPilot parameters they imply), ``gnss_source`` (our urban
GNSS fixes as GPS_INPUT), ``driver`` (GUIDED take-off, then the shared route phase), ``session``
(the MAVLink loop against one SITL instance), ``flight`` (one profile end to end: SITL, session,
the companion's methods on the recorded samples), ``backend`` (``ArduPilotBackend``,
``backend("ardupilot")``); ``sitl`` is the ArduCopter SITL launcher (context manager). What
ArduPilot shares with PX4 is in ``simvehicle.harness.foreign``. The command:
``gcs_tools.sitl.autopilot_cli``.
"""
