"""The vehicle side's harness: everything that FLIES a mission around the vehicle core.

``backend`` (one interface, ``VehicleBackend``, and the registry of backends by name), ``fly`` (our
simulator in-process: vehicle, planner, autopilot and estimator closed in one loop), ``sitl`` (our
simulator as MAVLink/UDP processes: launcher, supervisor, outcome, vehicle id), ``ardupilot``
(ArduCopter SITL on our degraded GNSS), ``px4`` (the PX4 SITL launcher: SIH quadrotor). Only
the harness may import ``companion.estimator`` and ``companion.planning`` (the vehicle core flies
the setpoints it receives); ``gcs_tools`` drives it and writes the files.
"""
