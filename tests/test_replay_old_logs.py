"""Old ArduCopter DataFlash logs (<= 3.2: millisecond stamps, older GPS/IMU/ATT layouts) replay like
new ones; the receiver's velocity is read from every log format (DataFlash GPS/GPA, ULog
vehicle_gps_position) with known answers."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from dataflash_writer import GPS_3_1, OLD_FORMATS, DataFlashWriter
from pymavlink import DFReader
from pyulog import ULog

from companion.domain.geodesy import LocalNedFrame
from companion.domain.samples import AttitudeSample, GnssFix, ImuSample
from companion.errors import UserError
from gcs_tools.cli import main
from gcs_tools.replay import core
from gcs_tools.replay.dataflash import DataFlashSource
from gcs_tools.replay.ulog import ULogSource

DATA = Path(__file__).parent / "data"
HOME = LocalNedFrame(-35.363261, 149.165230, 584.0)
G = 9.80665
V_NED = np.array([0.0, 2.0, -0.5])  # east at 2 m/s, climbing at 0.5 m/s
T0_MS = 5000


def old_log(path: Path, *, seconds: float = 20.0, gps: tuple[int, str, str] = OLD_FORMATS["GPS"],
            delay_param: float | None = None, imu_columns: str | None = None) -> Path:
    """An ArduCopter 3.2 log: IMU 50 Hz, ATT 10 Hz (yaw 90°), GPS 5 Hz, SIM 10 Hz, level flight east
    at constant velocity. Each GPS holds the position 220 ms before its boot time T (the EKF's
    default POS_DELAY), so validity = T − 220 ms puts it on the truth."""
    w = DataFlashWriter()
    for name in ("PARM", "IMU", "ATT", "SIM"):
        mtype, fmt, cols = OLD_FORMATS[name]
        w.define(mtype, name, fmt, imu_columns if name == "IMU" and imu_columns else cols)
    w.define(gps[0], "GPS", gps[1], gps[2])
    if delay_param is not None:
        w.add("PARM", "EKF_POS_DELAY", delay_param)
    delay_ms = 220.0 if delay_param is None else delay_param

    def where(t_ms: float) -> tuple[float, float, float]:
        return HOME.to_geodetic(V_NED * (t_ms - T0_MS) / 1000.0)

    for t in range(T0_MS, T0_MS + int(seconds * 1000), 20):
        w.add("IMU", t, 0.0, 0.0, 0.0, 0.0, 0.0, -G, 0, 0)
        if t % 100 == 0:
            w.add("ATT", t, 0.0, 0.0, 0.0, 0.0, 90.0, 90.0, 0.0, 0.0)
            lat, lon, alt = where(t)
            w.add("SIM", t, 0.0, 0.0, 90.0, alt, lat, lon)
        if t % 200 == 40:  # a GPS arrives between IMU samples' logging
            lat, lon, alt = where(t - delay_ms)
            common = (3, 130_040_903 + t, 1769, 10, 1.2, lat, lon, alt - 584.0, alt, 2.0, 90.0)
            w.add("GPS", *common, *((-0.5, t) if "VZ" in gps[2] else ()))
    path.write_bytes(bytes(w.data))
    return path


def test_an_arducopter_3_2_log_is_read_like_a_new_one(tmp_path: Path) -> None:
    """Millisecond stamps become µs; the GPS's boot time is its T (its TimeMS is GPS time of week);
    validity = T − 220 ms (3.2's EKF_POS_DELAY default); velocity from Spd/GCrs/VZ."""
    log = old_log(tmp_path / "old.bin")
    src = DataFlashSource(log)
    events = list(src)
    imu = [e for e in events if type(e) is ImuSample]
    att = [e for e in events if type(e) is AttitudeSample]
    fixes = [e for e in events if type(e) is GnssFix]
    assert len(imu) == 1000 and len(att) == 200 and len(fixes) == 100
    assert imu[0].t_us == T0_MS * 1000 and imu[1].t_us - imu[0].t_us == 20_000
    assert np.allclose(imu[0].acc_frd_m_s2, [0.0, 0.0, -G], atol=1e-6)
    assert np.allclose(att[0].q_ned_frd, [math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4)], atol=1e-9)
    assert fixes[0].t_validity_us == (T0_MS + 40 - 220) * 1000
    assert all(f.fix_type == 3 and math.isnan(f.h_acc_m) and f.hdop == pytest.approx(1.2) for f in fixes)
    assert all(np.allclose(f.v_ned_m_s, V_NED, atol=1e-6) for f in fixes)  # type: ignore[arg-type]
    assert src.gps_delay_ms == 220.0 and "3.2" in src.gps_delay_source
    s = core.replay(log, "second-order").summary
    truth = s["errors"]["truth"]
    assert truth["source"] == "SIM" and truth["n"] > 150
    assert truth["error_horizontal_m"]["median"] < 0.05, truth
    assert s["samples_used"] == {"imu": 1000, "attitude": 200, "gnss": 100, "gnss_without_gpa": 100}


def test_the_logs_own_ekf_pos_delay_is_used(tmp_path: Path) -> None:
    src = DataFlashSource(old_log(tmp_path / "d.bin", delay_param=150.0))
    fixes = [e for e in src if type(e) is GnssFix]
    assert fixes[0].t_validity_us == (T0_MS + 40 - 150) * 1000
    assert src.gps_delay_source == "log parameter EKF_POS_DELAY"


def test_a_gps_without_boot_time_is_stamped_on_arrival(tmp_path: Path) -> None:
    """ArduCopter 3.1's GPS (no T, no VZ): the fix arrived with the latest IMU/ATT message logged
    before it; its vertical velocity is unknown (NaN)."""
    src = DataFlashSource(old_log(tmp_path / "31.bin", gps=GPS_3_1))
    events = list(src)
    last = 0
    for e in events:
        if type(e) is GnssFix:
            assert e.t_validity_us == last - 220_000
            assert np.allclose(e.v_ned_m_s[:2], V_NED[:2], atol=1e-6) and math.isnan(e.v_ned_m_s[2])  # type: ignore[index]
        elif type(e) in (ImuSample, AttitudeSample):
            last = e.t_us  # type: ignore[union-attr]
    assert src.stats.decoded["gnss_stamped_on_arrival"] == src.stats.decoded["gnss"] == 100


def test_an_old_log_without_a_time_field_is_one_line(tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    columns = "Time,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,ErrG,ErrA"
    log = old_log(tmp_path / "bad.bin", seconds=2.0, imu_columns=columns)
    with pytest.raises(UserError, match="IMU has no field TimeUS or TimeMS"):
        list(DataFlashSource(log))
    assert main(["replay", str(log), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("beliefnav: error: ") and "\n" not in err
    assert "IMU has no field TimeUS or TimeMS" in err


def test_dataflash_gps_velocity_is_spd_gcrs_vz_with_gpa_speed_accuracy() -> None:
    """The SITL log: each fix's velocity is (Spd cos GCrs, Spd sin GCrs, VZ) of its GPS as pymavlink
    decodes it, its speed accuracy GPA.SAcc; and it agrees with the fixes' own motion."""
    log = DATA / "arducopter_sitl_hover.bin"
    ref = []
    df = DFReader.DFReader_binary(str(log), zero_time_base=False)
    sacc = []
    while (m := df.recv_msg()) is not None:
        if m.get_type() == "GPS" and m.I == 0:
            c = math.radians(m.GCrs)
            ref.append((m.Spd * math.cos(c), m.Spd * math.sin(c), m.VZ))
        elif m.get_type() == "GPA" and m.I == 0:
            sacc.append(m.SAcc)
    fixes = [e for e in DataFlashSource(log) if type(e) is GnssFix]
    v = np.array([f.v_ned_m_s for f in fixes])
    assert v.shape == (len(ref), 3) and np.allclose(v, ref, atol=1e-9)
    assert set(sacc) == {0.0} and all(math.isnan(f.vel_acc_m_s) for f in fixes)  # SITL reports none
    _agrees_with_motion(fixes, 0.3)


def test_gpa_speed_accuracy_and_no_vertical_velocity(tmp_path: Path) -> None:
    """Today's layouts (as in the SITL log) with a receiver that reports its speed accuracy (SAcc)
    and, on every other fix, no vertical velocity (VV 0): vel_acc = SAcc, v_down NaN there."""
    w = DataFlashWriter()
    w.define(130, "GPS", "QBBIHBcLLeffffB",
             "TimeUS,I,Status,GMS,GWk,NSats,HDop,Lat,Lng,Alt,Spd,GCrs,VZ,Yaw,U")
    w.define(131, "GPA", "QBCCCCfBIHeHH", "TimeUS,I,VDop,HAcc,VAcc,SAcc,YAcc,VV,SMS,Delta,AEl,RTCMFU,RTCMFD")
    for k in range(10):
        t_us = 1_000_000 + 200_000 * k
        w.add("GPS", t_us, 0, 3, 0, 0, 12, 0.9, -35.0, 149.0, 600.0, 3.0, 180.0, 0.25, 0.0, 1)
        w.add("GPA", t_us, 0, 1.1, 0.8, 1.2, 0.35, 0.0, k % 2, t_us // 1000 - 5, 200, 0.0, 0, 0)
    (tmp_path / "gpa.bin").write_bytes(bytes(w.data))
    src = DataFlashSource(tmp_path / "gpa.bin", gps_delay_ms=0.0)
    fixes = [e for e in src if type(e) is GnssFix]
    assert len(fixes) == 10 and all(f.vel_acc_m_s == pytest.approx(0.35) for f in fixes)
    assert all(f.h_acc_m == pytest.approx(0.8) and f.v_acc_m == pytest.approx(1.2) for f in fixes)
    for k, f in enumerate(fixes):
        assert np.allclose(f.v_ned_m_s[:2], [-3.0, 0.0], atol=1e-6)  # type: ignore[index]
        assert (f.v_ned_m_s[2] == 0.25) if k % 2 else math.isnan(f.v_ned_m_s[2])  # type: ignore[index]
        assert f.t_validity_us == 1_000_000 + 200_000 * k - 5000  # SMS: received 5 ms before logging


def test_ulog_gps_velocity_and_speed_accuracy() -> None:
    """PX4 vehicle_gps_position: vel_n/e/d_m_s where vel_ned_valid, s_variance_m_s as the speed
    accuracy; the vertical velocity agrees with the fixes' climb and descent."""
    log = DATA / "sample_px4_events.ulg"
    d = ULog(str(log), ["vehicle_gps_position"]).data_list[0].data
    fixes = [e for e in ULogSource(log) if type(e) is GnssFix]
    v = np.array([f.v_ned_m_s for f in fixes])
    ref = np.column_stack((d["vel_n_m_s"], d["vel_e_m_s"], d["vel_d_m_s"])).astype(float)
    assert v.shape == ref.shape and np.array_equal(v, ref)
    assert {f.vel_acc_m_s for f in fixes} == {0.25} and np.ptp(v[:, 2]) > 1.0
    _agrees_with_motion(fixes, 0.3)


def _agrees_with_motion(fixes: list[GnssFix], tol_m_s: float) -> None:
    """Median |v − Δp/Δt| over consecutive 3-D fixes (central differences) below ``tol_m_s``."""
    good = [f for f in fixes if f.fix_type >= 3]
    t = np.array([f.t_validity_us for f in good]) / 1e6
    p = HOME.to_ned_m(np.array([f.lat_deg for f in good]), np.array([f.lon_deg for f in good]),
                      np.array([f.alt_m for f in good])).T
    v_fd = (p[2:] - p[:-2]) / (t[2:] - t[:-2])[:, None]
    v = np.array([f.v_ned_m_s for f in good])[1:-1]
    ok = np.isfinite(v).all(axis=1)
    assert np.median(np.linalg.norm(v[ok] - v_fd[ok], axis=1)) < tol_m_s
