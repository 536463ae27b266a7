"""One spelling per option across subcommands, defaults for --out, --json where there is a result,
and options checked before anything starts."""

import argparse
import json
import re
import subprocess
import sys
import time

from gcs_tools.cli import COMMANDS, build_parser, main

RESULT_COMMANDS = ("fly", "sitl", "replay", "evaluate", "export", "bench")


def _options() -> dict[str, dict[str, argparse.Action]]:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    out = {}
    for name in COMMANDS:
        p = sub.choices[name]
        out[name] = {s: a for a in p._actions for s in a.option_strings if a.help != argparse.SUPPRESS}
    return out


def test_one_spelling_per_option_and_units_in_names():
    opts = _options()
    seen: dict[str, set[str]] = {}
    for cmd, actions in opts.items():
        for name in actions:
            seen.setdefault(re.sub(r"-(s|ms|hz|m)$", "", name), set()).add(name)  # unit suffix off
            if any(w in name for w in ("duration", "timeout")):
                assert name.endswith("-s"), (cmd, name)  # seconds, said in the name
    clashes = {k: v for k, v in seen.items() if len(v) > 1}  # e.g. --max-duration beside --max-duration-s
    assert not clashes, clashes
    for cmd in ("fly", "sitl", "replay", "evaluate", "export", "record"):
        out = opts[cmd]["--out"]
        assert not out.required, cmd  # every --out has a default (runs/<command> or beside the input)
    for cmd in RESULT_COMMANDS:
        assert "--json" in opts[cmd], cmd


def test_fly_human_summary_and_json(tmp_path, capsys):
    assert main(["fly", "--mission", "test", "--max-duration-s", "3", "--out", str(tmp_path)]) == 1  # timeout
    text = capsys.readouterr().out
    assert text.startswith("fly second-order seed 0, test-city profile 0: did not reach the goal after 3.0 s")
    assert len(text.splitlines()) == 4 and "estimation error median" in text
    assert main(["fly", "--mission", "test", "--max-duration-s", "3", "--out", str(tmp_path), "--json"]) == 1
    s = json.loads(capsys.readouterr().out)
    assert s["duration_s"] == 3.0 and s == json.loads((tmp_path / "summary.json").read_text())


def test_sitl_typo_fails_at_once_naming_the_choices(tmp_path):
    out = tmp_path / "never"
    t0 = time.monotonic()
    done = subprocess.run([sys.executable, "-m", "gcs_tools", "sitl", "--method", "secnd", "--out", str(out)],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert done.stderr.splitlines() == [
        "beliefnav: error: --method 'secnd': not one of naive, adaptive, first-order, second-order, "
        "paper-literal, vbakf, fixed-beta, map-beta, windowed-ml, hmm-trust, map-hmm "
        "(did you mean 'second-order'?)"]
    assert not out.exists()  # nothing was started or written
    assert time.monotonic() - t0 < 30
    done = subprocess.run([sys.executable, "-m", "gcs_tools", "sitl", "--mission", "defualt", "--out",
                           str(out)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert ("(packaged: default, test, default-tuning, mild, mild-tuning; did you mean 'default'?)"
            in done.stderr)
    assert not out.exists()


def test_profiles_is_one_option_with_one_meaning():
    """A set of mission profiles is --profiles in every command (evaluate's old --missions is a hidden
    alias): --mission names a mission, never a count of profiles."""
    opts = _options()
    assert not [cmd for cmd, actions in opts.items() if "--missions" in actions]
    assert "--profiles" in opts["evaluate"] and "--mission" in opts["evaluate"]
