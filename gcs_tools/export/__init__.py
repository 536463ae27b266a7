"""``beliefnav export``: a run directory, a tlog or a recording as MCAP (Foxglove) or CSV."""
