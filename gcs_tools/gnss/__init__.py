"""Raw GNSS at the I/O edge: readers (RINEX 2/3/4, smartLoc, u-blox UBX) into ``companion.gnss`` epochs,
the single-point baseline against truth, the time join with a flight log, and ``beliefnav gnss``."""
