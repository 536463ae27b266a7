"""Companion processes: thin UDP/MAVLink edges around the estimator and the planner bridge."""
