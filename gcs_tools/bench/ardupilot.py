"""``beliefnav bench ardupilot``: ArduCopter SITL flown on our GNSS (``sitl --vehicle ardupilot``).

- One profile (test mission, profile 2, open loop, ``--speedup`` 10): ``sim_s_per_wall_s``
  (ArduPilot's boot time over the session's wall time, start-up included), the session's CPU
  seconds, and ``command_delay_ms`` (how late our GPS_INPUT/setpoints reached ArduPilot, in its
  time: > 100 ms p95 means the machine, not the estimators, was measured), with the 1-min load.
- Without ``--quick``: the 10-profile campaign of the default mission, open loop, on 2 workers
  (``campaign_wall_s``, flights valid).
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path
from typing import Any

from companion.estimator.methods import DEFAULT_METHOD
from simvehicle.harness.ardupilot.config import ArduPilotConfig

MISSION, PROFILE, SEED = "test", 2, 0


def measure(args: argparse.Namespace) -> dict[str, Any]:
    from gcs_tools.evaluate.ardupilot import evaluate
    from simvehicle.harness.backend import FlightRequest, backend

    quick = bool(getattr(args, "quick", False))
    cfg = ArduPilotConfig()
    out: dict[str, Any] = {"mission": MISSION, "profile": PROFILE, "seed": SEED, "speedup": cfg.speedup}
    with tempfile.TemporaryDirectory(prefix="beliefnav-bench-ardupilot-") as tmp:
        load0 = os.getloadavg()[0]
        cpu0 = time.process_time()
        r = backend("ardupilot", config=cfg).fly(FlightRequest(MISSION, PROFILE, DEFAULT_METHOD, SEED,
                                                               Path(tmp) / "one"))
        ap = r.summary["ardupilot"]
        out.update({
            "outcome": ap["ended_by"], "sim_s": ap["sim_s"], "wall_s": ap["wall_s"],
            "sim_s_per_wall_s": ap["sim_s_per_wall_s"], "session_cpu_s": ap["session_cpu_s"],
            "process_cpu_s_with_analysis": time.process_time() - cpu0,
            "command_delay_ms": ap["command_delay_ms"], "valid": ap["valid"],
            "load_1min_before": load0, "load_1min_after": os.getloadavg()[0],
        })
        if not quick:
            t0 = time.perf_counter()
            res = evaluate("default", tuple(range(10)), ("naive", "first-order", "second-order"), (0,), 2,
                           Path(tmp) / "campaign", cfg, ("none",))
            flights = res["info"]["flights"]
            out.update({"campaign_wall_s": time.perf_counter() - t0, "campaign_workers": 2,
                        "campaign_flights": len(flights),
                        "campaign_valid": sum(bool(f["valid"]) and not f["error"] for f in flights),
                        "campaign_load_1min_after": os.getloadavg()[0]})
    return out
