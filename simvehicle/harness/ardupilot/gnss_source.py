"""GPS_INPUT from our urban GNSS source (``simvehicle.harness.foreign.gnss_source``) for ArduPilot.

Timing on the wire: ``time_week_ms`` carries the fix's validity time (ArduPilot boot ms on a
fixed GPS week), as a receiver stamps its measurement epoch; ArduPilot's MAVLink GPS driver
(AP_GPS_MAV) uses it only through its jitter correction against the arrival time, and EKF3 then
assumes the fix is ``GPS1_DELAY_MS`` old. The modelled latency varies (0.1 s in open sky, up to
1.2 s in canyons); a constant delay is all EKF3 can assume. The companion fuses each fix at its
validity time (Algorithm 1).
"""

from __future__ import annotations

import math

from companion.gnss.timescale import week_tow
from simvehicle.harness.ardupilot.config import GPS1_ID, GPS_INPUT_IGNORE_VELOCITY, GPS_WEEK
from simvehicle.harness.foreign.gnss_source import SentFix


def gps_input_fields(sf: SentFix, gps_id: int = GPS1_ID,
                     velocity_sigma_m_s: float = 0.0) -> dict[str, float | int]:
    """GPS_INPUT fields (MAVLink common) for a fix: validity time as GPS time, to receiver ``gps_id``.

    Velocity (and ``speed_accuracy``: the fix's own, else ``velocity_sigma_m_s``) when the fix carries
    one; otherwise flagged as ignored. Time: the fix's GPS time (``t_gps_s``, a raw receiver's) as week
    and time of week, else the validity time's boot ms on a fixed week.

    ``horiz_accuracy``/``vert_accuracy`` carry the model's reported accuracy (the white-noise std,
    not the bias: what a receiver that cannot see its multipath reports; EKF3 floors it at
    EK3_POSNE_M_NSE). HDOP/VDOP are 1.0 (good geometry): EKF3 uses the accuracies when present.
    """
    fix, v = sf.fix, sf.v_ned_m_s
    acc = fix.h_acc_m if math.isfinite(fix.h_acc_m) else 1.0
    vacc = fix.v_acc_m if math.isfinite(fix.v_acc_m) else 1.5
    speed_acc = sf.speed_accuracy_m_s if math.isfinite(sf.speed_accuracy_m_s) else velocity_sigma_m_s
    if sf.t_gps_s is None:
        week, t_ms = GPS_WEEK, fix.t_validity_us // 1000
    else:  # a raw receiver's fix: the GPS time of its measurement (ArduPilot sets its clock from it)
        week, tow_s = week_tow(sf.t_gps_s)
        t_ms = round(tow_s * 1000.0)
    return {
        "time_usec": int(fix.t_validity_us),
        "gps_id": gps_id,
        "ignore_flags": GPS_INPUT_IGNORE_VELOCITY if v is None else 0,
        "time_week_ms": int(t_ms),
        "time_week": int(week),
        "fix_type": int(fix.fix_type),
        "lat": round(fix.lat_deg * 1e7),
        "lon": round(fix.lon_deg * 1e7),
        "alt": float(fix.alt_m),
        "hdop": 1.0,
        "vdop": 1.0,
        "vn": 0.0 if v is None else float(v[0]),
        "ve": 0.0 if v is None else float(v[1]),
        "vd": 0.0 if v is None else float(v[2]),
        "speed_accuracy": 0.0 if v is None else float(speed_acc),
        "horiz_accuracy": float(acc),
        "vert_accuracy": float(vacc),
        "satellites_visible": int(fix.satellites_visible),
        "yaw": 0,
    }
