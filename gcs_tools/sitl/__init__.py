"""``beliefnav sitl``: the command (``cli``) and the ArduPilot vehicle's options (``ardupilot_cli``);
the processes themselves are flown by ``simvehicle.harness`` (``backend("sim" | "ardupilot")``)."""
