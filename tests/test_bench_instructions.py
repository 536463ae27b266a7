"""``gcs_tools.bench.instructions``: the stream it counts is the benchmark's, and runs (here without
valgrind, whose count the docs quote: docs/benchmarks.md, "Instruction counts")."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from gcs_tools.bench import estimator as be
from gcs_tools.bench.instructions import WORKLOAD


@pytest.mark.parametrize("which", ["estimator", "tight"])
def test_the_workload_runs_one_stream(which):
    """The measured process's code, run as it is: a warm-up stream, then the counted one inside
    functools.reduce, ending at a position; the estimator's is the benchmark's own stream's."""
    proc = subprocess.run([sys.executable, "-c", WORKLOAD, which, "1.0"], capture_output=True, text=True,
                          timeout=300, check=True)
    final = [line for line in proc.stdout.splitlines() if line.startswith("final")]
    assert len(final) == 1
    position = json.loads(final[0][6:])  # a list of three floats
    assert len(position) == 3 and all(isinstance(v, float) for v in position)
    if which == "estimator":
        est = be.streaming_wall_s(be.flight(1.0, None))[2].estimate()
        assert est is not None and position == est.p_ned_m.tolist()
