"""Truthful outcomes of a SITL run: one line saying why it failed, or nothing when it succeeded.

Success is exactly: the vehicle ended the flight itself, at the goal, without a collision.
Anything else — the simulated time limit, a collision on the way, a process that died (named,
with its signal or exit status and the last line of its log), the wall-clock time-out, Ctrl-C —
is a failure with a reason. Pure functions of what the launcher and the processes recorded.
"""

from __future__ import annotations

import signal
from typing import Any

from companion.errors import UserError


def check_run_arguments(method: str, seed: int) -> None:
    """Refuse what would only fail once the processes run (one line, exit 2)."""
    from companion.estimator import check_method

    check_method(method)  # names every method and the nearest
    if seed < 0:
        raise UserError(f"--seed must be >= 0, got {seed}")


def describe_exit(returncode: int | None) -> str:
    """``killed by SIGKILL``, ``exited with status 3``, ``still running``."""
    if returncode is None:
        return "still running"
    if returncode < 0:
        try:
            return f"killed by {signal.Signals(-returncode).name}"
        except ValueError:
            return f"killed by signal {-returncode}"
    if returncode > 128 and returncode - 128 in signal.valid_signals():
        return f"exited with status {returncode} ({signal.Signals(returncode - 128).name})"
    return f"exited with status {returncode}"


def process_exits(return_codes: dict[str, int | None], ended_by: str) -> dict[str, dict[str, Any]]:
    """Each process's return code with what it means. The launcher stops every process with
    SIGTERM once the run is over, so 143 (128 + SIGTERM: our processes exit through
    ``SystemExit``) or -15 is the planned stop, not a failure; ``clean`` says so."""
    crashed = ended_by.split(":", 1)[1] if ended_by.startswith("crash:") else None
    out: dict[str, dict[str, Any]] = {}
    for name, rc in return_codes.items():
        if name == crashed:
            exit_, clean = f"ended the run: {describe_exit(rc)}", False
        elif rc == 0:
            exit_, clean = "exited normally", True
        elif rc in (128 + signal.SIGTERM, -signal.SIGTERM):
            exit_, clean = "stopped by the launcher (SIGTERM), as planned", True
        elif rc == -signal.SIGKILL:
            exit_, clean = "killed by SIGKILL: did not stop within the launcher's grace period", False
        else:
            exit_, clean = describe_exit(rc), False
        out[name] = {"return_code": rc, "exit": exit_, "clean": clean}
    return out


def failure_reason(run: Any, summary: dict[str, Any]) -> str:
    """Why the run failed ('' when it reached the goal without a collision). ``run`` is a SitlRun."""
    ended_by: str = run.ended_by
    if ended_by.startswith("crash:"):
        name = ended_by.split(":", 1)[1]
        detail = f": {run.crash_detail}" if run.crash_detail else ""
        return f"{name} process {describe_exit(run.exit_code)}{detail}"
    if ended_by == "timeout":
        return "wall-clock time-out (--wall-timeout-s): every process was stopped"
    if ended_by == "interrupted":
        return "interrupted: every process was stopped"
    collisions = int(summary.get("collisions", 0))
    if collisions:
        return f"the vehicle collided {collisions} time(s)"
    outcome = summary.get("sitl", {}).get("outcome", "unknown")
    if outcome == "timeout":
        limit_s = float(summary.get("duration_s", 0.0))
        return f"the goal was not reached within the simulated time limit ({limit_s:.1f} s)"
    if not summary.get("reached_goal"):
        return f"the goal was not reached (vehicle outcome {outcome!r})"
    return ""
