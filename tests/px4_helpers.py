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
- :class:`GroundStation` — PX4's GCS link as the vehicle's own system id (PX4 takes HIL_GPS only
  from it): ``feed_gps()`` sends a HIL_GPS fix at SIH's true position for every truth sample
  (HIL_STATE_QUATERNION at 10 Hz of PX4's time) from a thread, plus any message via ``send``.
- :func:`listener` — ``px4-listener TOPIC`` parsed into ``{field: text}`` (the newest message).

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
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

os.environ.setdefault("MAVLINK20", "1")  # ODOMETRY (id 331) is MAVLink 2 only
from ardupilot_helpers import require_tool  # noqa: E402
from pymavlink import mavutil  # noqa: E402

from simvehicle.harness.px4.sitl import SOCKET_PATH, Px4Config, Px4Sitl, resolve_dir  # noqa: E402

PX4_TEST_SPEED = 5.0  # PX4_SIM_SPEED_FACTOR for tests: 4.9x measured, leaves a core for the rest
TEST_INSTANCES = (5, 10)  # -i 5..9: clear of the default 0 a developer's own PX4 takes
M = mavutil.mavlink


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


def listener(sitl: Px4Sitl, topic: str) -> dict[str, str]:
    """The newest ``topic`` message as ``{field: value text}`` ({} when never published)."""
    fields = {}
    for line in sitl.listener(topic).splitlines():
        name, sep, value = line.strip().partition(":")
        if sep and name and " " not in name:
            fields[name] = value.strip()
    return fields


class GroundStation:
    """A ground station on PX4's GCS link (``udpout:127.0.0.1:18570 + i``) as system ``i + 1``."""

    def __init__(self, sitl: Px4Sitl) -> None:
        self.sitl = sitl
        self.conn = mavutil.mavlink_connection(sitl.gcs_url, source_system=sitl.system_id,
                                               source_component=190)
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self.gps_sent = 0
        self.last: dict[str, Any] = {}

    def send(self, msg: Any) -> None:
        with self._lock:
            self.conn.mav.send(msg)

    def _announce(self, rate_hz: float) -> None:
        """Our HEARTBEAT (PX4 learns our address from it, also after a reboot) and the truth stream."""
        self.send(M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3))
        self.send(M.MAVLink_command_long_message(self.sitl.system_id, 1, M.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                                 M.MAVLINK_MSG_ID_HIL_STATE_QUATERNION, 1e6 / rate_hz,
                                                 0, 0, 0, 0, 0))

    def feed_gps(self, rate_hz: float = 10.0) -> GroundStation:
        """HIL_GPS at SIH's true position (fix 3D, 0.5 m accuracy) for each truth sample, at ``rate_hz``."""
        def run() -> None:
            announced = 0.0
            while not self._stop.is_set():
                if time.monotonic() - announced > 1.0:
                    announced = time.monotonic()
                    self._announce(rate_hz)
                with self._lock:
                    m = self.conn.recv_match(blocking=False)
                if m is None:
                    time.sleep(0.002)
                    continue
                self.last[m.get_type()] = m
                if m.get_type() == "HIL_STATE_QUATERNION":
                    fix = (3, m.lat, m.lon, m.alt, 50, 80, 0, m.vx, m.vy, m.vz, 65535, 12)
                    self.send(M.MAVLink_hil_gps_message(int(time.time() * 1e6), *fix))
                    self.gps_sent += 1

        self._thread = threading.Thread(target=run, daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5)
        self.conn.close()

    def __enter__(self) -> GroundStation:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def px4_fixture(scope: str = "module", speed_factor: float = PX4_TEST_SPEED, **config: Any) -> Any:
    """A pytest fixture yielding a running :class:`Px4Sitl` shared by the tests of ``scope``."""

    @pytest.fixture(scope=scope)  # type: ignore[misc]
    def px4(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Px4Sitl]:
        with running_px4(tmp_path_factory.mktemp("px4"), speed_factor, **config) as sitl:
            yield sitl

    return px4
