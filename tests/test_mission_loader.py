"""Mission loading: the shipped cities load; every bad mission is refused with its one-line error."""

import copy
from importlib import resources

import pytest
import yaml

from companion.mission import ConfigError, build_mission, load_mission, load_yaml

BASE = load_yaml(resources.files("companion.mission") / "data" / "test.yaml")


def test_default_city_is_big_with_canyons_and_open_space():
    m = load_mission("default")
    b = m.world.config.bounds
    assert b.north_max_m - b.north_min_m >= 200 and b.east_max_m - b.east_min_m >= 200
    assert len(m.profiles) == 10
    assert m.frame.home_lat_deg == pytest.approx(47.3769)
    # street canyons 12-20 m wide between tall blocks, and an open plaza of > 60 m
    assert m.world.clearance_m(90.0, 62.0) == pytest.approx(8.0)  # 16 m street
    assert m.world.clearance_m(148.0, 150.0) > 30.0
    assert min(b.height_m for b in m.world.config.buildings) > m.altitude_m


def test_test_city_and_overrides():
    m = load_mission("test")
    assert m.name == "test-city" and len(m.profiles) == 3 and m.world.shape == (100, 100)
    assert m.flight.speed_max_m_s == 3.0 and m.flight.acc_max_m_s2 == 1.5  # override + default
    data = copy.deepcopy(BASE)
    data["gnss"] = {"latency_mean_open_s": 0.1}
    m2 = build_mission(data, "x.yaml")
    assert m2.section("gnss") == {"latency_mean_open_s": 0.1}
    assert m2.section("vehicle") == {}
    with pytest.raises(KeyError):
        m2.section("weather")


def test_loads_from_a_path(tmp_path):
    p = tmp_path / "city.yaml"
    p.write_text(yaml.safe_dump(BASE))
    assert load_mission(p).name == "test-city"
    assert load_mission(str(p)).world.rects_m.shape == (4, 4)


def _set(data, path, value):
    keys = path.split(".")
    for k in keys[:-1]:
        data = data[int(k)] if isinstance(data, list) else data[k]
    last = keys[-1]
    if value is DELETE:
        del data[last]
    elif isinstance(data, list):
        data[int(last)] = value
    else:
        data[last] = value


DELETE = object()
RING = [  # four buildings walling in a courtyard around (9, 90)
    {"north_min_m": 0, "east_min_m": 80, "north_max_m": 2, "east_max_m": 100},
    {"north_min_m": 16, "east_min_m": 80, "north_max_m": 18, "east_max_m": 100},
    {"north_min_m": 0, "east_min_m": 80, "north_max_m": 18, "east_max_m": 82},
    {"north_min_m": 0, "east_min_m": 98, "north_max_m": 18, "east_max_m": 100},
]


@pytest.mark.parametrize(
    ("path", "value", "message"),
    [
        ("bogus", 1, "unknown key 'bogus'"),
        ("home", DELETE, "missing key 'home'"),
        ("profiles", DELETE, "missing key 'profiles'"),
        ("name", 3, "name: expected a string"),
        ("home.lat_deg", 95, "home: lat_deg: must be in [-90, 90]"),
        ("home.alt_m", "high", "home.alt_m: expected a number"),
        ("planner.w_foo", 1.0, "planner: unknown key 'w_foo'"),
        ("planner.w_clr", -1.0, "planner: w_clr: must be >= 0"),
        ("planner.w_tra", 0.0, "planner: w_tra: must be > 0"),
        ("planner.los_margin_m", 5.0, "planner: los_margin_m (5.0) must be <= clearance_margin_m"),
        ("world.resolution_m", 4.0, "planner.clearance_margin_m (3.0) must be >= world.resolution_m"),
        ("flight.speed_max_m_s", 0, "flight: speed_max_m_s: must be > 0"),
        ("flight.speed_min_m_s", 0, "flight: speed_min_m_s: must be > 0"),
        ("flight.speed_min_m_s", 3.5, "flight: speed_min_m_s (3.5) must be <= speed_max_m_s (3.0)"),
        ("planner.expected_error_m", -1.0, "planner: expected_error_m: must be >= 0, got -1.0"),
        ("planner.expected_error_m", float("nan"),
         "planner.expected_error_m: expected a finite number, got nan"),
        ("flight.altitude_m", True, "flight.altitude_m: expected a number"),
        ("flight.altitude_m", 50.0, "world.buildings[0].height_m (30.0) must exceed flight.altitude_m"),
        ("world.resolution_m", -1.0, "world: resolution_m: must be > 0"),
        ("world.resolution_m", "fine", "world.resolution_m: expected a number"),
        ("world.bounds.north_max_m", 0, "world.bounds: north_max_m (0.0) must be > north_min_m (0.0)"),
        ("world.buildings.1.east_max_m", 55, "world.buildings[1]: east_max_m (55.0) must be > east_min_m"),
        ("world.buildings.1.height_m", -3, "world.buildings[1]: height_m: must be > 0"),
        ("world.buildings.1.roof", "flat", "world.buildings[1]: unknown key 'roof'"),
        ("world.buildings.1.north_min_m", DELETE, "world.buildings[1]: missing key 'north_min_m'"),
        ("world.buildings.2.north_max_m", 120, "world: buildings[2]: extends outside bounds"),
        ("world.buildings", "none", "world.buildings: expected a list"),
        ("profiles", [], "profiles: at least one profile is needed"),
        ("profiles.0.start_ne_m", [1, 2, 3], "profiles[0].start_ne_m: expected 2 items"),
        ("profiles.0.goal_ne_m", [5, 47], "profiles[0]: start_ne_m and goal_ne_m coincide"),
        ("profiles.1.start_ne_m", [30, 30], "profiles[1].start_ne_m: (30, 30) is inside building 0"),
        ("profiles.1.goal_ne_m", [47, 30], "profiles[1].goal_ne_m: (47, 30) is 2.00 m from building 0, "
         "closer than planner.clearance_margin_m (3)"),
        ("profiles.2.goal_ne_m", [52, 101], "profiles[2].goal_ne_m: (52, 101) is outside world.bounds"),
        ("profiles.2.start_ne_m", [-1, 5], "profiles[2].start_ne_m: (-1, 5) is outside world.bounds"),
        ("vehicle", [1, 2], "vehicle: expected a mapping"),
    ],
)
def test_bad_missions_are_refused_with_one_line(path, value, message):
    data = copy.deepcopy(BASE)
    _set(data, path, value)
    with pytest.raises(ConfigError) as info:
        build_mission(data, "x.yaml")
    assert str(info.value).startswith("x.yaml: " + message), str(info.value)
    assert "\n" not in str(info.value)


def test_unreachable_goal_is_refused():
    data = copy.deepcopy(BASE)
    data["world"]["buildings"] += RING
    data["profiles"][1]["goal_ne_m"] = [9, 90]
    with pytest.raises(ConfigError, match=r"^x.yaml: profiles\[1\]: goal unreachable from start"):
        build_mission(data, "x.yaml")
    data["world"]["buildings"][-2]["north_max_m"] = 4  # a 12 m gap in the west wall: now reachable
    m = build_mission(data, "x.yaml")
    assert m.world.clearance_m(9, 90) == pytest.approx(7.0)


def test_file_errors_name_the_file(tmp_path):
    with pytest.raises(ConfigError, match="nowhere.yaml: cannot read"):
        load_mission(tmp_path / "nowhere.yaml")
    p = tmp_path / "bad.yaml"
    p.write_text(yaml.safe_dump({**BASE, "speed": 3}))
    with pytest.raises(ConfigError, match=r"bad.yaml: unknown key 'speed'"):
        load_mission(p)


def test_overlapping_buildings_are_fine():
    data = copy.deepcopy(BASE)
    extra = {"north_min_m": 30, "east_min_m": 30, "north_max_m": 50, "east_max_m": 45}  # overlaps building 0
    data["world"]["buildings"].append(extra)
    m = build_mission(data, "x.yaml")
    assert m.world.clearance_m(40.0, 42.0) == 0.0 and m.world.clearance_m(40.0, 47.0) == pytest.approx(2.0)


def test_a_mission_extends_another_and_cycles_are_refused(tmp_path):
    """``extends:``: the base's keys, replaced by the file's own (``default-tuning`` is one such file)."""
    tuned, base = load_mission("default-tuning"), load_mission("default")
    assert tuned.name == base.name and tuned.sections == base.sections and len(tuned.profiles) == 4
    assert not set(tuned.profiles) & set(base.profiles)
    mine = tmp_path / "mine.yaml"
    mine.write_text("extends: test\nflight: {altitude_m: 12.0}\n")
    m = load_mission(mine)
    assert m.altitude_m == 12.0 and m.profiles == load_mission("test").profiles
    (tmp_path / "a.yaml").write_text("extends: b.yaml\n")
    (tmp_path / "b.yaml").write_text("extends: a.yaml\n")
    with pytest.raises(ConfigError, match="b.yaml: extends: 'a.yaml' makes a chain deeper than 4 or a cycle"):
        load_mission(tmp_path / "a.yaml")
    (tmp_path / "c.yaml").write_text("extends: [test]\n")
    with pytest.raises(ConfigError, match="extends: expected a packaged mission name or a file path"):
        load_mission(tmp_path / "c.yaml")
