"""The import rules of docs/ARCHITECTURE.md, as import-linter contracts (pyproject.toml), hold."""

import pkgutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

import simvehicle

ROOT = Path(__file__).resolve().parents[1]


def _contracts() -> list[dict]:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]["contracts"]


def test_every_contract_is_kept():
    pytest.importorskip("importlinter")
    lint = Path(sys.executable).parent / "lint-imports"
    done = subprocess.run([str(lint), "--no-cache"], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-2000:]
    assert f"Contracts: {len(_contracts())} kept, 0 broken." in done.stdout


def test_the_vehicle_core_contract_lists_every_module_but_the_harness():
    """A new simvehicle module is core (no estimator, no planner) unless it lives in the harness."""
    core = next(c for c in _contracts() if c["name"].startswith("the vehicle core"))
    found = pkgutil.iter_modules(simvehicle.__path__)
    modules = {f"simvehicle.{m.name}" for m in found if m.name != "harness"}
    assert modules == set(core["source_modules"])
