"""A flight as MCAP for Foxglove: JSON messages with JSON Schemas (Foxglove's own for poses and fixes).

Topics (log time = the flight's time stamps, ns):

- ``/beliefnav/state`` (``beliefnav.State``): one message per row with every scalar column
  (``beta``, ``nis``, ``est_error_m``, ``track_error_m``, ``latency_s``, ``clearance_m``, biases ...)
  -> Plot panel paths such as ``/beliefnav/state.beta``. NaN is written as ``null``.
- ``/pose/<track>`` (``foxglove.PoseInFrame``) for each track the source has (true, estimated,
  reference, gnss, autopilot) in frame ``enu`` (x east, y north, z up: Foxglove's 3-D view is z-up).
- ``/path/<track>`` (``foxglove.PosesInFrame``): the whole track once, at the first time stamp, so the
  3-D view shows the path while the pose moves along it.
- ``/gnss/fix`` (``foxglove.LocationFix``): the fixes of logs and recordings; for a run directory
  ``/map/true``: the true track in WGS-84 through the mission's home -> Map panel.
"""

from __future__ import annotations

import json
import math
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
from mcap.writer import Writer

from gcs_tools.export.flight import SCALARS, TRACKS, Flight

FRAME_ID = "enu"
PATH_MAX_POSES = 2000  # /path/* messages are decimated to at most this many poses
PROFILE = "beliefnav"


def foxglove_schemas() -> dict[str, Any]:
    text = resources.files("gcs_tools.export").joinpath("foxglove_schemas.json").read_text(encoding="utf-8")
    return dict(json.loads(text))


STATE_SCHEMA = {
    "title": "beliefnav.State",
    "description": "Scalar state of a beliefnav flight at one time (units in the names; null: not available)",
    "type": "object",
    "properties": {c: {"type": ["number", "null"]} for c in SCALARS},
}


def _num(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _time(t_s: float) -> dict[str, int]:
    ns = max(0, round(t_s * 1e9))
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def _pose(p_ned_m: np.ndarray) -> dict[str, Any]:
    n, e, d = (float(x) for x in p_ned_m)
    return {"position": {"x": e, "y": n, "z": -d}, "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}


def write_mcap(flight: Flight, path: Path) -> dict[str, int]:
    """Write the MCAP; returns messages per topic."""
    fox = foxglove_schemas()
    counts: dict[str, int] = {}
    t = flight.t_s
    with path.open("wb") as f:
        w = Writer(f)
        w.start(profile=PROFILE, library="beliefnav")

        def channel(topic: str, schema_name: str, schema: dict[str, Any]) -> int:
            sid = w.register_schema(schema_name, "jsonschema", json.dumps(schema).encode())
            counts[topic] = 0
            return w.register_channel(topic, "json", sid)

        def put(cid: int, topic: str, t_s: float, msg: dict[str, Any]) -> None:
            ns = max(0, round(t_s * 1e9))
            w.add_message(cid, ns, json.dumps(msg, allow_nan=False).encode(), ns, sequence=counts[topic])
            counts[topic] += 1

        state = channel("/beliefnav/state", "beliefnav.State", STATE_SCHEMA)
        cols = [flight.columns[c] for c in SCALARS]
        for row in range(len(t)):
            put(state, "/beliefnav/state", t[row],
                {c: _num(v[row]) for c, v in zip(SCALARS, cols, strict=True)})
        for label in TRACKS:
            p = flight.track(label)
            ok = np.isfinite(p).all(axis=1)
            if not ok.any():
                continue
            pose_topic, path_topic = f"/pose/{label}", f"/path/{label}"
            pose = channel(pose_topic, "foxglove.PoseInFrame", fox["foxglove.PoseInFrame"])
            for i in np.flatnonzero(ok):
                put(pose, pose_topic, t[i],
                    {"timestamp": _time(t[i]), "frame_id": FRAME_ID, "pose": _pose(p[i])})
            idx = np.flatnonzero(ok)
            idx = idx[:: max(1, math.ceil(len(idx) / PATH_MAX_POSES))]
            route = channel(path_topic, "foxglove.PosesInFrame", fox["foxglove.PosesInFrame"])
            put(route, path_topic, t[0], {"timestamp": _time(t[0]), "frame_id": FRAME_ID,
                                          "poses": [_pose(p[i]) for i in idx]})
        fix_topic, fixes = _fixes(flight)
        if fixes:
            fix_ch = channel(fix_topic, "foxglove.LocationFix", fox["foxglove.LocationFix"])
            for t_s, lat, lon, alt, h_acc_m in fixes:
                var = h_acc_m**2 if math.isfinite(h_acc_m) else 0.0
                put(fix_ch, fix_topic, t_s, {
                    "timestamp": _time(t_s), "frame_id": fix_topic.rsplit("/", 1)[-1], "latitude": lat,
                    "longitude": lon, "altitude": alt, "position_covariance": [var, 0, 0, 0, var, 0, 0, 0, 0],
                    "position_covariance_type": 1 if math.isfinite(h_acc_m) else 0})
        w.finish()
    return counts


def _fixes(flight: Flight) -> tuple[str, list[tuple[float, float, float, float, float]]]:
    """(topic, rows): the GNSS fixes when the source has them, else the true track in WGS-84."""
    if flight.fixes:
        return "/gnss/fix", [(x.t_s, x.lat_deg, x.lon_deg, x.alt_m, x.h_acc_m) for x in flight.fixes]
    p = flight.track("true")
    ok = np.isfinite(p).all(axis=1)
    if flight.frame is None or not ok.any():
        return "", []
    step = max(1, int(ok.sum() // 5000))  # a map needs no more than a few thousand points
    out = []
    for i in np.flatnonzero(ok)[::step]:
        lat, lon, alt = flight.frame.to_geodetic(p[i])
        out.append((float(flight.t_s[i]), lat, lon, alt, math.nan))
    return "/map/true", out
