"""The tuning set: the default city with start/goal profiles that are never reported.

Hyper-parameters (estimator config defaults) are tuned only on ``default-tuning`` with
seeds ``TUNING_SEEDS``; the reported campaign flies the default city's own 10 profiles with
other seeds. ``load("default-tuning")`` is the default mission file with its profiles
replaced, checked by the same loader (so every pair is reachable).
"""

from __future__ import annotations

from importlib import resources

from companion.mission import Mission, build_mission, load_mission, load_yaml

TUNING_MISSION = "default-tuning"
TUNING_SEEDS = tuple(range(1000, 1010))
TUNING_PROFILES = (  # north/east metres; none shares an end point with a reported profile
    {"name": "east-street-to-north", "start_ne_m": [57, 280], "goal_ne_m": [239, 124]},
    {"name": "west-street-to-south-east", "start_ne_m": [176, 20], "goal_ne_m": [10, 243]},
    {"name": "park-to-crossing", "start_ne_m": [270, 200], "goal_ne_m": [118, 62]},
    {"name": "wide-canyon-north", "start_ne_m": [30, 180], "goal_ne_m": [240, 180]},
)


def load(name: str) -> Mission:
    """A mission by name or path; ``default-tuning`` is the tuning set."""
    if name != TUNING_MISSION:
        return load_mission(name)
    ref = resources.files("companion.mission") / "data" / "default.yaml"
    with resources.as_file(ref) as path:
        data = load_yaml(path)
    data["profiles"] = [dict(p) for p in TUNING_PROFILES]
    return build_mission(data, f"{TUNING_MISSION} (default.yaml, tuning profiles)")
