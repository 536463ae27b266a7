"""MAVLink 2 edge: codec (domain types <-> messages), frame scanner, tlog I/O, UDP links and
connection strings, and the lockstep step protocol of ``beliefnav sitl``."""
