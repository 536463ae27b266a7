"""SITL: three processes over MAVLink/UDP, supervised (``beliefnav sitl``)."""
