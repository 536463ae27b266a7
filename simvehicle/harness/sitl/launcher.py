"""Run one SITL flight: three processes over MAVLink/UDP, supervised, then summarised.

The vehicle (``python -m simvehicle``), the companion estimator and the planner bridge
(``python -m companion estimator|bridge``) are started on free (or given) loopback ports. The
launcher shows progress from the vehicle's progress lines; when the vehicle ends (arrival or
its simulated time limit), when any process dies, on Ctrl-C or on the wall-clock timeout, it
stops all three (vehicle first, so it flushes the tlog and time series) and then writes what
was recorded.

MAVLink 2 signing is on by default: every run gets a fresh 32-byte key in ``<out>/signing.key``
(mode 0600, created before any process starts), or uses ``signing_key_file``; ``signing=False``
(``--no-signing``) turns it off.
"""

from __future__ import annotations

import contextlib
import json
import os
import secrets
import signal
import socket
import subprocess
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from companion.errors import UserError
from companion.mission import load_mission
from companion.planning import Route, plan_route
from simvehicle.harness.fly import FlyConfig
from simvehicle.harness.sitl.supervisor import ChildSpec, Supervisor, free_udp_ports, read_tail

PORT_NAMES = ("estimator", "bridge", "ground")
POLL_S = 0.05


@dataclass(frozen=True, slots=True)
class SitlOptions:
    mission: str
    profile: int
    method: str
    seed: int
    out_dir: Path
    max_duration_s: float | None = None  # None: as ``fly`` (start delay + route + margin)
    realtime: bool = False
    signing_key_file: Path | None = None  # None: a fresh key per run in <out>/signing.key
    signing: bool = True  # False: no MAVLink 2 signing (--no-signing)
    ports: tuple[int, int, int] | None = None  # vehicle's estimator, bridge and ground ports
    wall_timeout_s: float | None = None
    drop_probability: float = 0.0  # TEST ONLY: loss injection on every link, both directions
    telemetry_args: tuple[str, ...] = ()  # Zenoh flags for every process (--vehicle-id, --no-telemetry)
    scenario: str | None = None  # the vehicle's sensor scenario (None: the mission file's)
    ground_args: tuple[str, ...] = ()  # vehicle's --ground-out / --no-ground-out flags (default: 14550)
    fly: FlyConfig = field(default_factory=FlyConfig)  # start delay, arrival test, time limit: as ``fly``
    ubx_port: int | None = None  # the raw receiver's UBX TCP port (scenario canyon; None: a free one)


@dataclass(slots=True)
class SitlRun:
    """What the processes left behind (read after they were stopped)."""

    out_dir: Path
    ended_by: str  # "vehicle" (arrival or time limit), "crash:<name>", "timeout", "interrupted"
    return_codes: dict[str, int | None]
    vehicle: dict[str, Any] = field(default_factory=dict)
    estimator: dict[str, Any] = field(default_factory=dict)
    bridge: dict[str, Any] = field(default_factory=dict)
    crash_detail: str = ""
    exit_code: int | None = None  # of the process that ended the run (crash: negative = signal)


def check_ports_free(ports: tuple[int, int, int], host: str = "127.0.0.1") -> None:
    """One clear line naming the first port another program holds."""
    for name, port in zip(PORT_NAMES, ports, strict=True):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            try:
                s.bind((host, port))
            except OSError:
                raise UserError(f"UDP port {port} on {host} ({name} port) is already in use") from None


def flight_plan(opts: SitlOptions) -> tuple[Route, float]:
    """The route the bridge will fly (same start delay as ``fly``) and the simulated time limit."""
    route = plan_route(load_mission(opts.mission), opts.profile, t_start_s=opts.fly.start_delay_s)
    if opts.max_duration_s is not None:
        return route, opts.max_duration_s
    return route, opts.fly.start_delay_s + route.duration_s + max(opts.fly.timeout_margin_s,
                                                                  0.5 * route.duration_s)


def estimator_param_args(mission: str) -> list[str]:
    """``--estimator-param EST_*=VALUE`` for the vehicle's ground link: the parameters the estimator
    process builds from the same mission file (``companion.wiring``; the vehicle knows no estimator)."""
    from companion.wiring import mission_estimator_config
    from simvehicle.params import estimator_param_values

    values = estimator_param_values(mission_estimator_config(load_mission(mission)))
    return [f"--estimator-param={name}={value!r}" for name, value in values.items()]


SIGNING_KEY_NAME = "signing.key"


def signing_key_path(opts: SitlOptions) -> Path | None:
    """The key file all three processes sign with (None: signing off)."""
    if not opts.signing:
        return None
    return opts.signing_key_file or opts.out_dir / SIGNING_KEY_NAME


def write_fresh_key(path: Path) -> None:
    """A new random passphrase (one word of 43 URL-safe characters, 256 random bits; the key is its
    SHA-256), readable by its owner only (0600). One word, so a ground station operator can type
    it into MAVProxy's ``signing key`` (which hashes what it is given the same way)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.unlink(missing_ok=True)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w", encoding="ascii") as f:
        f.write(secrets.token_urlsafe(32) + "\n")


def prepare_signing(opts: SitlOptions) -> None:
    """Create this run's fresh key unless signing is off or the user gave a key file."""
    if opts.signing and opts.signing_key_file is None:
        write_fresh_key(opts.out_dir / SIGNING_KEY_NAME)


def child_specs(opts: SitlOptions, ports: tuple[int, int, int]) -> list[ChildSpec]:
    out = opts.out_dir
    route, max_duration_s = flight_plan(opts)
    goal = route.waypoints_ned_m[-1]
    common: list[str] = list(opts.telemetry_args)
    key = signing_key_path(opts)
    if key is not None:
        common += ["--signing-key-file", str(key)]
    if opts.drop_probability > 0:
        common += ["--drop-probability", str(opts.drop_probability)]

    def loss_seed(k: int) -> list[str]:
        return ["--loss-seed", str(opts.seed * 10 + k)] if opts.drop_probability > 0 else []

    vehicle = [
        "simvehicle", "--mission", opts.mission, "--profile", str(opts.profile), "--seed", str(opts.seed),
        "--estimator-port", str(ports[0]), "--bridge-port", str(ports[1]), "--ground-port", str(ports[2]),
        "--out", str(out), "--max-duration-s", str(max_duration_s),
        "--goal-ned-m", *(repr(float(c)) for c in goal), "--goal-radius-m", str(opts.fly.goal_radius_m),
        "--goal-speed-m-s", str(opts.fly.goal_speed_m_s),
        "--arrive-after-s", str(route.t_start_s + route.duration_s), *opts.ground_args, *common,
        *loss_seed(0), *estimator_param_args(opts.mission),
    ]
    if opts.realtime:
        vehicle.append("--realtime")
    if opts.scenario is not None:
        vehicle += ["--scenario", opts.scenario]
    if opts.ubx_port is not None:
        vehicle += ["--ubx-port", str(opts.ubx_port)]
    estimator = [
        "companion", "estimator", "--vehicle-port", str(ports[0]), "--mission", opts.mission,
        "--method", opts.method, "--stats", str(out / "estimator.json"), "--step-markers", *common,
        *loss_seed(1),
    ]
    bridge = [
        "companion", "bridge", "--vehicle-port", str(ports[1]), "--mission", opts.mission,
        "--profile", str(opts.profile), "--start-delay-s", str(opts.fly.start_delay_s),
        "--stats", str(out / "bridge.json"), *common, *loss_seed(2),
    ]
    return [ChildSpec("vehicle", tuple(vehicle)), ChildSpec("estimator", tuple(estimator)),
            ChildSpec("bridge", tuple(bridge))]


Progress = Callable[[float, float], None]  # (simulated time s, distance to goal m)


def _follow_progress(stream: Any, on_progress: Progress | None) -> None:
    for raw in stream:
        try:
            line = json.loads(raw)
        except ValueError:
            continue
        if on_progress is not None and isinstance(line, dict):
            on_progress(float(line.get("t_s", 0.0)), float(line.get("goal_distance_m", float("nan"))))


def _sigint_sets(event: threading.Event) -> Callable[[], None]:
    """While a flight runs, Ctrl-C sets ``event`` instead of raising KeyboardInterrupt wherever the
    main thread happens to be: an exception raised between a lock's acquire and its ``try`` (as in
    ``subprocess.Popen.poll``) leaves the lock held, and the clean-up's ``wait()`` then blocks for
    ever. Returns the function that puts the previous handler back (a no-op off the main thread)."""
    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    previous = signal.signal(signal.SIGINT, lambda signum, frame: event.set())

    def restore() -> None:
        with contextlib.suppress(ValueError, TypeError):
            signal.signal(signal.SIGINT, previous)
    return restore


def launch(opts: SitlOptions, on_progress: Progress | None = None) -> SitlRun:
    """Fly once; always stops every process and returns what they recorded."""
    ports = opts.ports or tuple(free_udp_ports(3))
    assert len(ports) == 3
    check_ports_free(ports)
    opts.out_dir.mkdir(parents=True, exist_ok=True)
    for stale in ("vehicle.json", "estimator.json", "bridge.json", "vehicle_series.npz", "vehicle_series.f64",
                  "run.tlog", "receiver.json", "receiver.ubx"):
        (opts.out_dir / stale).unlink(missing_ok=True)
    prepare_signing(opts)
    supervisor = Supervisor(opts.out_dir / "logs")
    ended_by = "interrupted"
    detail = ""
    exit_code: int | None = None
    reader: threading.Thread | None = None
    interrupted = threading.Event()
    restore_sigint = _sigint_sets(interrupted)
    try:
        specs = child_specs(opts, ports)
        vehicle = supervisor.start(specs[0], stdout=subprocess.PIPE)
        reader = threading.Thread(target=_follow_progress, args=(vehicle.stdout, on_progress), daemon=True)
        reader.start()
        for spec in specs[1:]:
            supervisor.start(spec)
        deadline = None if opts.wall_timeout_s is None else time.monotonic() + opts.wall_timeout_s
        while True:
            exited = supervisor.first_exit()
            if exited is not None:
                exit_code = exited.returncode
                if exited.name == "vehicle" and exited.returncode == 0:
                    ended_by = "vehicle"
                else:
                    ended_by = f"crash:{exited.name}"
                    detail = read_tail(opts.out_dir / "logs" / f"{exited.name}.log")
                break
            if deadline is not None and time.monotonic() > deadline:
                ended_by = "timeout"
                break
            if interrupted.wait(POLL_S):
                ended_by = "interrupted"
                break
    except KeyboardInterrupt:  # a Ctrl-C before our handler was in place, or off the main thread
        ended_by = "interrupted"
    finally:
        restore_sigint()
        codes = supervisor.stop(order=("vehicle",))
        if reader is not None:
            reader.join(timeout=1.0)
    run = SitlRun(opts.out_dir, ended_by, codes, crash_detail=detail, exit_code=exit_code)
    run.vehicle = _read_json(opts.out_dir / "vehicle.json")
    run.estimator = _read_json(opts.out_dir / "estimator.json")
    run.bridge = _read_json(opts.out_dir / "bridge.json")
    return run


def _read_json(path: Path) -> dict[str, Any]:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
