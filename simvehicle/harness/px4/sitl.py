"""Start PX4 SITL (the real autopilot firmware, with its built-in SIH quadrotor) as a context manager.

```python
from simvehicle.harness.px4.sitl import Px4Config, Px4Sitl
with Px4Sitl(Px4Config(work_dir=run_dir / "px4", speed_factor=5, params={"EKF2_GPS_DELAY": 110})) as px4:
    px4.url          # "udpin:127.0.0.1:<14540 + i>": where PX4's onboard link sends (a companion listens)
    px4.system_id    # i + 1
    px4.instance     # the -i chosen (the first free one)
```

The firmware directory (``bin/px4``, ``etc/``) may be read-only and shared: each launch copies
the binary into ``work_dir/bin`` with the ``px4-<command>`` links PX4's start script calls, and
runs there (``-w work_dir/rootfs``: parameters, dataman, logs). ``params`` go into
``work_dir/bin/px4-rc.params``, which the start script sources after the airframe, so they are
in force from boot; logging is off unless ``logging`` (``SDLOG_MODE`` -1: a flight logs 10-20 MB).
``speed_factor`` is ``PX4_SIM_SPEED_FACTOR`` (lockstep; <= 10 on two cores, where it measured
9.5x at 10); ``home`` sets the SIH origin (``PX4_HOME_LAT/LON/ALT``).

Instance ``i`` (0..9: above 9 the onboard ports collide) answers as system ``i + 1`` and shifts
every UDP port by ``i``: it listens on 14580 + i (onboard), 18570 + i (GCS), 14280 + i, 13030 + i,
19450 + i and sends to 14540 + i. The first instance whose ports are all free (and whose
``/tmp/px4-sock-i`` answers nobody) is taken; a lost race moves on to the next. Starting waits
for the first HEARTBEAT on 14540 + i (:meth:`Px4Sitl.wait_heartbeat`, unless
``start(wait_heartbeat=False)``). Stopping sends SIGTERM to the process group, SIGKILL after
``stop_timeout_s``, and removes the server socket PX4 leaves in /tmp: nothing is left behind.

Directory: ``Px4Config.px4_dir``, else ``$BELIEFNAV_PX4_DIR``, else ``<repo>/../shared/tools/px4``.
"""

from __future__ import annotations

import contextlib
import math
import os
import shutil
import signal
import socket
import subprocess
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType

from companion.errors import UserError
from simvehicle.harness.firmware import log_tail, port_free, signal_group, stop_group

DIR_ENV = "BELIEFNAV_PX4_DIR"
REPO_ROOT = Path(__file__).resolve().parents[3]
DEFAULT_DIR = REPO_ROOT.parent / "shared" / "tools" / "px4"
OFFBOARD_REMOTE_BASE = 14540  # PX4 sends its onboard link here (+ instance): a companion listens
GCS_LOCAL_BASE = 18570  # PX4's GCS link binds this (+ instance): a ground station sends to it
UDP_LOCAL_BASES = (14580, GCS_LOCAL_BASE, 14280, 13030, 19450)  # what PX4 binds (+ instance)
MAX_INSTANCE = 9  # above 9 the onboard link's remote port is shared (14549)
SOCKET_PATH = "/tmp/px4-sock-{}"


@dataclass(frozen=True, slots=True)
class Px4Config:
    work_dir: Path  # bin/ (the copied binary), rootfs/ (PX4's working directory), px4.log
    px4_dir: Path | None = None  # bin/px4 and etc/; None: $BELIEFNAV_PX4_DIR, else the shared tools' px4
    speed_factor: float = 1.0  # PX4_SIM_SPEED_FACTOR: simulated seconds per wall second
    instance: int | None = None  # -i; None: the first free one in instance_range
    instance_range: tuple[int, int] = (0, MAX_INSTANCE + 1)  # [first, last) instances probed
    home: tuple[float, float, float] | None = None  # SIH origin: lat deg, lon deg, alt m (AMSL)
    params: Mapping[str, float] = field(default_factory=dict)  # set at boot (px4-rc.params)
    logging: bool = False  # the ULog logger (SDLOG_MODE): off by default
    model: str = "sihsim_quadx"  # PX4_SIM_MODEL
    start_timeout_s: float = 30.0  # wall time for the first HEARTBEAT
    stop_timeout_s: float = 5.0  # wall time between SIGTERM and SIGKILL


def resolve_dir(px4_dir: Path | None = None) -> Path:
    """The PX4 directory to run from, checked (else a UserError)."""
    path = px4_dir or (Path(os.environ[DIR_ENV]) if os.environ.get(DIR_ENV) else DEFAULT_DIR)
    binary = path / "bin" / "px4"
    if not binary.is_file():
        raise UserError(f"PX4 SITL not found: {binary} (set {DIR_ENV} to the directory of bin/px4 and etc/)")
    if not os.access(binary, os.X_OK) or not (path / "etc" / "init.d-posix" / "rcS").is_file():
        raise UserError(f"PX4 SITL directory {path} lacks an executable bin/px4 or etc/init.d-posix/rcS")
    return path


def instance_ports(instance: int) -> tuple[int, ...]:
    """The UDP ports instance ``instance`` uses: where it sends (first), then what it binds."""
    return (OFFBOARD_REMOTE_BASE + instance, *(base + instance for base in UDP_LOCAL_BASES))


def _server_alive(instance: int) -> bool:
    """Whether a PX4 server answers on /tmp/px4-sock-<instance> (a stale file answers nobody)."""
    path = SOCKET_PATH.format(instance)
    if not os.path.exists(path):
        return False
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        try:
            s.connect(path)
        except OSError:
            return False
    return True


def free_instance(first: int = 0, last: int = MAX_INSTANCE + 1, skip: frozenset[int] = frozenset()) -> int:
    for instance in range(first, min(last, MAX_INSTANCE + 1)):
        if instance in skip or _server_alive(instance):
            continue
        if all(port_free(p, socket.SOCK_DGRAM) for p in instance_ports(instance)):
            return instance
    last = min(last, MAX_INSTANCE + 1) - 1
    raise UserError(f"no free PX4 SITL instance in -i {first}..{last} (ports in use)")


def _param_lines(params: Mapping[str, float], logging: bool) -> str:
    lines = ["#!/bin/sh", "# written by simvehicle.harness.px4.sitl: sourced by PX4's rcS after the airframe"]
    if not logging:
        lines.append("param set SDLOG_MODE -1")
    for name, value in params.items():
        if not name or not name.replace("_", "").isalnum() or not name.isupper() or len(name) > 16:
            raise UserError(f"bad PX4 parameter name {name!r} (upper case, at most 16 characters)")
        v = float(value)
        if not math.isfinite(v):
            raise UserError(f"PX4 parameter {name} must be finite, got {v}")
        lines.append(f"param set {name} {int(v) if v.is_integer() else repr(v)}")
    return "\n".join(lines) + "\n"


class Px4Sitl:
    """One running PX4 SITL; ``with`` starts and stops it."""

    def __init__(self, config: Px4Config) -> None:
        if not (math.isfinite(config.speed_factor) and config.speed_factor > 0):
            raise UserError(f"PX4 speed factor must be positive, got {config.speed_factor}")
        self.config = config
        self.px4_dir = resolve_dir(config.px4_dir)
        self.work_dir = config.work_dir.resolve()
        self.instance = -1
        self.process: subprocess.Popen[bytes] | None = None
        self.starts = 0

    # -- addresses ----------------------------------------------------------------------------
    @property
    def system_id(self) -> int:
        return self.instance + 1

    @property
    def offboard_port(self) -> int:
        """Where PX4's onboard link sends (a companion listens here)."""
        return OFFBOARD_REMOTE_BASE + self.instance

    @property
    def url(self) -> str:
        return f"udpin:127.0.0.1:{self.offboard_port}"

    @property
    def gcs_url(self) -> str:
        """PX4's GCS link (MAVLink mode Normal): send to it, it answers to the sender's address."""
        return f"udpout:127.0.0.1:{GCS_LOCAL_BASE + self.instance}"

    @property
    def log_dir(self) -> Path:
        """Where PX4's logger writes its ULogs (``logging``): ``rootfs/log/<date>/<time>.ulg``."""
        return self.work_dir / "rootfs" / "log"

    def ulogs(self) -> list[Path]:
        """The ULogs written so far, oldest first."""
        return sorted(self.log_dir.rglob("*.ulg"), key=lambda p: p.stat().st_mtime)

    def listener(self, topic: str, timeout_s: float = 10.0) -> str:
        """``px4-listener TOPIC`` on this instance: the latest uORB message as PX4 prints it."""
        out = subprocess.run([str(self.work_dir / "bin" / "px4-listener"), "--instance", str(self.instance),
                              topic], capture_output=True, text=True, timeout=timeout_s,
                             cwd=self.work_dir / "rootfs", check=False)
        return out.stdout

    @property
    def log_path(self) -> Path:
        return self.work_dir / "px4.log"

    # -- life cycle ---------------------------------------------------------------------------
    def _prepare(self) -> Path:
        """work_dir/bin: the binary, its px4-<command> links, our px4-rc.params."""
        bin_dir = self.work_dir / "bin"
        if bin_dir.exists():
            shutil.rmtree(bin_dir)
        bin_dir.mkdir(parents=True)
        source = self.px4_dir / "bin"
        shutil.copy2(source / "px4", bin_dir / "px4")
        for entry in source.iterdir():
            if entry.name.startswith("px4-") and entry.name != "px4-alias.sh":
                (bin_dir / entry.name).symlink_to("px4")
        if (source / "px4-alias.sh").is_file():
            shutil.copy2(source / "px4-alias.sh", bin_dir / "px4-alias.sh")
        (bin_dir / "px4-rc.params").write_text(_param_lines(self.config.params, self.config.logging))
        return bin_dir / "px4"

    def _env(self) -> dict[str, str]:
        c = self.config
        env = {k: v for k, v in os.environ.items() if not k.startswith("PX4_")}
        env["PX4_SIM_MODEL"] = c.model
        if c.speed_factor != 1.0:
            env["PX4_SIM_SPEED_FACTOR"] = f"{c.speed_factor:g}"
        if c.home is not None:
            env["PX4_HOME_LAT"], env["PX4_HOME_LON"], env["PX4_HOME_ALT"] = (f"{v:.9g}" for v in c.home)
        return env

    def start(self, wait_heartbeat: bool = True) -> Px4Sitl:
        c = self.config
        binary = self._prepare()
        tried: set[int] = set()
        while True:
            self.instance = c.instance if c.instance is not None else free_instance(
                *c.instance_range, skip=frozenset(tried))
            if self._launch(binary, fresh=True):
                break
            tried.add(self.instance)
            if c.instance is not None:
                raise UserError(f"PX4 SITL -i {c.instance} did not start: {self._tail()}")
        if wait_heartbeat:
            self.wait_heartbeat(c.start_timeout_s)
        return self

    def _launch(self, binary: Path, fresh: bool) -> bool:
        """Start the firmware; False when it exits at once (another PX4 took the instance)."""
        rootfs = self.work_dir / "rootfs"
        if fresh and rootfs.exists():
            shutil.rmtree(rootfs)
        rootfs.mkdir(parents=True, exist_ok=True)
        with contextlib.suppress(FileNotFoundError):
            if not _server_alive(self.instance):
                os.unlink(SOCKET_PATH.format(self.instance))  # a stale socket of a killed PX4
        with self.log_path.open("ab") as log:
            self.process = subprocess.Popen(
                [str(binary), "-d", "-i", str(self.instance), "-w", str(rootfs), str(self.px4_dir / "etc")],
                cwd=self.work_dir, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
                env=self._env(), start_new_session=True)
        self.starts += 1
        time.sleep(0.3)
        if self.process.poll() is not None:
            self.process = None
            self._remove_socket()
            return False
        return True

    def wait_heartbeat(self, timeout_s: float) -> None:
        """Until PX4's HEARTBEAT (system ``i + 1``) arrives on 14540 + i (listened to briefly, so a
        companion can take the port afterwards)."""
        from companion.mavlink.frames import parse_datagram

        deadline = time.monotonic() + timeout_s
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            try:
                s.bind(("127.0.0.1", self.offboard_port))
            except OSError as exc:
                self.stop()
                raise UserError(f"PX4 SITL: UDP {self.offboard_port} is taken: {exc.strerror}") from None
            s.settimeout(0.2)
            while time.monotonic() < deadline:
                if not self.running():
                    raise UserError(f"PX4 SITL -i {self.instance} exited: {self._tail()}")
                try:
                    data = s.recv(65_535)
                except TimeoutError:
                    continue
                views, _ = parse_datagram(data)
                if any(v.get_type() == "HEARTBEAT" and v.get_srcSystem() == self.system_id for v in views):
                    return
        self.stop()
        raise UserError(f"PX4 SITL -i {self.instance}: no HEARTBEAT within {timeout_s:g} s: {self._tail()}")

    def _tail(self) -> str:
        return log_tail(self.log_path)

    def running(self) -> bool:
        return self.process is not None and self.process.poll() is None

    def restart(self, wait_heartbeat: bool = True) -> None:
        """Reboot: stop the firmware and start it again on the same instance, parameters kept."""
        self.stop()
        if not self._launch(self.work_dir / "bin" / "px4", fresh=False):
            raise UserError(f"PX4 SITL -i {self.instance} did not restart: {self._tail()}")
        if wait_heartbeat:
            self.wait_heartbeat(self.config.start_timeout_s)

    def stop(self) -> int | None:
        """Stop the firmware (SIGTERM to its group, SIGKILL after the time-out); its exit code."""
        proc, self.process = self.process, None
        if proc is None:
            return None
        stop_group(proc, self.config.stop_timeout_s)
        signal_group(proc, signal.SIGKILL)  # whatever its start script left running
        self._remove_socket()
        return proc.returncode

    def _remove_socket(self) -> None:
        if self.instance >= 0 and not _server_alive(self.instance):
            with contextlib.suppress(FileNotFoundError):
                os.unlink(SOCKET_PATH.format(self.instance))

    def __enter__(self) -> Px4Sitl:
        return self.start()

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.stop()

