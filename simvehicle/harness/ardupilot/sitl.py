"""Start ArduCopter SITL (the real autopilot firmware built for Linux) as a context manager.

```python
from simvehicle.harness.ardupilot.sitl import ArduPilotSitl, SitlConfig
with ArduPilotSitl(SitlConfig(work_dir=run_dir / "ardupilot", speedup=10,
                              params={"GPS1_TYPE": 14})) as sitl:
    sitl.url           # "tcp:127.0.0.1:5760+10*I" = SERIAL0 (the simulation waits for a client here)
    sitl.serial_urls   # SERIAL0..2 (SERIAL1/2 do not block; they listen once SERIAL0 has a client:
                       # sitl.wait_serial(1) returns SERIAL1's URL when it does)
    sitl.instance      # the -I chosen (first one whose ports are all free)
```

Parameters: ArduPilot reads every ``--defaults`` file at boot, and with ``-w`` (wipe the
stored parameters, the default here) those defaults are what the firmware boots with. The
extra ``params`` are written to ``work_dir/extra.parm`` and passed after ``copter.parm``, so
they win and are in force from the first boot: parameters that ArduPilot only applies at boot
(``GPS1_TYPE``, ``VISO_TYPE``, ``EK3_SRC1_*``) need no reboot. :meth:`ArduPilotSitl.restart`
stops the firmware and starts it again in the same directory without ``-w`` (its stored
parameters kept): a real reboot, for tests of what a companion does when the autopilot reboots.

The firmware writes ``eeprom.bin``, ``logs/`` (DataFlash ``.bin``) and ``terrain/`` into its
working directory; stdout/stderr go to ``work_dir/arducopter.log``. Stopping sends SIGTERM to
its process group, then SIGKILL after ``stop_timeout_s``.

Binary: ``SitlConfig.binary``, else environment ``BELIEFNAV_ARDUPILOT_BIN``, else
``<repo>/../shared/tools/ardupilot/arducopter``; defaults file: ``copter.parm`` beside it.
"""

from __future__ import annotations

import os
import subprocess
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType

from companion.errors import UserError
from simvehicle.harness.firmware import log_tail, port_free, stop_group

BINARY_ENV = "BELIEFNAV_ARDUPILOT_BIN"
REPO_ROOT = Path(__file__).resolve().parents[3]
DEFAULT_BINARY = REPO_ROOT.parent / "shared" / "tools" / "ardupilot" / "arducopter"
DEFAULTS_NAME = "copter.parm"
SERIAL0_BASE_PORT = 5760  # SERIAL0 TCP; SERIAL1 = +2, SERIAL2 = +3; -I N adds 10 N to each
SERIAL_OFFSETS = (0, 2, 3)
INSTANCE_PORT_STEP = 10
# ArduPilot's autotest home: lat deg, lon deg, alt m, heading deg
CANBERRA_HOME = (-35.363261, 149.165230, 584.0, 353.0)


@dataclass(frozen=True, slots=True)
class SitlConfig:
    work_dir: Path  # the firmware's working directory (eeprom.bin, logs/, terrain/, arducopter.log)
    binary: Path | None = None  # None: $BELIEFNAV_ARDUPILOT_BIN, else the shared tools' arducopter
    defaults: Path | None = None  # None: copter.parm beside the binary
    home: tuple[float, float, float, float] = CANBERRA_HOME  # lat deg, lon deg, alt m (AMSL), heading deg
    speedup: float = 10.0  # simulated seconds per wall second
    model: str = "+"  # SITL frame model
    instance: int | None = None  # -I; None: the first free one in instance_range
    instance_range: tuple[int, int] = (0, 100)  # [first, last) instances probed
    params: Mapping[str, float] = field(default_factory=dict)  # extra parameters, in force from boot
    wipe: bool = True  # -w: forget stored parameters (eeprom.bin) at start
    start_timeout_s: float = 20.0  # wall time for SERIAL0 to start listening
    stop_timeout_s: float = 5.0  # wall time between SIGTERM and SIGKILL


def resolve_binary(binary: Path | None = None) -> Path:
    """The arducopter binary to run, checked to exist and be executable (else a UserError)."""
    path = binary or (Path(os.environ[BINARY_ENV]) if os.environ.get(BINARY_ENV) else DEFAULT_BINARY)
    if not path.is_file():
        raise UserError(f"ArduCopter SITL binary not found: {path} (set {BINARY_ENV} or pass the path)")
    if not os.access(path, os.X_OK):
        raise UserError(f"ArduCopter SITL binary is not executable: {path}")
    return path


def instance_ports(instance: int) -> tuple[int, int, int]:
    """TCP ports of SERIAL0..2 for ``-I instance``."""
    base = SERIAL0_BASE_PORT + INSTANCE_PORT_STEP * instance
    return tuple(base + off for off in SERIAL_OFFSETS)  # type: ignore[return-value]


def free_instance(first: int = 0, last: int = 100, skip: frozenset[int] = frozenset()) -> int:
    """The first ``-I`` in [first, last) whose three serial ports are free (a UserError if none)."""
    for instance in range(first, last):
        if instance not in skip and all(port_free(p) for p in instance_ports(instance)):
            return instance
    raise UserError(f"no free ArduPilot SITL instance in -I {first}..{last - 1} (TCP ports in use)")


def write_param_file(path: Path, params: Mapping[str, float]) -> Path:
    """A parameter file in ArduPilot's ``NAME VALUE`` format (names checked, values finite)."""
    lines = []
    for name, value in params.items():
        if not name or not name.replace("_", "").isalnum() or not name.isupper() or len(name) > 16:
            raise UserError(f"bad ArduPilot parameter name {name!r} (upper case, at most 16 characters)")
        value = float(value)
        if value != value or value in (float("inf"), float("-inf")):
            raise UserError(f"ArduPilot parameter {name} must be finite, got {value}")
        lines.append(f"{name} {value:.9g}\n")
    path.write_text("".join(lines))
    return path


class ArduPilotSitl:
    """One running ArduCopter SITL; ``with`` starts and stops it."""

    def __init__(self, config: SitlConfig) -> None:
        self.config = config
        self.binary = resolve_binary(config.binary)
        self.defaults = config.defaults or self.binary.with_name(DEFAULTS_NAME)
        if not self.defaults.is_file():
            raise UserError(f"ArduPilot defaults file not found: {self.defaults}")
        self.work_dir = config.work_dir.resolve()
        self.instance = -1
        self.process: subprocess.Popen[bytes] | None = None
        self.starts = 0

    # -- addresses ----------------------------------------------------------------------------
    @property
    def ports(self) -> tuple[int, int, int]:
        return instance_ports(self.instance)

    @property
    def url(self) -> str:
        """SERIAL0 as a connection string; the simulation runs only once a client is connected."""
        return f"tcp:127.0.0.1:{self.ports[0]}"

    @property
    def serial_urls(self) -> tuple[str, str, str]:
        return tuple(f"tcp:127.0.0.1:{p}" for p in self.ports)  # type: ignore[return-value]

    @property
    def log_path(self) -> Path:
        return self.work_dir / "arducopter.log"

    @property
    def dataflash_dir(self) -> Path:
        return self.work_dir / "logs"

    # -- life cycle ---------------------------------------------------------------------------
    def command(self, wipe: bool) -> list[str]:
        c = self.config
        defaults = [str(self.defaults)]
        if c.params:
            defaults.append(str(write_param_file(self.work_dir / "extra.parm", c.params)))
        home = ",".join(f"{v:.9g}" for v in c.home)
        cmd = [str(self.binary), "--model", c.model, "--speedup", f"{c.speedup:g}", "--home", home,
               "--defaults", ",".join(defaults), "-I", str(self.instance)]
        return [*cmd, "-w"] if wipe else cmd

    def start(self) -> ArduPilotSitl:
        c = self.config
        if c.speedup <= 0:
            raise UserError(f"--speedup must be positive, got {c.speedup}")
        self.work_dir.mkdir(parents=True, exist_ok=True)
        tried: set[int] = set()
        while True:
            if c.instance is not None:
                self.instance = c.instance
            else:
                self.instance = free_instance(*c.instance_range, skip=frozenset(tried))
            if self._launch(wipe=c.wipe):
                return self
            tried.add(self.instance)
            if c.instance is not None:
                raise UserError(f"ArduCopter SITL -I {c.instance} did not start: {self._tail()}")

    def _launch(self, wipe: bool) -> bool:
        """Start the firmware; True once SERIAL0 listens, False if another process took the port."""
        with self.log_path.open("ab") as log:
            self.process = subprocess.Popen(
                self.command(wipe), cwd=self.work_dir, stdin=subprocess.DEVNULL, stdout=log,
                stderr=subprocess.STDOUT, start_new_session=True)
        self.starts += 1
        deadline = time.monotonic() + self.config.start_timeout_s
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                self.process = None
                return False  # most often: the port was taken between the probe and the bind
            if self._listening():
                return True
            time.sleep(0.05)
        self.stop()
        raise UserError(f"ArduCopter SITL did not open TCP port {self.ports[0]} within "
                        f"{self.config.start_timeout_s:g} s: {self._tail()}")

    def wait_serial(self, index: int, timeout_s: float = 20.0) -> str:
        """The URL of SERIAL``index`` once it listens (SERIAL1/2 open only after SERIAL0 has a client)."""
        deadline = time.monotonic() + timeout_s
        while not port_listening(self.ports[index]):
            if not self.running() or time.monotonic() > deadline:
                raise UserError(f"ArduCopter SITL SERIAL{index} (TCP {self.ports[index]}) is not listening: "
                                f"{self._tail()}")
            time.sleep(0.05)
        return self.serial_urls[index]

    def _listening(self) -> bool:
        # Connecting to SERIAL0 would make this probe the firmware's client; ask the kernel instead.
        return port_listening(self.ports[0])

    def _tail(self) -> str:
        return log_tail(self.log_path)

    def running(self) -> bool:
        return self.process is not None and self.process.poll() is None

    def restart(self) -> None:
        """Reboot: stop the firmware and start it again on the same instance, stored parameters kept."""
        self.stop()
        if not self._launch(wipe=False):
            raise UserError(f"ArduCopter SITL -I {self.instance} did not restart: {self._tail()}")

    def stop(self) -> int | None:
        """Stop the firmware (SIGTERM to its group, SIGKILL after the time-out); its exit code."""
        proc, self.process = self.process, None
        return None if proc is None else stop_group(proc, self.config.stop_timeout_s)

    def __enter__(self) -> ArduPilotSitl:
        return self.start()

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.stop()


def port_listening(port: int) -> bool:
    """Whether a TCP socket in LISTEN state holds ``port`` (from /proc/net/tcp, no connection made)."""
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            rows = Path(table).read_text().splitlines()[1:]
        except OSError:
            continue
        for row in rows:
            cols = row.split()
            if len(cols) > 3 and cols[3] == "0A" and int(cols[1].rsplit(":", 1)[1], 16) == port:
                return True
    return False
