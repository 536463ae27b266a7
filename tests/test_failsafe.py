"""What the companion feeds an autopilot when the GNSS goes away (docs/deploy.md, "Failsafe"):
measured on the real quad106 log with the fixes cut after 300 s, through the same Navigator and
feed encoders the companion uses."""

import math
from pathlib import Path

import numpy as np
import pytest

from companion.autopilot import feeds
from companion.domain.geodesy import LocalNedFrame
from companion.domain.samples import AttitudeSample, GnssFix, ImuSample
from companion.estimator import EstimatorConfig
from companion.wiring import navigator_for
from gcs_tools.replay.logs import open_log

QUAD106 = Path(__file__).parent / "data" / "quad106.tlog"
CUT_S = 300.0  # boot time after which no fix reaches the filter
OUTAGE_S = 40.0


@pytest.fixture(scope="module")
def outage():
    """(s since the last fused fix, GPS_INPUT, VISION_POSITION_ESTIMATE, estimate) at each IMU sample
    from 2 s before the cut to OUTAGE_S after it."""
    cfg = EstimatorConfig()
    nav = frame = last_fix_s = attitude = None
    out = []
    for s in open_log(QUAD106):
        if isinstance(s, GnssFix):
            if s.t_validity_us * 1e-6 >= CUT_S:
                continue
            if frame is None and s.fix_type >= 3:
                frame = LocalNedFrame(s.lat_deg, s.lon_deg, s.alt_m)
                nav = navigator_for(None, "second-order", config=cfg, frame=frame)
            last_fix_s = s.t_validity_us * 1e-6
        elif isinstance(s, AttitudeSample):
            attitude = s.q_ned_frd
        if nav is None or not isinstance(s, (GnssFix, ImuSample, AttitudeSample)):
            continue
        nav.push(s)
        if isinstance(s, ImuSample) and CUT_S - 2 < s.t_us * 1e-6 < CUT_S + OUTAGE_S:
            e = nav.estimate()
            out.append((s.t_us * 1e-6 - last_fix_s, feeds.gps_input(e, frame, feeds.FeedConfig(), unix_s=0.0),
                        feeds.vision_position(e, attitude, feeds.FeedConfig()), e))
        elif isinstance(s, ImuSample) and s.t_us * 1e-6 >= CUT_S + OUTAGE_S:
            break
    return cfg, out


def test_gps_input_says_no_fix_once_the_estimate_is_no_longer_valid(outage):
    """GPS_INPUT keeps a 3-D fix with a growing accuracy while the filter dead-reckons, then, once no
    fix has been fused for ``pos_valid_timeout_s`` (5 s, as EKF2's position validity), says fix type 0
    with zero accuracy (the autopilot's own GPS failsafe takes over)."""
    cfg, rows = outage
    imu_period_s = float(np.median(np.diff([r[3].t_us for r in rows]))) * 1e-6
    valid = [(dt, m) for dt, m, _, _ in rows if m.fix_type == 3]
    lost = [(dt, m) for dt, m, _, _ in rows if m.fix_type == 0]
    assert valid and lost
    last_valid_dt = max(dt for dt, _ in valid)
    first_lost_dt = min(dt for dt, _ in lost)
    assert cfg.pos_valid_timeout_s - 0.2 <= last_valid_dt < cfg.pos_valid_timeout_s + imu_period_s
    assert first_lost_dt > last_valid_dt and all(dt > last_valid_dt for dt, _ in lost)  # no way back
    assert all(m.horiz_accuracy == 0 and m.satellites_visible == 0 for _, m in lost)
    acc = [(dt, m.horiz_accuracy) for dt, m in valid if dt > 0.5]  # (after the last fix came in)
    assert all(b >= a for (_, a), (_, b) in zip(acc, acc[1:], strict=False))  # grows while dead-reckoning
    at = {round(dt): a for dt, a in acc}
    print("GPS_INPUT horiz_accuracy [m] 1..4 s after the last fix:", [round(at[k], 2) for k in (1, 2, 3, 4)])
    assert at[1] < at[4] and at[4] > 1.0


def test_vision_keeps_sending_the_dead_reckoned_position_with_its_growing_covariance(outage):
    """VISION_POSITION_ESTIMATE has no validity flag: it goes on with the dead-reckoned position,
    its stated position variance growing without bound (what the autopilot's EKF weighs it by)."""
    _, rows = outage
    sigma = [(dt, math.sqrt(v.covariance[0] + v.covariance[6])) for dt, _, v, _ in rows if dt > 0.5]
    assert all(b >= a for (_, a), (_, b) in zip(sigma, sigma[1:], strict=False))
    at = {round(dt): s for dt, s in sigma}
    print("VISION horizontal std [m] 5, 10, 30 s after the last fix:", [round(at[k], 1) for k in (5, 10, 30)])
    assert at[10] > 5.0 and at[30] > 30.0
