"""``beliefnav sitl``: the command (``cli``) and the SITL autopilots' options (``autopilot_cli``:
ArduPilot, PX4); the processes themselves are flown by ``simvehicle.harness``
(``backend("sim" | "ardupilot" | "px4")``)."""
