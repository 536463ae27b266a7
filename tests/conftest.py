"""Test-run isolation and scheduling.

* Every Zenoh session of this run (and of the processes it starts) uses a private hub port, so
  concurrent runs and a developer's live tools never share a mesh; under pytest-xdist each worker
  gets its own (a worker inherits the controller's environment), unless the developer set
  ``BELIEFNAV_ZENOH_HUB`` themselves.
* Tests that start a real autopilot (ArduPilot or PX4 SITL: their modules use the helpers named in
  ``_AUTOPILOT_HELPERS``) are marked ``autopilot``. ``make test`` runs the others on two workers, then
  these alone and one after another: a lockstep autopilot at 5x beside other CPU-heavy tests would
  make its real-time margins the test instead of the code."""

import os
import socket

import pytest

_HUB_OWNER = "_BELIEFNAV_ZENOH_HUB_FROM_CONFTEST"
_AUTOPILOT_HELPERS = ("require_ardupilot", "require_px4", "px4_fixture", "running_px4")


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
