"""Replay speed on the real log: ``measure_replay(path, method)`` -> dict (simulated s per wall s).

Called by the estimator benchmark (``beliefnav bench estimator``) for ``replay_realtime_factor``.
Where the time goes is measured, not guessed: a read+decode-only pass over the same file, and
the full replay with the time spent inside the navigator accumulated separately.
"""

from __future__ import annotations

import contextlib
import time
from pathlib import Path
from typing import Any

from companion.mavlink import codec as mc
from companion.mavlink.tlog import read_tlog
from gcs_tools.replay import core

REAL_LOG = Path(__file__).resolve().parents[2] / "tests" / "data" / "quad106.tlog"


def measure_read(path: Path) -> float:
    """Wall seconds to read and decode every estimator input of ``path`` (no estimator)."""
    t0 = time.perf_counter()
    for _, view in read_tlog(path, (*core.IMU_TYPES, *core.ATTITUDE_TYPES, core.GNSS_TYPE)):
        with contextlib.suppress(mc.CodecError):
            mc.decode_sample(view)
    return time.perf_counter() - t0


def measure_replay(path: str | Path = REAL_LOG, method: str = "second-order") -> dict[str, Any]:
    path = Path(path)
    read_s = measure_read(path)
    cpu0 = time.process_time()
    result = core.replay(path, method)
    cpu_s = time.process_time() - cpu0
    s = result.summary
    return {
        "replay_realtime_factor": s["realtime_factor"],
        # per CPU second of this process (the machine is shared: wall time includes waiting)
        "replay_realtime_factor_cpu": s["duration_s"] / cpu_s,
        "replay_log_duration_s": s["duration_s"],
        "replay_wall_s": s["wall_s"],
        "replay_estimator_s": s["timing_s"]["estimator"],
        "replay_read_decode_only_s": read_s,
        "replay_read_realtime_factor": s["duration_s"] / read_s,
        "replay_method": method,
    }
