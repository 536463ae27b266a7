"""Companion computer: the belief-adaptive estimator and the planner bridge."""
