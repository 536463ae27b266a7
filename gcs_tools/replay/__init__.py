"""Replay of recorded tlogs through the estimator (``beliefnav replay``)."""
