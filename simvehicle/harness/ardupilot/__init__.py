"""ArduPilot SITL beside the companion: EKF3 versus the belief-adaptive estimator on the same GNSS.

``config`` (run parameters, the ArduPilot parameters they imply), ``gnss_source`` (our urban
degradation model turned into GPS_INPUT from ArduPilot's truth), ``driver`` (GUIDED take-off and
the planned route as SET_POSITION_TARGET_LOCAL_NED), ``session`` (the MAVLink loop against one
SITL instance), ``flight`` (one profile end to end: SITL, session, the companion's methods on
the recorded samples), ``backend`` (``ArduPilotBackend``, ``backend("ardupilot")``); ``sitl``
is the ArduCopter SITL launcher (context manager). The command: ``gcs_tools.sitl.ardupilot_cli``.
"""
