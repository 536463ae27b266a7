"""docs/parameters.md is what the code says (options, fields, defaults, units, comments), and the
companion's --config file takes every option, checked key by key, the command line winning."""

import argparse
import dataclasses

import pytest

from companion.errors import ConfigError
from gcs_tools import paramdoc


def test_the_committed_parameter_reference_is_up_to_date():
    assert paramdoc.main(["--check"]) == 0, "run `make docs` (python -m gcs_tools.paramdoc)"


def test_fields_carry_their_default_unit_and_comment():
    from companion.estimator.config import EstimatorConfig

    text = paramdoc.render()
    default = EstimatorConfig().bias_tau_s
    comment = "paper Γ_mp: correlation time of the GNSS multipath bias state"
    assert f"| `bias_tau_s` | {default:g} | s | {comment} |" in text
    assert "| `inertia_kg_m2` | (0.02, 0.02, 0.04) | kg·m² |" in text  # the longest unit suffix wins
    units = [paramdoc.unit(name) for name in ("speed_max_m_s", "acc_max_m_s2", "eta")]
    assert units == ["m/s", "m/s²", ""]
    for f in dataclasses.fields(EstimatorConfig):
        assert f"| `{f.name}` |" in text  # every field
    assert "| `--gps-delay-ms GPS_DELAY_MS` | `gps-delay-ms` |" in text  # every companion option


@pytest.fixture()
def companion_parser():
    from gcs_tools.cli import build_parser

    parser = build_parser(["companion"])
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return parser, sub.choices["companion"]


def test_config_file_gives_options_and_the_command_line_wins(companion_parser, tmp_path):
    from gcs_tools import companion_config

    parser, companion = companion_parser
    cfg = tmp_path / "companion.yaml"
    cfg.write_text("master: serial:/dev/ttyAMA0:921600\nout: /var/lib/beliefnav\nfeed: gps-input\n"
                   "gps-delay-ms: 110\nno-telemetry: true\nmethod: naive\nestimator:\n  eta: 0.3\n")
    args = parser.parse_args(["companion", "--config", str(cfg), "--feed", "vision", "--gps-delay-ms", "120"])
    sections = companion_config.merge(args, args._config_parser, args._option_defaults)
    assert (args.master, str(args.out), args.method, args.no_telemetry) == (
        "serial:/dev/ttyAMA0:921600", "/var/lib/beliefnav", "naive", True)
    assert (args.feed, args.gps_delay_ms) == ("vision", 120.0)  # the command line wins
    assert args.discovery_timeout_s == 60.0 and args.component_id == 197  # the defaults stay
    assert companion_config.estimator_config(sections, cfg).eta == 0.3
    # an option the user gave with its default's value still wins over the file
    args = parser.parse_args(["companion", "--config", str(cfg), "--feed", "none"])
    companion_config.merge(args, args._config_parser, args._option_defaults)
    assert args.feed == "none"


@pytest.mark.parametrize(("text", "message"), [
    ("mastr: tcp:1.2.3.4:5760\n", "unknown key 'mastr' (did you mean 'master'?)"),
    ("feed: vison\n", "feed: 'vison' is not one of none, vision, odometry, gps-input (did you mean 'vision'"),
    ("gps-delay-ms: fast\n", "gps-delay-ms: expected a number, got 'fast'"),
    ("component-id: 1.5\n", "component-id: expected an integer, got 1.5"),
    ("no-telemetry: yes please\n", "no-telemetry: expected true or false, got 'yes please'"),
    ("master: [a, b]\n", "master: expected a single value"),
    ("estimator: {etaa: 1}\n", "estimator: unknown key 'etaa'"),
    ("master: 'x\n", "invalid YAML"),
])
def test_config_mistakes_are_one_line_naming_the_key(companion_parser, tmp_path, text, message):
    from gcs_tools import companion_config

    parser, _ = companion_parser
    cfg = tmp_path / "bad.yaml"
    cfg.write_text(text)
    args = parser.parse_args(["companion", "--config", str(cfg)])
    with pytest.raises(ConfigError) as exc:
        sections = companion_config.merge(args, args._config_parser, args._option_defaults)
        companion_config.estimator_config(sections, cfg)
    assert str(exc.value).startswith(str(cfg)) and message in str(exc.value) and "\n" not in str(exc.value)
