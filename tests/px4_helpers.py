"""PX4 SITL for tests (SIH quadrotor, ``simvehicle.harness.px4.sitl``): the firmware from
``<repo>/../shared/tools/px4/`` (or $BELIEFNAV_PX4_DIR). Missing, the tests skip on a developer
machine and FAIL in CI (environment CI=true), where the shared directory is always checked out
beside the repo.

- :func:`require_px4` — the directory, or skip/fail.
- :func:`running_px4` — a context manager: a PX4 on the first free instance (its own ports, its
  own system id ``instance + 1``), started in a work directory, its first HEARTBEAT awaited;
  on exit it is stopped (process group SIGTERM, then SIGKILL) and checked gone: no process,
  no /tmp/px4-sock-<i> left.
- :func:`px4_fixture` — the same as a pytest fixture, module-scoped by default, so the tests of
  a module share one PX4 (it boots in 1-4 s; at ``PX4_TEST_SPEED`` it flies 5x real time).

```python
from px4_helpers import px4_fixture
px4 = px4_fixture(speed_factor=5, params={"EKF2_GPS_DELAY": 110})

def test_something(px4, tmp_path):
    run_companion(px4.url, tmp_path / "out", ...)   # udpin:127.0.0.1:<14540 + i>
```
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from ardupilot_helpers import require_tool

from simvehicle.harness.px4.sitl import SOCKET_PATH, Px4Config, Px4Sitl, resolve_dir

PX4_TEST_SPEED = 5.0  # PX4_SIM_SPEED_FACTOR for tests: 4.9x measured, leaves a core for the rest


def require_px4() -> Path:
    return require_tool(resolve_dir, "PX4 SITL")


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().split()[2]
    except OSError:
        return False
    return state != "Z"


@contextlib.contextmanager
def running_px4(work_dir: Path, speed_factor: float = PX4_TEST_SPEED, **config: Any) -> Iterator[Px4Sitl]:
    """A started PX4 (see the module doc); stopped and checked gone on exit."""
    require_px4()
    sitl = Px4Sitl(Px4Config(work_dir=work_dir, speed_factor=speed_factor, **config))
    sitl.start()
    pid = sitl.process.pid if sitl.process is not None else -1
    try:
        yield sitl
    finally:
        sitl.stop()
        assert not _alive(pid), f"PX4 (pid {pid}) still running after stop"
        assert not os.path.exists(SOCKET_PATH.format(sitl.instance)), "PX4 left its server socket"


def px4_fixture(scope: str = "module", speed_factor: float = PX4_TEST_SPEED, **config: Any) -> Any:
    """A pytest fixture yielding a running :class:`Px4Sitl` shared by the tests of ``scope``."""

    @pytest.fixture(scope=scope)  # type: ignore[misc]
    def px4(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Px4Sitl]:
        with running_px4(tmp_path_factory.mktemp("px4"), speed_factor, **config) as sitl:
            yield sitl

    return px4
