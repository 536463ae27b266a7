"""``beliefnav evaluate --vehicle ardupilot``: EKF3 beside the companion's methods over profiles and seeds.

The campaign itself is ``gcs_tools.evaluate.autopilot`` (one ArduCopter SITL flight per profile,
seed and loop; statistics, report); this module names ArduPilot's loops:

- ``none``: open loop, EKF3 fed our raw fixes WITH a Doppler velocity (truth + 0.1 m/s noise);
- ``none-posonly``: open loop, EKF3 fed positions only; only its EKF3 row is kept
  (``ardupilot-ekf3-posonly``: the companion rows would repeat those of ``none``);
- ``gps-input`` / ``vision``: closed loop, ArduPilot flies on the second-order companion PROCESS
  (its cleaned fixes as GPS1, or its position as ExternalNav); row ``companion-live`` = what it sent.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from gcs_tools.evaluate.autopilot import CLOSED_LOOP_METHOD, Loop, VehicleCampaign, open_loops
from gcs_tools.evaluate.autopilot import evaluate as evaluate_campaign
from simvehicle.harness.ardupilot.config import ArduPilotConfig

POSONLY_ROW = "ardupilot-ekf3-posonly"  # EKF3 without the GNSS velocity
CAMPAIGN = VehicleCampaign(
    vehicle="ardupilot", title="ArduPilot", ekf="EKF3", autopilot_row="ardupilot-ekf3",
    loops=(*open_loops("EKF3", POSONLY_ROW),
           Loop("gps-input", f"EKF3 on {CLOSED_LOOP_METHOD}'s cleaned fixes (GPS_INPUT)", "gps-input"),
           Loop("vision", f"EKF3 on {CLOSED_LOOP_METHOD}'s position as ExternalNav", "vision")),
    figure_title="ArduCopter SITL on our urban GNSS: EKF3 vs the companion (open loop; whiskers p5-p95)",
    config_class=ArduPilotConfig, speed_field="speedup",
    rescorer="simvehicle.harness.ardupilot.rescore:rescore_ardupilot")
LOOPS = CAMPAIGN.loop_names


def evaluate(mission: str, profiles: Sequence[int], methods: Sequence[str], seeds: Sequence[int],
             workers: int, out: Path, config: ArduPilotConfig | None = None,
             feeds: Sequence[str] = LOOPS, resume: bool = False) -> dict[str, Any]:
    return evaluate_campaign(CAMPAIGN, mission, profiles, methods, seeds, workers, out,
                             config or ArduPilotConfig(), feeds, resume=resume)
