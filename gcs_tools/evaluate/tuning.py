"""The tuning set and parameter overrides for sweeps.

Hyper-parameters (estimator config defaults) are tuned only on ``default-tuning`` with
seeds ``TUNING_SEEDS``; the reported campaign flies the default city's own 10 profiles with
other seeds. ``default-tuning`` is a packaged mission (``companion/mission/data/default-tuning.yaml``:
the default city with other profiles), so every command accepts it.

Overrides (``--set estimator.r_inflation_max=100``) replace one field of one of the mission's
override sections (``companion.mission.OVERRIDE_SECTIONS``) for every flight of a campaign, so
every method sees the same change. They are ``(key, value)`` pairs with hashable scalar values,
so a job that carries them stays picklable and a worker can cache the mission it builds.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import yaml

from companion.errors import UserError
from companion.mission import OVERRIDE_SECTIONS, Mission, load_mission
from gcs_tools import choices

TUNING_MISSION = "default-tuning"
TUNING_SEEDS = tuple(range(1000, 1010))

Override = tuple[str, Any]  # ("estimator.sigma_acc_m_s2", 0.02)


def profiles(text: str | None = None) -> tuple[int, ...]:
    """Profiles of the tuning mission: ``text`` as ``--profiles`` (a count or a list/range), or all of
    them (the mission file is the one source of how many there are)."""
    available = len(load_mission(TUNING_MISSION).profiles)
    return choices.profiles(text, available) if text else tuple(range(available))


def load(name: str, overrides: Sequence[Override] = ()) -> Mission:
    """A mission by name or path (``default-tuning`` is the tuning set), with ``overrides`` applied."""
    return with_overrides(load_mission(name), overrides)


def parse_override(text: str) -> Override:
    """``"estimator.eta=0.3"`` → ``("estimator.eta", 0.3)`` (value read as YAML: a scalar)."""
    key, sep, raw = text.partition("=")
    section, dot, name = key.strip().partition(".")
    if not (sep and dot and name.isidentifier()):
        raise UserError(f"--set: expected SECTION.FIELD=VALUE, got {text!r}")
    if section not in OVERRIDE_SECTIONS:
        known = ", ".join(OVERRIDE_SECTIONS)
        raise UserError(f"--set {text!r}: unknown section {section!r} (known: {known})")
    try:
        value = yaml.safe_load(raw)
    except yaml.YAMLError:
        value = None
    if not isinstance(value, (int, float, str, bool)):
        raise UserError(f"--set {text!r}: expected a number, string or boolean value")
    return f"{section}.{name}", value


def with_overrides(mission: Mission, overrides: Sequence[Override]) -> Mission:
    """``mission`` with each ``section.field`` replaced (later overrides win); fields are checked
    when the section's config is built (``check``)."""
    if not overrides:
        return mission
    sections = {name: dict(body) for name, body in mission.sections.items()}
    for key, value in overrides:
        section, _, field = key.partition(".")
        sections.setdefault(section, {})[field] = value
    return dataclasses.replace(mission, sections=sections)


def check(mission: Mission) -> None:
    """Build every config a flight builds from ``mission``: a bad override fails here, in one line."""
    from companion.wiring import mission_estimator_config, mission_plugin_config
    from simvehicle.config import sim_config_for

    mission_estimator_config(mission)
    mission_plugin_config(mission)
    sim_config_for(mission)
