"""Two runs on one telemetry network never publish under one vehicle id silently (real Zenoh)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

from companion.telemetry.pubsub import TelemetryConfig
from simvehicle.harness.sitl.vehicle_id import claim_vehicle_id


def test_a_held_id_is_not_taken_again_and_is_free_once_released():
    config = TelemetryConfig.from_env(dict(os.environ))
    first = claim_vehicle_id(config, "uav7")
    assert first is not None and (first.vehicle_id, first.note) == ("uav7", "")
    try:
        second = claim_vehicle_id(config, "uav7")
        assert second is not None and second.vehicle_id == "uav8" and "'uav7' is in use" in second.note
        second.close()
    finally:
        first.close()
    again = claim_vehicle_id(config, "uav7")
    assert again is not None and again.vehicle_id == "uav7"
    again.close()
    assert claim_vehicle_id(TelemetryConfig(enabled=False), "uav7") is None


def test_sitl_moves_to_a_free_id_and_says_so(tmp_path):
    config = TelemetryConfig.from_env(dict(os.environ))
    held = claim_vehicle_id(config, "uav1")
    assert held is not None and held.vehicle_id == "uav1"
    try:
        done = subprocess.run([sys.executable, "-m", "gcs_tools", "sitl", "--no-progress", "--no-figures",
                               "--mission", "test", "--max-duration-s", "1", "--out", str(tmp_path)],
                              capture_output=True, text=True, timeout=60)
    finally:
        held.close()
    assert "beliefnav: note: vehicle id 'uav1' is in use" in done.stderr and "'uav2'" in done.stderr
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["sitl"]["vehicle_id"] == "uav2"
    assert done.returncode == 1  # 1 s is not enough to reach the goal: a time-out, said in one line
    assert done.stderr.strip().splitlines()[-1].startswith("beliefnav: error: the goal was not reached")
