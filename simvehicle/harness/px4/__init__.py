"""PX4 beside the companion: ``sitl`` is the PX4 SITL launcher (SIH quadrotor, context manager)."""
