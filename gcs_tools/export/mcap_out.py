"""A flight as MCAP for Foxglove: JSON messages with JSON Schemas (Foxglove's own for poses, fixes
and the scene), a metadata record, log times on the flight's wall clock.

Topics (docs/foxglove.md has the list for users):

- ``/beliefnav/state`` (``beliefnav.State``): one message per row with every scalar column
  (``beta``, ``nis``, ``est_error_m``, ``track_error_m``, ``latency_s``, ``clearance_m``, biases ...)
  -> Plot panel paths such as ``/beliefnav/state.beta``. NaN is written as ``null``.
- ``/pose/<track>`` (``foxglove.PoseInFrame``) for each track the source has (true, estimated,
  reference, autopilot) in frame ``enu`` (x east, y north, z up about the home point: Foxglove's
  3-D view is z-up), oriented by the track's attitude (body FLU -> ENU, from the source's body FRD
  -> NED quaternion; identity where the source has none: the reference); ``/pose/gnss`` at each
  fix's arrival.
- ``/path/<track>`` (``foxglove.PosesInFrame``): the whole track once, at the first time stamp.
- ``/gnss/fix`` (``foxglove.LocationFix``): every GNSS fix (3-D or better) at its arrival, with the
  receiver's accuracy as covariance; coloured red when the filter's innovation gate rejected it.
- ``/map/true``, ``/map/estimated`` (``foxglove.LocationFix``): the true and estimated tracks in
  WGS-84 through the flight's home (decimated to a few thousand points) -> Map panel.
- ``/map/buildings`` (``foxglove.SceneUpdate``): the mission's buildings as boxes in ``enu``, once.

Log and publish times are the flight's wall clock (``epoch_unix_s`` + ``t_s``); message
``timestamp`` fields the same (a fix's: its validity time). Without a known wall clock the times
are the flight's own clock since 1970 (the metadata says so).
"""

from __future__ import annotations

import json
import math
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
from mcap.writer import Writer

from companion.domain.rotation import enu_flu
from gcs_tools import palette
from gcs_tools.export.flight import SCALARS, TRACKS, Flight, ned_to_lla

FRAME_ID = "enu"
PATH_MAX_POSES = 2000  # /path/* messages are decimated to at most this many poses
MAP_MAX_POINTS = 5000  # /map/* tracks are decimated to at most this many fixes
PROFILE = "beliefnav"
BUILDING_ALPHA = 0.55


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


def _rgba(hex_colour: str, alpha: float = 1.0) -> dict[str, float]:
    return {"r": int(hex_colour[1:3], 16) / 255, "g": int(hex_colour[3:5], 16) / 255,
            "b": int(hex_colour[5:7], 16) / 255, "a": alpha}


class _Out:
    """The MCAP writer with per-topic channels and counts; times in seconds of the wall clock."""

    def __init__(self, writer: Writer, epoch_s: float) -> None:
        self.w, self.epoch_s = writer, epoch_s
        self.fox = foxglove_schemas()
        self.counts: dict[str, int] = {}
        self.channels: dict[str, int] = {}

    def ns(self, t_s: float) -> int:
        return max(0, round((self.epoch_s + t_s) * 1e9))

    def stamp(self, t_s: float) -> dict[str, int]:
        ns = self.ns(t_s)
        return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}

    def channel(self, topic: str, schema_name: str, schema: dict[str, Any] | None = None) -> None:
        sid = self.w.register_schema(schema_name, "jsonschema",
                                     json.dumps(schema or self.fox[schema_name]).encode())
        self.counts[topic] = 0
        self.channels[topic] = self.w.register_channel(topic, "json", sid)

    def put(self, topic: str, t_s: float, msg: dict[str, Any]) -> None:
        ns = self.ns(t_s)
        self.w.add_message(self.channels[topic], ns, json.dumps(msg, allow_nan=False).encode(), ns,
                           sequence=self.counts[topic])
        self.counts[topic] += 1


def _pose(p_ned_m: np.ndarray, q_enu: np.ndarray | None) -> dict[str, Any]:
    n, e, d = (float(x) for x in p_ned_m)
    w, x, y, z = (1.0, 0.0, 0.0, 0.0) if q_enu is None or not np.isfinite(q_enu).all() else (
        float(v) for v in q_enu)
    return {"position": {"x": e, "y": n, "z": -d}, "orientation": {"x": x, "y": y, "z": z, "w": w}}


def metadata(flight: Flight, exporter_version: str) -> dict[str, str]:
    """The MCAP metadata record ``beliefnav`` (strings only, as MCAP wants)."""
    f = flight.frame
    out = {"source": flight.source, "kind": flight.kind, "name": flight.name,
           "exported_by": f"beliefnav {exporter_version}",
           "clock": flight.clock,
           "epoch_unix_s": "" if flight.epoch_unix_s is None else f"{flight.epoch_unix_s:.6f}",
           "home": "" if f is None else f"{f.home_lat_deg:.8f},{f.home_lon_deg:.8f},{f.home_alt_m:.3f}",
           "home_source": flight.home_source, "frame": "enu: x east, y north, z up about the home (metres)",
           "fixes": str(len(flight.fixes)), "warnings": " | ".join(flight.warnings)}
    out |= {k: str(v) for k, v in flight.info.items()}
    return out


def write_mcap(flight: Flight, path: Path, exporter_version: str = "unknown") -> dict[str, int]:
    """Write the MCAP; returns messages per topic."""
    t = flight.t_s
    with path.open("wb") as f:
        w = Writer(f)
        w.start(profile=PROFILE, library="beliefnav")
        out = _Out(w, flight.epoch_unix_s or 0.0)
        w.add_metadata("beliefnav", metadata(flight, exporter_version))
        out.channel("/beliefnav/state", "beliefnav.State", STATE_SCHEMA)
        cols = [flight.columns[c] for c in SCALARS]
        for row in range(len(t)):
            out.put("/beliefnav/state", t[row], {c: _num(v[row]) for c, v in zip(SCALARS, cols, strict=True)})
        _buildings(out, flight)
        for label in TRACKS:
            if label != "gnss":
                _track(out, flight, label)
        _fixes(out, flight)
        for label in ("true", "estimated"):
            _map_track(out, flight, label)
        w.finish()
    return out.counts


def _track(out: _Out, flight: Flight, label: str) -> None:
    p = flight.track(label)
    ok = np.flatnonzero(np.isfinite(p).all(axis=1))
    if not ok.size:
        return
    q = flight.attitude.get(label)
    q_enu = enu_flu(np.nan_to_num(q, nan=1.0)) if q is not None else None
    if q_enu is not None and q is not None:
        q_enu[~np.isfinite(q).all(axis=1)] = np.nan  # no attitude at that row: identity
    t = flight.t_s
    pose_topic, path_topic = f"/pose/{label}", f"/path/{label}"
    out.channel(pose_topic, "foxglove.PoseInFrame")
    for i in ok:
        out.put(pose_topic, t[i], {"timestamp": out.stamp(t[i]), "frame_id": FRAME_ID,
                                   "pose": _pose(p[i], None if q_enu is None else q_enu[i])})
    idx = ok[:: max(1, math.ceil(len(ok) / PATH_MAX_POSES))]
    out.channel(path_topic, "foxglove.PosesInFrame")
    out.put(path_topic, t[0], {"timestamp": out.stamp(t[0]), "frame_id": FRAME_ID,
                               "poses": [_pose(p[i], None if q_enu is None else q_enu[i]) for i in idx]})


def _fixes(out: _Out, flight: Flight) -> None:
    """/gnss/fix (every fix, geodetic), /pose/gnss and /path/gnss (the same in ``enu``)."""
    if not flight.fixes:
        return
    order = sorted(range(len(flight.fixes)), key=lambda i: flight.fixes[i].t_s)
    fixes = [flight.fixes[i] for i in order]
    ned = flight.fixes_ned_m()[order]
    colour_ok = _rgba(palette.quantity("gnss"))
    colour_bad = _rgba(palette.quantity("rejected"))
    out.channel("/gnss/fix", "foxglove.LocationFix")
    for x in fixes:
        var = x.h_acc_m**2 if math.isfinite(x.h_acc_m) else 0.0
        t_stamp = x.t_validity_s if math.isfinite(x.t_validity_s) else x.t_s
        out.put("/gnss/fix", x.t_s, {
            "timestamp": out.stamp(t_stamp), "frame_id": "gnss", "latitude": x.lat_deg,
            "longitude": x.lon_deg, "altitude": x.alt_m,
            "position_covariance": [var, 0, 0, 0, var, 0, 0, 0, 0],
            "position_covariance_type": 1 if math.isfinite(x.h_acc_m) else 0,
            "color": colour_bad if x.rejected == 1 else colour_ok})
    if not np.isfinite(ned).all():
        return  # no frame: the fixes go to the map only
    out.channel("/pose/gnss", "foxglove.PoseInFrame")
    for x, p in zip(fixes, ned, strict=True):
        out.put("/pose/gnss", x.t_s, {"timestamp": out.stamp(x.t_s), "frame_id": FRAME_ID,
                                      "pose": _pose(p, None)})
    idx = range(0, len(fixes), max(1, math.ceil(len(fixes) / PATH_MAX_POSES)))
    out.channel("/path/gnss", "foxglove.PosesInFrame")
    t0 = float(flight.t_s[0]) if len(flight.t_s) else fixes[0].t_s
    out.put("/path/gnss", t0, {"timestamp": out.stamp(t0), "frame_id": FRAME_ID,
                               "poses": [_pose(ned[i], None) for i in idx]})


def _map_track(out: _Out, flight: Flight, label: str) -> None:
    """``/map/<label>``: the track in WGS-84 for the Map panel (needs the flight's frame)."""
    p = flight.track(label)
    ok = np.flatnonzero(np.isfinite(p).all(axis=1))
    if flight.frame is None or not ok.size:
        return
    ok = ok[:: max(1, math.ceil(len(ok) / MAP_MAX_POINTS))]
    lla = ned_to_lla(flight.frame, p[ok])
    topic = f"/map/{label}"
    colour = _rgba(palette.quantity(label))
    out.channel(topic, "foxglove.LocationFix")
    for i, (lat, lon, alt) in zip(ok, lla, strict=True):
        t_s = float(flight.t_s[i])
        out.put(topic, t_s, {"timestamp": out.stamp(t_s), "frame_id": label, "latitude": float(lat),
                             "longitude": float(lon), "altitude": float(alt),
                             "position_covariance": [0.0] * 9, "position_covariance_type": 0,
                             "color": colour})


def _buildings(out: _Out, flight: Flight) -> None:
    """``/map/buildings``: one SceneUpdate at the first time with a box per building (ground at the
    home's height, roof at the building's height; a recording's buildings, whose height is not
    sent, are drawn 40 m tall)."""
    if not flight.buildings or not len(flight.t_s):
        return
    t0 = float(flight.t_s[0])
    colour = _rgba(palette.quantity("building"), BUILDING_ALPHA)
    cubes = []
    for n0, e0, n1, e1, h in flight.buildings:
        h = h if math.isfinite(h) else 40.0
        cubes.append({"pose": {"position": {"x": (e0 + e1) / 2, "y": (n0 + n1) / 2, "z": h / 2},
                               "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}},
                      "size": {"x": e1 - e0, "y": n1 - n0, "z": h}, "color": colour})
    entity = {"timestamp": out.stamp(t0), "frame_id": FRAME_ID, "id": "buildings",
              "lifetime": {"sec": 0, "nsec": 0}, "frame_locked": True, "metadata": [],
              "arrows": [], "cubes": cubes, "spheres": [], "cylinders": [], "lines": [], "triangles": [],
              "texts": [], "models": []}
    out.channel("/map/buildings", "foxglove.SceneUpdate")
    out.put("/map/buildings", t0, {"deletions": [], "entities": [entity]})
