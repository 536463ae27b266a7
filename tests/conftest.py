"""Test-run isolation and scheduling.

* Every Zenoh session of this run (and of the processes it starts) uses a private hub port, so
  concurrent runs and a developer's live tools never share a mesh; under pytest-xdist each worker
  gets its own (a worker inherits the controller's environment), unless the developer set
  ``BELIEFNAV_ZENOH_HUB`` themselves.
* Tests that start a real autopilot (ArduPilot or PX4 SITL: their modules use the helpers named in
  ``_AUTOPILOT_HELPERS``) are marked ``autopilot``. ``make test`` runs the others on two workers, then
  these alone and one after another: a lockstep autopilot at 5x beside other CPU-heavy tests would
  make its real-time margins the test instead of the code (measured 2026-11-27 on the shared VM: the
  ArduPilot tests on two workers, 2 of 16 failed with commands seconds late; two PX4 flights at once,
  both failed).
* ``quad106_replayed``: one ``beliefnav replay`` of the real quad106 log per test run, read by the
  modules that test what it wrote (figures, export)."""

import contextlib
import fcntl
import io
import os
import socket
from pathlib import Path

import pytest

_HUB_OWNER = "_BELIEFNAV_ZENOH_HUB_FROM_CONFTEST"
_AUTOPILOT_HELPERS = ("require_ardupilot", "require_px4", "px4_fixture", "running_px4")


QUAD106 = Path(__file__).parent / "data" / "quad106.tlog"


@pytest.fixture(scope="session")
def quad106_replayed(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """``beliefnav replay tests/data/quad106.tlog --out DIR --no-progress`` (in process, exit 0), run
    once per test run: DIR and what the command printed. The command is deterministic; under
    pytest-xdist the first worker runs it under a lock and the others read what it left."""
    from gcs_tools.cli import main

    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent  # the run's directory, shared by its workers
    out, printed = root / "quad106-replay", root / "quad106-replay.printed"
    with open(root / "quad106-replay.lock", "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        if not printed.exists():
            text = io.StringIO()
            with contextlib.redirect_stdout(text):
                code = main(["replay", str(QUAD106), "--out", str(out), "--no-progress"])
            assert code == 0, text.getvalue()
            printed.with_suffix(".partial").write_text(text.getvalue())
            printed.with_suffix(".partial").rename(printed)  # complete, or absent
    return out, printed.read_text()


def _free_hub() -> str:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{s.getsockname()[1]}"


def pytest_configure(config: pytest.Config) -> None:
    worker = os.environ.get("PYTEST_XDIST_WORKER")
    if "BELIEFNAV_ZENOH_HUB" not in os.environ or (worker and os.environ.get(_HUB_OWNER)):
        os.environ["BELIEFNAV_ZENOH_HUB"] = _free_hub()
        os.environ[_HUB_OWNER] = "1"


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        module = getattr(item, "module", None)
        if module is not None and any(hasattr(module, name) for name in _AUTOPILOT_HELPERS):
            item.add_marker(pytest.mark.autopilot)
