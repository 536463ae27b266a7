"""Shared fixtures of the SITL tests: real processes on free loopback ports, always stopped."""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from simvehicle.harness.sitl.launcher import SitlOptions, child_specs, prepare_signing
from simvehicle.harness.sitl.supervisor import ChildSpec, Supervisor, free_udp_ports


def require_pieces() -> None:
    """Skip until the estimator's Navigator and the SimVehicle have landed."""
    try:
        from companion.estimator import Navigator  # noqa: F401
        from simvehicle import SimVehicle  # noqa: F401
    except ImportError as exc:
        pytest.skip(f"needs the estimator and vehicle: {exc}")


def route_duration_s(mission: str, profile: int) -> float:
    from companion.mission import load_mission
    from companion.planning import plan_route

    return plan_route(load_mission(mission), profile).duration_s


class Trio:
    """The three processes started by hand (so a test can kill, restart or impersonate one)."""

    def __init__(self, out: Path, opts: SitlOptions, estimator_bind_port: int | None = None,
                 bridge_bind_port: int | None = None) -> None:
        self.out = out
        self.opts = opts
        self.ports = tuple(free_udp_ports(3))
        self.estimator_bind_port = estimator_bind_port
        self.sup = Supervisor(out / "logs")
        prepare_signing(opts)  # signed as `beliefnav sitl` is by default
        self.specs = {s.name: s for s in child_specs(opts, self.ports)}  # type: ignore[arg-type]
        for name, port in (("estimator", estimator_bind_port), ("bridge", bridge_bind_port)):
            if port is not None:
                spec = self.specs[name]
                self.specs[name] = ChildSpec(name, (*spec.module_argv, "--bind-port", str(port)))
        self.vehicle = self.sup.start(self.specs["vehicle"], stdout=subprocess.PIPE)
        os.set_blocking(self.vehicle.stdout.fileno(), False)  # type: ignore[union-attr]
        self.start("estimator")
        self.start("bridge")
        self._buffer = b""
        self.t_s = 0.0

    def start(self, name: str, tag: str = "") -> subprocess.Popen[bytes]:
        spec = self.specs[name]
        if tag:
            spec = ChildSpec(f"{name}{tag}", tuple(a.replace(f"{name}.json", f"{name}{tag}.json")
                                                   for a in spec.module_argv))
        return self.sup.start(spec)

    def poll_progress(self) -> float:
        try:
            chunk = self.vehicle.stdout.read()  # type: ignore[union-attr]
        except (BlockingIOError, ValueError):
            chunk = None
        if chunk:
            self._buffer += chunk
            *lines, self._buffer = self._buffer.split(b"\n")
            for line in lines:
                with contextlib.suppress(ValueError, KeyError):
                    self.t_s = float(json.loads(line)["t_s"])
        return self.t_s

    def wait_sim_time(self, t_s: float, wall_timeout_s: float) -> None:
        deadline = time.monotonic() + wall_timeout_s
        while self.poll_progress() < t_s:
            assert self.vehicle.poll() is None, "vehicle ended early"
            assert time.monotonic() < deadline, f"simulated time {t_s} s not reached"
            time.sleep(0.05)

    def wait_vehicle(self, wall_timeout_s: float) -> dict:
        self.vehicle.wait(timeout=wall_timeout_s)
        return json.loads((self.out / "vehicle.json").read_text())

    def stop(self) -> None:
        self.sup.stop(order=("vehicle",))


def run_cli(*args: str, timeout_s: float = 55.0, figures: bool = False) -> subprocess.CompletedProcess[str]:
    """``beliefnav sitl --no-progress ARGS``; without ``figures`` also ``--no-figures`` (map.png and
    belief.png cost ~2 s of CPU; the shared lockstep flight draws and checks them)."""
    extra = [] if figures else ["--no-figures"]
    return subprocess.run([sys.executable, "-m", "gcs_tools", "sitl", "--no-progress", *extra, *args],
                          capture_output=True, text=True, timeout=timeout_s)


def children_of(out: Path) -> list[int]:
    """Pids of live processes whose command line names ``out`` (our children)."""
    pids = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            cmd = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            state = (entry / "stat").read_text().split()[2]
        except OSError:
            continue
        ours = str(out) in cmd and ("-m simvehicle" in cmd or "-m companion" in cmd)
        if ours and state != "Z":
            pids.append(int(entry.name))
    return pids
