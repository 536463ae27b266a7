"""Files of a flight: ``summary.json`` (strict JSON), ``timeseries.csv``, ``map.png``, ``belief.png``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from companion.errors import UserError
from gcs_tools.figures import belief_figure, map_figure
from gcs_tools.jsonvalues import plain_json
from simvehicle.harness.backend import FlightResult

# CSV column groups: series key -> column names
COLUMNS = {
    "t_s": ["t_s"],
    "p_true_ned_m": ["p_true_n_m", "p_true_e_m", "p_true_d_m"],
    "p_est_ned_m": ["p_est_n_m", "p_est_e_m", "p_est_d_m"],
    "p_ref_ned_m": ["p_ref_n_m", "p_ref_e_m", "p_ref_d_m"],
    "b_true_ned_m": ["b_true_n_m", "b_true_e_m", "b_true_d_m"],
    "b_est_ned_m": ["b_est_n_m", "b_est_e_m", "b_est_d_m"],
    "beta": ["beta"],
    "nis": ["nis"],
    "latency_s": ["latency_s"],
    "clearance_m": ["clearance_m"],
    "est_error_m": ["est_error_m"],
    "track_error_m": ["track_error_m"],
}
# Written when the series has them: the autopilot's own estimate (``sitl --vehicle ardupilot``).
OPTIONAL_COLUMNS = {
    "p_autopilot_ned_m": ["p_autopilot_n_m", "p_autopilot_e_m", "p_autopilot_d_m"],
    "autopilot_error_m": ["autopilot_error_m"],
}


def strict_json(value: Any) -> Any:
    """NaN/inf -> None, numpy scalars -> Python, recursively (so the file is strict JSON)."""
    return plain_json(value, nan_to_none=True)


def write_outputs(result: FlightResult, world: Any, out_dir: str | Path) -> list[Path]:
    """Write the four files into ``out_dir`` (created); returns their paths."""
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"{out}: cannot create the output directory: {exc.strerror or exc}") from None
    s = result.summary
    paths = [out / "summary.json", out / "timeseries.csv", out / "map.png", out / "belief.png"]
    paths[0].write_text(json.dumps(strict_json(s), indent=2, allow_nan=False) + "\n", encoding="utf-8")
    columns = COLUMNS | {k: v for k, v in OPTIONAL_COLUMNS.items() if k in result.series}
    table = np.column_stack([np.asarray(result.series[k], dtype=float).reshape(len(result.series["t_s"]), -1)
                             for k in columns])
    header = ",".join(c for cols in columns.values() for c in cols)
    np.savetxt(paths[1], table, delimiter=",", header=header, comments="", fmt="%.6g")
    title = f"{s['mission']} profile {s['profile']}, {s['method']}, seed {s['seed']}"
    tracks = {"true": result.series["p_true_ned_m"], "estimated": result.series["p_est_ned_m"]}
    if "p_autopilot_ned_m" in result.series:
        tracks["autopilot"] = result.series["p_autopilot_ned_m"]
    map_figure(paths[2], world, result.route.waypoints_ned_m, tracks, title)
    belief_figure(paths[3], result.series, title)
    return paths
