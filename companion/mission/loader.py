"""Load and check a mission file: the one loader, shared by the planner and the simulator.

A mission is refused here, before anything flies, with a one-line ``ConfigError`` naming the
file and field: unknown/missing keys, wrong types, degenerate rectangles, non-positive sizes,
and start/goal points that are outside the bounds, inside or too close to a building, or
cannot reach each other through the planner's free cells.
"""

from __future__ import annotations

import dataclasses
import typing
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from companion.domain.geodesy import LocalNedFrame
from companion.errors import not_one_of
from companion.mission.config import (
    OVERRIDE_SECTIONS,
    FlightConfig,
    MissionFile,
    PlannerConfig,
    Profile,
)
from companion.mission.grid import connected_4
from companion.mission.scenarios import SCENARIOS, scenario_sections
from companion.mission.schema import ConfigError, build, load_yaml
from companion.mission.world import World

# companion/mission/data/<name>.yaml
BUILTIN_MISSIONS = ("default", "test", "default-tuning", "mild", "mild-tuning")
MAX_EXTENDS = 4  # a mission file may extend another (``extends:``) this many levels deep


@dataclass(frozen=True)
class Mission:
    """A checked mission: frame, world, flight limits, planner weights, profiles, overrides."""

    name: str
    frame: LocalNedFrame
    world: World
    flight: FlightConfig
    planner: PlannerConfig
    profiles: tuple[Profile, ...]
    sections: dict[str, dict[str, Any]]
    source: str  # file the mission came from, for messages
    scenario: str = "paper"  # sensor realism (companion.mission.scenarios), one of SCENARIOS

    @property
    def altitude_m(self) -> float:
        return self.flight.altitude_m

    def section(self, name: str) -> dict[str, Any]:
        """The raw override mapping for another owner's config ({} when the file has none)."""
        if name not in OVERRIDE_SECTIONS:
            raise KeyError(f"no override section {name!r} (known: {', '.join(OVERRIDE_SECTIONS)})")
        return dict(self.sections.get(name, {}))

    def settings(self, name: str) -> dict[str, Any]:
        """The fields in force for section ``name``: the scenario's (``scenarios.SCENARIO_SECTIONS``),
        overridden by the mission's own section. What the simulator and the filter are built from."""
        return {**scenario_sections(self.scenario).get(name, {}), **self.section(name)}


def load_mission(which: str | Path, scenario: str | None = None) -> Mission:
    """Load a packaged mission (``BUILTIN_MISSIONS``: ``"default"``, ``"test"``, ``"default-tuning"``,
    ``"mild"``, ``"mild-tuning"``)
    or a YAML file path; ``scenario`` (``--scenario``) replaces the file's ``scenario:``.

    A file may start from another with ``extends: NAME|PATH`` (a packaged name, or a path relative
    to the file): its top-level keys replace the base's (``default-tuning`` is the default city
    with other profiles)."""
    data, source = _mission_data(which, ())
    mission = build_mission(data, source)
    return mission if scenario is None else with_scenario(mission, scenario)


def _mission_data(which: str | Path, seen: tuple[str, ...]) -> tuple[dict[str, Any], str]:
    """The file's mapping with its ``extends:`` chain resolved, and its name for messages."""
    if str(which) in BUILTIN_MISSIONS:
        ref = resources.files("companion.mission") / "data" / f"{which}.yaml"
        with resources.as_file(ref) as path:
            data, source = load_yaml(path), path.name
    else:
        data, source = load_yaml(which), str(which)
    base = data.pop("extends", None)
    if base is None:
        return data, source
    if not isinstance(base, str) or not base:
        raise ConfigError(f"{source}: extends: expected a packaged mission name or a file path")
    where = base if base in BUILTIN_MISSIONS else str((Path(str(which)).parent / base).resolve())
    here = str(which) if str(which) in BUILTIN_MISSIONS else str(Path(which).resolve())
    if where in (*seen, here) or len(seen) >= MAX_EXTENDS:
        raise ConfigError(f"{source}: extends: {base!r} makes a chain deeper than {MAX_EXTENDS} or a cycle")
    base_data, _ = _mission_data(where, (*seen, here))
    return {**base_data, **data}, source


def with_scenario(mission: Mission, scenario: str) -> Mission:
    """``mission`` flown under sensor scenario ``scenario`` (checked against SCENARIOS)."""
    _check_scenario(scenario, "--scenario")
    return dataclasses.replace(mission, scenario=scenario)


def _check_scenario(name: str, where: str) -> None:
    if name not in SCENARIOS:
        raise not_one_of(where, name, SCENARIOS)  # "--scenario 'realstic': not one of ... (did you mean ...)"


def build_mission(data: dict[str, Any], source: str = "mission") -> Mission:
    """Build and check a mission from a parsed YAML mapping; ``source`` prefixes every error."""
    hints = typing.get_type_hints(MissionFile)
    unknown = sorted(set(map(str, data)) - set(hints) - set(OVERRIDE_SECTIONS))
    if unknown:
        known = ", ".join([*hints, *OVERRIDE_SECTIONS])
        raise ConfigError(f"{source}: unknown key {unknown[0]!r} (known: {known})")
    missing = [n for n in _required_fields(MissionFile) if n not in data]
    if missing:
        raise ConfigError(f"{source}: missing key {missing[0]!r}")
    spec = MissionFile(**{n: build(hints[n], data[n], f"{source}: {n}") for n in hints if n in data})
    sections = {}
    for name in OVERRIDE_SECTIONS:
        if name in data:
            sections[name] = build(dict[str, Any], data[name], f"{source}: {name}")
    if not spec.profiles:
        raise ConfigError(f"{source}: profiles: at least one profile is needed")
    _check_scenario(spec.scenario, f"{source}: scenario")
    _check_cross(spec, source)
    world = World(spec.world)
    _check_profiles(spec, world, source)
    home = spec.home
    return Mission(
        name=spec.name,
        frame=LocalNedFrame(home.lat_deg, home.lon_deg, home.alt_m),
        world=world,
        flight=spec.flight,
        planner=spec.planner,
        profiles=spec.profiles,
        sections=sections,
        source=source,
        scenario=spec.scenario,
    )


def _required_fields(cls: type) -> list[str]:
    return [f.name for f in dataclasses.fields(cls)
            if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING]


def _check_cross(spec: MissionFile, source: str) -> None:
    margin_m = spec.planner.clearance_margin_m
    res_m = spec.world.resolution_m
    if margin_m < res_m:
        raise ConfigError(
            f"{source}: planner.clearance_margin_m ({margin_m}) must be >= world.resolution_m ({res_m})"
        )
    for k, b in enumerate(spec.world.buildings):
        if b.height_m <= spec.flight.altitude_m:
            raise ConfigError(
                f"{source}: world.buildings[{k}].height_m ({b.height_m}) must exceed flight.altitude_m "
                f"({spec.flight.altitude_m}): the world is 2-D"
            )


def _check_profiles(spec: MissionFile, world: World, source: str) -> None:
    margin_m = spec.planner.clearance_margin_m
    blocked = world.blocked(margin_m)
    for k, prof in enumerate(spec.profiles):
        cells = []
        for key in ("start_ne_m", "goal_ne_m"):
            n, e = getattr(prof, key)
            where = f"{source}: profiles[{k}].{key}"
            if not spec.world.bounds.contains(n, e):
                raise ConfigError(f"{where}: ({n:g}, {e:g}) is outside world.bounds")
            d_m, k_bld = world.clearance_m(n, e), world.nearest_building(n, e)
            if d_m <= 0.0:
                raise ConfigError(f"{where}: ({n:g}, {e:g}) is inside building {k_bld}")
            if d_m < margin_m:
                raise ConfigError(
                    f"{where}: ({n:g}, {e:g}) is {d_m:.2f} m from building {k_bld}, "
                    f"closer than planner.clearance_margin_m ({margin_m:g})"
                )
            cells.append(world.cell_of(n, e))
        if not _connected(blocked, cells[0], cells[1]):
            raise ConfigError(
                f"{source}: profiles[{k}]: goal unreachable from start "
                f"with planner.clearance_margin_m {margin_m:g}"
            )


def _connected(blocked: np.ndarray, a: tuple[int, int], b: tuple[int, int]) -> bool:
    """Same component of the free cells (start and goal cells always free)?

    The planner moves diagonally only between free orthogonal neighbours, so its 8-connected
    moves connect exactly what 4-connectivity (``ndimage.label``'s default) connects.
    """
    return connected_4(~blocked, a, b)
