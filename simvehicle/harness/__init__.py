"""The vehicle side's harness: everything that FLIES a mission around the vehicle core.

``backend`` (one interface, ``VehicleBackend``, and the registry of backends by name), ``fly`` (our
simulator in-process: vehicle, planner, autopilot and estimator closed in one loop), ``sitl`` (our
simulator as MAVLink/UDP processes: launcher, supervisor, outcome, vehicle id), ``foreign`` (what
every real autopilot's SITL flown on our degraded GNSS shares), ``ardupilot`` (ArduCopter SITL),
``px4`` (PX4 SITL with its SIH quadrotor); ``firmware`` (what their launchers share). Only
the harness may import ``companion.estimator`` and ``companion.planning`` (the vehicle core flies
the setpoints it receives); ``gcs_tools`` drives it and writes the files.
"""
