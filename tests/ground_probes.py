"""Third-party ground clients run against a live vehicle, each in its own process.

``python ground_probes.py mavsdk PORT OUT.json`` connects MAVSDK-Python (udpout to the ground
port) and records what its telemetry and param plugins report; ``... mavproxy PORT OUT.json
STATE_DIR`` drives a real MAVProxy (udpout) through its console and records its output. The
test (tests/test_ground_clients.py) reads the JSON files; nothing here asserts.
"""

from __future__ import annotations

import asyncio
import json
import queue
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

TELEMETRY = ("position", "attitude_quaternion", "armed", "in_air", "flight_mode", "health", "home",
             "position_velocity_ned", "landed_state")


def _plain(value: Any) -> Any:
    """MAVSDK result objects -> JSON (their public attributes), enums -> names."""
    if hasattr(value, "name") and hasattr(value, "value") and not isinstance(value, bool):
        return value.name  # an enum (MAVSDK's are IntEnums)
    if isinstance(value, bool | int | float | str) or value is None:
        return value
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return {k: _plain(getattr(value, k)) for k in dir(value)
            if not k.startswith("_") and not callable(getattr(value, k))}


async def _mavsdk(port: int) -> dict[str, Any]:
    from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
    from mavsdk.asyncio.plugins.param import ParamAsync
    from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

    async def first(gen: Any, timeout_s: float) -> Any:
        async def one() -> Any:
            async for item in gen:
                return item
        return await asyncio.wait_for(one(), timeout_s)

    out: dict[str, Any] = {}
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as mavsdk:
        await mavsdk.add_any_connection(f"udpout://127.0.0.1:{port}")
        system = await mavsdk.first_autopilot(timeout_s=40.0)
        if system is None:
            return {"error": "no autopilot discovered"}
        out["autopilot_type"] = _plain(await system.autopilot_type())
        telemetry = TelemetryAsync(system)
        deadline = time.monotonic() + 20.0

        async def first_of(name: str) -> Any:
            try:
                value = _plain(await first(getattr(telemetry, f"subscribe_{name}")(), 8.0))
                while name == "flight_mode" and value != "OFFBOARD" and time.monotonic() < deadline:
                    value = _plain(await first(getattr(telemetry, f"subscribe_{name}")(), 8.0))
                return value
            except Exception as exc:  # a timeout is a result to report, not a crash
                return {"error": repr(exc)}

        # the first update of each, waiting for a good one where it matters, one after another (health
        # is good only a few seconds into the flight), but HOME_POSITION's (up to 5 s) meanwhile
        home = asyncio.ensure_future(first_of("home"))
        for name in TELEMETRY:
            out[name] = await home if name == "home" else await first_of(name)
        params = ParamAsync(system)
        try:
            out["EST_CHI2_GATE"] = await asyncio.wait_for(params.get_param_float("EST_CHI2_GATE"), 15.0)
            every = await asyncio.wait_for(params.get_all_params(), 20.0)
            out["params"] = {p.name: p.value for p in every.float_params}
        except Exception as exc:
            out["params_error"] = repr(exc)
    return out


def _mavproxy(port: int, state_dir: Path, wall_s: float) -> dict[str, Any]:
    """Start MAVProxy on ``udpout``, wait until it shows OFFBOARD and saved the parameters, let
    it watch the link a few seconds more, then ask ``link`` for its loss statistics."""
    mavproxy = Path(sys.executable).parent / "mavproxy.py"
    proc = subprocess.Popen(
        [sys.executable, str(mavproxy), f"--master=udpout:127.0.0.1:{port}", f"--state-basedir={state_dir}",
         "--default-modules=link,param", "--nowait"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=state_dir,
    )
    lines: queue.Queue[str] = queue.Queue()

    def pump() -> None:
        for line in proc.stdout:  # type: ignore[union-attr]
            lines.put(line.rstrip())

    threading.Thread(target=pump, daemon=True).start()
    seen: list[str] = []
    deadline = time.monotonic() + wall_s

    def until(pred: Any, limit: float) -> bool:
        while time.monotonic() < limit:
            try:
                seen.append(lines.get(timeout=0.2))
            except queue.Empty:
                continue
            if pred():
                return True
        return False

    text = lambda: "\n".join(seen)  # noqa: E731
    ready = until(lambda: "Mode OFFBOARD" in text() and "Saved" in text(), deadline)
    if ready:
        time.sleep(2.0)  # a few more seconds of traffic counted (from its start: > 1000 packets by then)
        assert proc.stdin is not None
        proc.stdin.write("link\n")
        proc.stdin.flush()
        until(lambda: "packets" in seen[-1] if seen else False, deadline)
    proc.terminate()
    try:
        proc.wait(timeout=1)  # (it often ignores SIGTERM; its output is all read by now)
    except subprocess.TimeoutExpired:
        proc.kill()
    until(lambda: False, time.monotonic() + 0.5)
    return {"ready": ready, "output": seen}


def main() -> int:
    kind, port, out = sys.argv[1], int(sys.argv[2]), Path(sys.argv[3])
    if kind == "mavsdk":
        result = asyncio.run(_mavsdk(port))
    else:
        result = _mavproxy(port, Path(sys.argv[4]), float(sys.argv[5]))
    out.write_text(json.dumps(result, default=repr))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
