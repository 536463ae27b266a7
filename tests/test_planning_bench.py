"""``beliefnav bench plan --json`` runs and prints the planner's figures (no timing asserted)."""

import json
import subprocess
import sys

import pytest


@pytest.mark.timeout(60)
def test_bench_plan_prints_json():
    out = subprocess.run([sys.executable, "-m", "gcs_tools", "bench", "plan", "--quick", "--json"],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    res = json.loads(out.stdout)
    assert len(res["route_length_m"]) == 10 and res["plan_wall_s_max"] >= res["plan_wall_s_median"] > 0
