"""Files of a flight: ``summary.json`` (strict JSON), ``timeseries.csv``, ``gnss.csv`` (every fix the
filter received, when the backend knows them), ``map.png``, ``belief.png``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from companion.errors import UserError
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
# Written when the series has them: the true attitude (body FRD -> NED quaternion w, x, y, z: fly and
# sitl), the autopilot's own estimate (``sitl --vehicle ardupilot``).
OPTIONAL_COLUMNS = {
    "q_true_ned_frd": ["q_true_w", "q_true_x", "q_true_y", "q_true_z"],
    "p_autopilot_ned_m": ["p_autopilot_n_m", "p_autopilot_e_m", "p_autopilot_d_m"],
    "autopilot_error_m": ["autopilot_error_m"],
}


# gnss.csv: one row per fix received (FlightResult.fixes)
GNSS_COLUMNS = {
    "t_s": ["t_s"],  # arrival at the filter [s]
    "t_validity_s": ["t_validity_s"],  # when the position was true [s]
    "p_ned_m": ["p_n_m", "p_e_m", "p_d_m"],
    "h_acc_m": ["h_acc_m"],  # the accuracy the receiver reported (NaN: none)
    "rejected": ["rejected"],  # 1: refused by the filter's innovation gate (empty: not known)
}
GNSS_FILE = "gnss.csv"


def write_table(path: Path, table: dict[str, np.ndarray], columns: dict[str, list[str]]) -> None:
    """The named arrays as CSV: one header row, 6 significant digits, NaN written as ``nan``."""
    n = len(table["t_s"])
    data = np.column_stack([np.asarray(table[k], dtype=float).reshape(n, -1) for k in columns])
    header = ",".join(c for cols in columns.values() for c in cols)
    np.savetxt(path, data, delimiter=",", header=header, comments="", fmt="%.6g")


def strict_json(value: Any) -> Any:
    """NaN/inf -> None, numpy scalars -> Python, recursively (so the file is strict JSON)."""
    return plain_json(value, nan_to_none=True)


def write_outputs(result: FlightResult, world: Any, out_dir: str | Path, figures: bool = True) -> list[Path]:
    """Write the files into ``out_dir`` (created); returns their paths. ``figures=False``: no map.png
    or belief.png (a previous run's in ``out_dir`` are removed: they would not show this flight)."""
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"{out}: cannot create the output directory: {exc.strerror or exc}") from None
    s = result.summary
    figure_paths = [out / "map.png", out / "belief.png"]
    paths = [out / "summary.json", out / "timeseries.csv", *(figure_paths if figures else [])]
    paths[0].write_text(json.dumps(strict_json(s), indent=2, allow_nan=False) + "\n", encoding="utf-8")
    columns = COLUMNS | {k: v for k, v in OPTIONAL_COLUMNS.items() if k in result.series}
    write_table(paths[1], result.series, columns)
    fixes = result.fixes
    if fixes:
        paths.insert(2, out / GNSS_FILE)
        write_table(paths[2], fixes, GNSS_COLUMNS)
    if not figures:
        for path in figure_paths:
            path.unlink(missing_ok=True)
        return paths
    from gcs_tools import figures as draw  # matplotlib (about a second of CPU to import) only when drawing

    title = f"{s['mission']} profile {s['profile']}, {s['method']}, seed {s['seed']}"
    tracks = {"true": result.series["p_true_ned_m"], "estimated": result.series["p_est_ned_m"]}
    if "p_autopilot_ned_m" in result.series:
        tracks["autopilot"] = result.series["p_autopilot_ned_m"]
    draw.map_figure(out / "map.png", world, result.route.waypoints_ned_m, tracks, title,
               fixes_ned_m=fixes.get("p_ned_m"), error_m=result.series["est_error_m"],
               rejected=np.nan_to_num(fixes["rejected"]) > 0 if fixes else None)
    draw.belief_figure(out / "belief.png", result.series, title, fixes)
    return paths
