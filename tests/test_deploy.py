"""The deployment files hold together (docs/deploy.md): the example configuration is one the
companion accepts, the systemd unit passes `systemd-analyze verify`, the Dockerfile passes hadolint
and copies what `pip install .` needs, and the companion says where it waits for the autopilot.
No container engine runs here: the image itself is not built by these tests."""

import argparse
import os
import re
import shutil
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import pytest
from telemetry_helpers import free_port

ROOT = Path(__file__).resolve().parents[1]
DOCKERFILE = ROOT / "packaging" / "docker" / "Dockerfile"
UNIT = ROOT / "packaging" / "systemd" / "beliefnav-companion.service"
CONFIG = ROOT / "packaging" / "companion.yaml"
IN_CI = os.environ.get("CI") == "true"


def _tool(name: str) -> str:
    found = shutil.which(name) or str(Path(sys.executable).parent / name)
    if not Path(found).exists():
        if IN_CI:
            pytest.fail(f"{name} is missing in CI")
        pytest.skip(f"no {name} on this machine")
    return found


def test_the_example_configuration_is_accepted_with_every_key_known():
    from gcs_tools import companion_config
    from gcs_tools.cli import build_parser

    parser = build_parser(["companion"])
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    companion = sub.choices["companion"]
    values, sections = companion_config.read(CONFIG, companion, companion.get_default("_option_defaults"))
    assert values["master"] == "serial:/dev/ttyAMA0:921600" and values["feed"] == "none"
    assert companion_config.estimator_config(sections, CONFIG).sigma_acc_m_s2 == 0.3


def test_systemd_unit_verifies_and_runs_the_documented_command(tmp_path):
    analyze = _tool("systemd-analyze")
    unit = tmp_path / UNIT.name
    unit.write_text(UNIT.read_text())
    done = subprocess.run([analyze, "verify", str(unit)], capture_output=True, text=True, timeout=60)
    complaints = [x for x in (done.stdout + done.stderr).splitlines() if str(unit) in x]
    assert done.returncode == 0 and not complaints, complaints  # no unknown key, no bad value
    text = UNIT.read_text()
    assert "beliefnav companion --config /etc/beliefnav/companion.yaml" in text
    assert "KillSignal=SIGTERM" in text and "SupplementaryGroups=dialout" in text


def _instructions() -> list[tuple[str, str]]:
    """(INSTRUCTION, arguments) of the Dockerfile, continuation lines joined, comments dropped."""
    text = re.sub(r"\\\n", " ", DOCKERFILE.read_text())
    return [(ln.split(None, 1)[0].upper(), ln.split(None, 1)[1] if " " in ln.strip() else "")
            for ln in (x.strip() for x in text.splitlines()) if ln and not ln.startswith("#")]


def test_dockerfile_passes_hadolint():
    hadolint = _tool("hadolint")
    done = subprocess.run([hadolint, "--failure-threshold", "warning", str(DOCKERFILE)], capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 0, done.stdout + done.stderr


def test_dockerfile_copies_what_the_install_needs_and_runs_the_companion():
    """Every COPY source exists in the build context (the repository) and is not left out by
    .dockerignore; the packages pyproject.toml installs and the files setup.py reads are copied;
    the entry point is the console script; the configuration the command reads is the one copied."""
    steps = _instructions()
    ignored = [p.strip() for p in (ROOT / ".dockerignore").read_text().splitlines()
               if p.strip() and not p.startswith("#")]
    copied = set()
    for kind, args in steps:
        if kind == "COPY" and "--from=" not in args:
            *sources, _dest = args.split()
            for src in sources:
                assert (ROOT / src).exists(), src
                assert not any(Path(src).match(p) or src.split("/")[0] == p for p in ignored), src
                copied.add(src.rstrip("/"))
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())
    packages = {p.rstrip("*") for p in project["tool"]["setuptools"]["packages"]["find"]["include"]}
    assert packages <= copied, packages - copied
    assert {"pyproject.toml", "setup.py", "requirements.lock", project["project"]["readme"]} <= copied
    assert "/src/requirements.lock" in " ".join(a for k, a in steps if k == "ENV")  # the lock's versions
    entry = next(a for k, a in steps if k == "ENTRYPOINT")
    assert entry == '["beliefnav", "companion"]' and "beliefnav" in project["project"]["scripts"]
    cmd = next(a for k, a in steps if k == "CMD")
    assert cmd == '["--config", "/etc/beliefnav/companion.yaml"]'
    assert any(k == "COPY" and a.split() == ["packaging/companion.yaml", "/etc/beliefnav/companion.yaml"]
               for k, a in steps)
    users = [a for k, a in steps if k == "USER"]
    assert users == ["beliefnav"]  # not root
    froms = [a for k, a in steps if k == "FROM"]
    assert all(re.match(r"python:\$\{PYTHON_VERSION\}-slim-bookworm", f) for f in froms)
    assert next(a for k, a in steps if k == "ARG").startswith("PYTHON_VERSION=3.11")


def test_the_companion_says_where_it_waits_for_a_heartbeat(tmp_path):
    """The packaged configuration with --master and --out overridden on the command line: the first
    line is said at once (not after the discovery time-out), then one error line, exit 2."""
    port = free_port()
    argv = [sys.executable, "-m", "gcs_tools", "companion", "--config", str(CONFIG), "--master",
            f"udpin:127.0.0.1:{port}", "--out", str(tmp_path / "out"), "--no-telemetry",
            "--discovery-timeout-s", "3"]
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        t0 = time.monotonic()
        first = proc.stdout.readline()
        said_after_s = time.monotonic() - t0
        assert proc.poll() is None  # still waiting when it said so
        out, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert first == f"companion: waiting for a HEARTBEAT on udpin:127.0.0.1:{port} (up to 3 s)\n"
    assert said_after_s < 30  # (the interpreter's start; the time-out is 3 s after it)
    assert proc.returncode == 2
    assert err.strip().splitlines() == [
        f"beliefnav: error: --master udpin:127.0.0.1:{port}: no autopilot HEARTBEAT within 3 s"]
    assert (tmp_path / "out" / "summary.json").is_file()


def test_a_run_whose_duration_ends_before_any_heartbeat_is_no_success(tmp_path):
    """``--duration-s`` shorter than the discovery time-out (docs/autopilot.md's udpin example with
    nothing sending): the same one line and exit 2 as a discovery time-out, not exit 0 with no autopilot."""
    port = free_port()
    argv = [sys.executable, "-m", "gcs_tools", "companion", "--master", f"udpin:127.0.0.1:{port}",
            "--out", str(tmp_path / "out"), "--no-telemetry", "--duration-s", "1"]
    proc = subprocess.run(argv, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        f"beliefnav: error: --master udpin:127.0.0.1:{port}: no autopilot HEARTBEAT within 1 s"]
    assert (tmp_path / "out" / "summary.json").is_file()
