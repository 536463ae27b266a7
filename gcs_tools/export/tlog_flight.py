"""A tlog as a :class:`~gcs_tools.export.flight.Flight`: what was on the wire, on the log's own clock.

Every message is placed by its own boot-time stamp (ODOMETRY and GPS_RAW_INT ``time_usec``,
``time_boot_ms`` of the others), so an estimate sent once is one row however many messages share
a tlog stamp; SIM_STATE, which carries no time, at the time of the HIGHRES_IMU before it (as
``beliefnav replay`` does; without one by its tlog stamp less the log's offset between its stamps
and boot time: SYSTEM_TIME's, else the median over boot-stamped messages). The wall
clock is SYSTEM_TIME's ``time_unix_usec`` paired with its ``time_boot_ms``.

The local frame: ``--home`` if given (checked), else the log's GPS_GLOBAL_ORIGIN, else its
HOME_POSITION, else the mission of the run directory the tlog sits in, else the first 3-D fix.
ODOMETRY and position setpoints are local NED about the origin their sender used (the log's
GPS_GLOBAL_ORIGIN or the run's mission when known) and are moved into the export frame.
"""

from __future__ import annotations

import math
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from companion.domain.geodesy import LocalNedFrame
from companion.errors import UserError
from gcs_tools.export.flight import (
    AXES,
    Fix,
    Flight,
    choose_home,
    interp,
    mission_buildings,
    nearest,
    read_summary,
    reframe,
    run_info,
    run_mission,
    set_track,
)

KINDS = ["ODOMETRY", "SIM_STATE", "GPS_RAW_INT", "GLOBAL_POSITION_INT", "SET_POSITION_TARGET_LOCAL_NED",
         "NAMED_VALUE_FLOAT", "DEBUG_VECT", "ATTITUDE_QUATERNION", "SYSTEM_TIME", "GPS_GLOBAL_ORIGIN",
         "HOME_POSITION", "HIGHRES_IMU"]
MAX_ATTITUDE_GAP_S = 0.2  # an attitude farther in time from a row than this is not used for it


def _plausible(lat_deg: float, lon_deg: float) -> bool:
    return abs(lat_deg) <= 90 and abs(lon_deg) <= 180 and not (lat_deg == 0 and lon_deg == 0)


def tlog_epoch(path: Path) -> float | None:
    """UNIX time of boot time 0 from the first SYSTEM_TIME with a UNIX time (None: none)."""
    from companion.mavlink.tlog import read_tlog

    for _, m in read_tlog(path, ["SYSTEM_TIME"]):
        if m.time_unix_usec > 0:
            return m.time_unix_usec * 1e-6 - m.time_boot_ms * 1e-3
    return None


def _repeated(m: Any, seen: set[tuple[int, int, int]]) -> bool:
    """A GPS_RAW_INT already seen: autopilots stream it faster than their receiver updates, repeating
    the same fix (its ``time_usec`` and position)."""
    key = (int(m.time_usec), int(m.lat), int(m.lon))
    if key in seen:
        return True
    seen.add(key)
    return False


def read_fixes(path: Path, epoch_unix_s: float | None) -> list[Fix]:
    """The 3-D (or better) GPS_RAW_INT fixes of a tlog, each once (its first arrival), arrival on its
    boot clock (tlog stamp less the stamp offset) when known, else their validity time."""
    from companion.mavlink import codec
    from companion.mavlink.tlog import read_tlog

    fixes = []
    seen: set[tuple[int, int, int]] = set()
    for stamp_us, m in read_tlog(path, ["GPS_RAW_INT"]):
        if _repeated(m, seen):
            continue
        try:
            fix = codec.decode_gnss(m)
        except codec.CodecError:
            continue
        if fix.fix_type >= 3:
            t_val = fix.t_validity_us * 1e-6
            t_arr = stamp_us * 1e-6 - epoch_unix_s if epoch_unix_s is not None else t_val
            fixes.append(Fix(t_arr, t_val, fix.lat_deg, fix.lon_deg, fix.alt_m, fix.h_acc_m))
    return fixes


def from_tlog(path: Path, home: LocalNedFrame | None = None) -> Flight:
    from companion.mavlink import codec
    from companion.mavlink.tlog import read_tlog

    rows: dict[str, list[tuple[float, Any]]] = defaultdict(list)  # boot-stamped: (t_s, value)
    sim_state: list[tuple[float, tuple[float, ...]]] = []  # (last IMU time [s] or NaN, lat lon alt q1..q4)
    sim_state_stamps: list[int] = []  # their tlog stamps (when no IMU came before)
    last_imu_s = float("nan")
    gnss: list[tuple[int, Any]] = []  # (tlog stamp, GnssFix), each fix once (its first arrival)
    gnss_seen: set[tuple[int, int, int]] = set()
    origins: dict[str, tuple[float, float, float]] = {}
    stamp_offsets: list[float] = []  # tlog stamp - boot time [s] of SYSTEM_TIME
    other_offsets: list[float] = []  # ... of other boot-stamped messages (a fallback)
    epoch: float | None = None
    try:
        for stamp_us, m in read_tlog(path, KINDS):
            kind = m.get_type()
            try:
                if kind == "ODOMETRY":
                    e = codec.decode_odometry(m)
                    rows["est"].append((e.t_us * 1e-6, tuple(e.p_ned_m)))
                    other_offsets.append((stamp_us - e.t_us) * 1e-6)
                elif kind == "HIGHRES_IMU":
                    last_imu_s = m.time_usec * 1e-6
                elif kind == "SIM_STATE":  # no stamp of its own: at the last IMU time, as replay does
                    lat, lon = ((m.lat_int * 1e-7, m.lon_int * 1e-7) if m.lat_int or m.lon_int  # degE7: 1 cm
                                else (float(m.lat), float(m.lon)))  # float32 degrees: ~0.5 m
                    sim_state.append((last_imu_s, (lat, lon, float(m.alt),
                                                   float(m.q1), float(m.q2), float(m.q3), float(m.q4))))
                    sim_state_stamps.append(stamp_us)
                elif kind == "GPS_RAW_INT" and not _repeated(m, gnss_seen):
                    fix = codec.decode_gnss(m)
                    if fix.fix_type >= 3:
                        gnss.append((stamp_us, fix))
                elif kind == "GLOBAL_POSITION_INT":
                    if _plausible(m.lat * 1e-7, m.lon * 1e-7):
                        rows["ap"].append((m.time_boot_ms * 1e-3, (m.lat * 1e-7, m.lon * 1e-7, m.alt * 1e-3)))
                elif kind == "SET_POSITION_TARGET_LOCAL_NED":
                    sp = codec.decode_setpoint(m)
                    rows["ref"].append((sp.t_us * 1e-6, tuple(sp.p_ned_m)))
                elif kind == "NAMED_VALUE_FLOAT":
                    v = codec.decode_named_value(m)
                    if v.name in (codec.BELIEF_NAME, codec.NIS_NAME):
                        rows[v.name].append((v.t_us * 1e-6, (v.value,)))
                elif kind == "DEBUG_VECT":
                    t_us, b = codec.decode_bias(m)
                    rows["bias"].append((t_us * 1e-6, tuple(b)))
                elif kind == "ATTITUDE_QUATERNION":
                    a = codec.decode_attitude(m)
                    rows["att"].append((a.t_us * 1e-6, tuple(a.q_ned_frd)))
                    other_offsets.append((stamp_us - a.t_us) * 1e-6)
                elif kind == "SYSTEM_TIME":
                    stamp_offsets.append(stamp_us * 1e-6 - m.time_boot_ms * 1e-3)
                    if epoch is None and m.time_unix_usec > 0:
                        epoch = m.time_unix_usec * 1e-6 - m.time_boot_ms * 1e-3
                elif kind in ("GPS_GLOBAL_ORIGIN", "HOME_POSITION"):
                    lla = (m.latitude * 1e-7, m.longitude * 1e-7, m.altitude * 1e-3)
                    if kind not in origins and _plausible(lla[0], lla[1]):
                        origins[kind] = lla
            except codec.CodecError:
                continue  # a damaged message is skipped here; `beliefnav replay` counts them by reason
    except FileNotFoundError:
        raise UserError(f"{path}: no such file") from None
    offsets = stamp_offsets or other_offsets
    stamp_offset_s = float(np.median(offsets)) if offsets else None
    fixes = [Fix(stamp * 1e-6 - stamp_offset_s if stamp_offset_s is not None else f.t_validity_us * 1e-6,
                 f.t_validity_us * 1e-6, f.lat_deg, f.lon_deg, f.alt_m, f.h_acc_m) for stamp, f in gnss]
    if not (rows["est"] or rows["ap"] or fixes or sim_state):
        raise UserError(f"{path}: no position, estimate or GNSS message in this tlog")

    # the frame: the log's own origin, else its run directory's mission, else the first fix
    summary = read_summary(path.parent) if path.parent.joinpath("timeseries.csv").is_file() else {}
    mission = run_mission(summary) if summary else None
    warnings: list[str] = []
    own, own_source = None, ""
    for kind in ("GPS_GLOBAL_ORIGIN", "HOME_POSITION"):
        if kind in origins:
            own, own_source = LocalNedFrame(*origins[kind]), f"the log's {kind}"
            break
    if own is None and mission is not None:
        own, own_source = mission.frame, f"the run's mission {mission.name!r}"
    if own is None and fixes:
        f0 = fixes[0]
        own, own_source = LocalNedFrame(f0.lat_deg, f0.lon_deg, f0.alt_m), "the first 3-D fix"
        if rows["est"] or rows["ref"]:
            warnings.append("the log has no GPS_GLOBAL_ORIGIN or HOME_POSITION and no run directory: "
                            "the frame is about the first fix, and ODOMETRY is assumed to be about it too")
    near = (fixes[0].lat_deg, fixes[0].lon_deg, fixes[0].alt_m) if fixes else own_lla(own)
    frame, home_source = choose_home(home, own, own_source, near, warnings)
    local_src = (LocalNedFrame(*origins["GPS_GLOBAL_ORIGIN"]) if "GPS_GLOBAL_ORIGIN" in origins
                 else mission.frame if mission is not None else frame)

    def series(key: str) -> tuple[np.ndarray, np.ndarray]:
        """Unique times (the first message of each time), sorted, and the values."""
        data = rows.get(key) or []
        if not data:
            return np.zeros(0), np.zeros((0, 3))
        t = np.array([r[0] for r in data])
        t_u, first = np.unique(t, return_index=True)
        return t_u, np.array([data[i][1] for i in first], dtype=float)

    t_est, p_est = series("est")
    t_ref, p_ref = series("ref")
    t_ap, lla_ap = series("ap")
    t_true = np.zeros(0)
    lla_true = q_true = np.zeros((0, 3))
    if sim_state and (stamp_offset_s is not None or not math.isnan(sim_state[0][0])):
        t_imu = np.array([s[0] for s in sim_state])
        t_stamp = np.array(sim_state_stamps) * 1e-6 - (stamp_offset_s or 0.0)
        t_all = np.where(np.isnan(t_imu), t_stamp, t_imu)
        t_true, first = np.unique(t_all, return_index=True)
        vals = np.array([sim_state[i][1] for i in first])
        lla_true, q_true = vals[:, :3], vals[:, 3:]
    if frame is not None and local_src is not None:
        p_est = reframe(p_est, local_src, frame) if len(p_est) else p_est
        p_ref = reframe(p_ref, local_src, frame) if len(p_ref) else p_ref
    base = next((t for t in (t_est, t_ap, t_true) if len(t)), None)
    if base is None:
        base = np.unique([f.t_s for f in fixes])
    columns: dict[str, np.ndarray] = {}
    if len(t_est):
        set_track(columns, "estimated", interp(base, t_est, p_est))
    if len(t_ref):
        set_track(columns, "reference", interp(base, t_ref, p_ref))
    for label, t_geo, geo in (("true", t_true, lla_true), ("autopilot", t_ap, lla_ap)):
        if len(t_geo) and frame is not None:
            ned = np.asarray(frame.to_ned_m(geo[:, 0], geo[:, 1], geo[:, 2]), dtype=float).T.reshape(-1, 3)
            set_track(columns, label, interp(base, t_geo, ned))
    for key, column in ((codec.BELIEF_NAME, "beta"), (codec.NIS_NAME, "nis")):
        t_val, values = series(key)
        if len(t_val):
            columns[column] = interp(base, t_val, values)[:, 0]
    t_b, bias = series("bias")
    if len(t_b):
        for i, axis in enumerate(AXES):
            columns[f"b_est_{axis}_m"] = interp(base, t_b, bias)[:, i]
    if len(t_est) and len(t_true):
        columns["est_error_m"] = np.linalg.norm(
            np.column_stack([columns[f"p_est_{a}_m"] for a in AXES])
            - np.column_stack([columns[f"p_true_{a}_m"] for a in AXES]), axis=1)
    attitude: dict[str, np.ndarray] = {}
    t_att, q_att = series("att")
    if len(t_att):  # the attitude the estimator was given (an autopilot's own, in a real log)
        q = nearest(base, t_att, q_att, MAX_ATTITUDE_GAP_S)
        attitude["estimated"] = attitude["autopilot"] = q
    if len(t_true):
        attitude["true"] = nearest(base, t_true, q_true, MAX_ATTITUDE_GAP_S)
        attitude.setdefault("estimated", attitude["true"])
    if epoch is None and stamp_offset_s is not None and not stamp_offsets:
        epoch = stamp_offset_s  # tlog stamps are the recorder's UNIX time: the same offset
        clock = "the log's boot time; the wall clock of its tlog stamps (no SYSTEM_TIME)"
    elif epoch is not None:
        clock = "the log's boot time; the wall clock of its SYSTEM_TIME"
    else:
        clock = "the log's boot time (no wall clock found)"
    flight = Flight(path.stem, base, columns, fixes=fixes, frame=frame, source=str(path), kind="tlog",
                    home_source=home_source, epoch_unix_s=epoch, clock=clock, attitude=attitude,
                    buildings=mission_buildings(mission) if mission is not None else [],
                    info=run_info(summary), warnings=warnings)
    flight.set_fix_columns()
    return flight


def own_lla(frame: LocalNedFrame | None) -> tuple[float, float, float] | None:
    return None if frame is None else (frame.home_lat_deg, frame.home_lon_deg, frame.home_alt_m)

