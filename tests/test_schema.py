"""The config builder: known answers and one-line errors that name the field."""

from dataclasses import dataclass, field

import pytest

from companion.mission.schema import ConfigError, build, load_yaml


@dataclass(frozen=True)
class Inner:
    gain_1_s: float
    name: str = "x"


@dataclass(frozen=True)
class Outer:
    inner: Inner
    sizes_m: tuple[float, float]
    items: list[int] = field(default_factory=list)

    def validate(self) -> None:
        if self.sizes_m[0] <= 0:
            raise ValueError("sizes_m[0]: must be > 0")


def test_builds_nested_and_converts_ints_to_float():
    o = build(Outer, {"inner": {"gain_1_s": 2}, "sizes_m": [1, 2.5], "items": [3]}, "cfg")
    assert o == Outer(Inner(2.0), (1.0, 2.5), [3])
    assert isinstance(o.inner.gain_1_s, float)


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"inner": {"gain_1_s": 1}, "sizes_m": [1, 2], "bogus": 1}, "cfg: unknown key 'bogus'"),
        ({"sizes_m": [1, 2]}, "cfg: missing key 'inner'"),
        ({"inner": {"gain_1_s": "abc"}, "sizes_m": [1, 2]}, "cfg.inner.gain_1_s: expected a number"),
        ({"inner": {"gain_1_s": float("nan")}, "sizes_m": [1, 2]}, "cfg.inner.gain_1_s: expected a finite"),
        ({"inner": {"gain_1_s": 1}, "sizes_m": [1]}, "cfg.sizes_m: expected 2 items"),
        ({"inner": {"gain_1_s": 1}, "sizes_m": [-1, 2]}, "cfg: sizes_m[0]: must be > 0"),
        ({"inner": {"gain_1_s": True}, "sizes_m": [1, 2]}, "cfg.inner.gain_1_s: expected a number"),
    ],
)
def test_errors_name_the_field(data, message):
    with pytest.raises(ConfigError) as info:
        build(Outer, data, "cfg")
    assert str(info.value).startswith(message)
    assert "\n" not in str(info.value)


def test_load_yaml_errors_are_one_line(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("a: [1, 2\n")
    with pytest.raises(ConfigError, match=r"bad.yaml: invalid YAML \(line \d+\)"):
        load_yaml(bad)
    with pytest.raises(ConfigError, match="cannot read"):
        load_yaml(tmp_path / "missing.yaml")
    lst = tmp_path / "list.yaml"
    lst.write_text("- 1\n")
    with pytest.raises(ConfigError, match="expected a mapping"):
        load_yaml(lst)
