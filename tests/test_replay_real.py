"""Real IMU flights (ANSFL) with synthetic GNSS: the reader's frames, the clock fit, the GNSS
made from truth plus the urban model or a recorded error series, and the raw fixes' scoring —
known answers on synthetic flights, then the real corpus."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from ansfl_helpers import G, Trajectory, real_flights, write_flight
from scipy.spatial.transform import Rotation

from companion.domain.geodesy import LocalNedFrame
from companion.domain.samples import GnssFix, ImuSample
from companion.errors import UserError
from gcs_tools.cli import main
from gcs_tools.replay import core
from gcs_tools.replay.ansfl import AnsflSource, load_flight
from gcs_tools.replay.clockfit import fit_clock_offset
from gcs_tools.replay.logs import open_log
from gcs_tools.replay.synthetic_gnss import (
    HDOP_UERE_M,
    GnssErrorOptions,
    Track,
    load_error_series,
    replace_gnss,
    synthesize,
)

FRAME = LocalNedFrame(32.7614, 35.0195, 0.0)


def write_series(path: Path, t_s: np.ndarray, err: np.ndarray, h: list[str] | None = None,
                 v: list[str] | None = None) -> Path:
    lines = ["t_s,err_n_m,err_e_m,err_d_m,h_acc_m,v_acc_m"]
    for k, (t, e) in enumerate(zip(t_s, err, strict=True)):
        lines.append(f"{t:.6f},{e[0]:.6f},{e[1]:.6f},{e[2]:.6f},{h[k] if h else ''},{v[k] if v else ''}")
    path.write_text("\n".join(lines) + "\n")
    return path


# --- clock fit and frames: known answers ------------------------------------------------------

def test_clock_fit_recovers_a_known_offset_and_heading_error() -> None:
    """IMU acceleration (120 Hz, 2 m/s² noise, heading 3° off) and truth positions (10 Hz, 1 cm
    noise) on clocks 0.437 s apart: the offset to 10 ms, the heading to 0.75° (about 3σ of the fit
    at these noise levels, measured over seeds: 3.5 ms and 0.25°); without noise, exact."""
    traj, rng = Trajectory(), np.random.default_rng(1)
    t = np.arange(0.0, 40.0, 1 / 120)
    psi = math.radians(-3.0)  # the IMU's horizontal axes turned 3° west of the truth's
    a = traj.a(t)
    a_exact = np.column_stack((math.cos(psi) * a[:, 0] - math.sin(psi) * a[:, 1],
                               math.sin(psi) * a[:, 0] + math.cos(psi) * a[:, 1], a[:, 2]))
    a_imu = a_exact + 2.0 * rng.standard_normal(a.shape)
    tau = np.arange(0.0, 39.0, 0.1)
    p = traj.p(tau + 0.437) + 0.01 * rng.standard_normal((len(tau), 3))
    fit = fit_clock_offset(t, a_imu, tau, p)
    assert abs(fit.offset_s - 0.437) < 0.010, fit
    assert abs(fit.yaw_deg - 3.0) < 0.75, fit
    exact = fit_clock_offset(t, a_exact, tau, traj.p(tau + 0.437))
    assert abs(exact.offset_s - 0.437) < 1e-4 and abs(exact.yaw_deg - 3.0) < 1e-3, exact
    assert fit.residual_rms_m_s2 < 0.5 * fit.signal_rms_m_s2
    assert fit.residual_rms_no_yaw_m_s2 > fit.residual_rms_m_s2
    with pytest.raises(UserError, match="overlap too little"):
        fit_clock_offset(t[:300], a_imu[:300], tau[:20], p[:20])


def test_ansfl_reader_frames_units_and_clock(tmp_path: Path) -> None:
    """A flight written in the data set's layout: the reader gives back the true FRD→NED attitude,
    the specific force in FRD (R f + g = the true acceleration), rad/s rates, the truth on the
    IMU clock about its first point, and the offset and heading error the file was made with."""
    traj = write_flight(tmp_path / "f", offset_s=0.3, heading_error_deg=2.0)
    fl = load_flight(tmp_path / "f" / "IMU_1.csv", tmp_path / "f" / "GT.csv")
    r_true = Rotation.from_euler("Z", -2.0, degrees=True) * traj.attitude(fl.t_s)
    r_read = Rotation.from_quat(fl.q_ned_frd[:, [1, 2, 3, 0]])
    assert np.max((r_read * r_true.inv()).magnitude()) < 1e-7
    a_read = fl.a_ned_m_s2()
    # the true acceleration seen through the recorded (2° off) heading
    a_true = Rotation.from_euler("Z", -2.0, degrees=True).apply(traj.a(fl.t_s))
    assert np.max(np.abs(a_read - a_true)) < 1e-6
    assert np.allclose(fl.gyro_frd_rad_s[:, 2], 0.05)
    assert np.allclose(fl.gyro_frd_rad_s[:, 0], 0.1 * np.sin(fl.t_s))
    assert abs(fl.clock.offset_s - 0.3) < 0.002 and abs(fl.clock.yaw_deg - 2.0) < 0.1
    truth_true = traj.p(fl.t_truth_s) - traj.p(np.array([0.3]))
    assert np.max(np.abs(fl.p_truth_ned_m - truth_true)) < 2e-3  # the fitted offset's error × speed


def test_level_at_rest_is_minus_g_on_frd_z(tmp_path: Path) -> None:
    d = tmp_path / "rest"
    d.mkdir()
    rows = [f"{k / 120:.6f},0,0,37.0,0,0,{G},0,0,0" for k in range(2400)]
    (d / "IMU_1.csv").write_text("time,Euler_X,Euler_Y,Euler_Z,Acc_X,Acc_Y,Acc_Z,Gyr_X,Gyr_Y,Gyr_Z\n"
                                 + "\n".join(rows) + "\n")
    gt = "\n".join(f"{k / 10:.1f},{0.3 * k},0,0" for k in range(150))
    (d / "GT.csv").write_text("time,North,East,Down\n" + gt)
    with pytest.raises(UserError, match="too little acceleration"):  # nothing to fit the clock on
        AnsflSource(d)
    from gcs_tools.replay.ansfl import attitude_ned_frd, rotate

    q = attitude_ned_frd(np.zeros(1), np.zeros(1), np.array([37.0]))
    assert np.allclose(rotate(q, np.array([[0.0, 0.0, -G]])), [[0.0, 0.0, -G]])
    assert np.allclose(rotate(q, np.array([[1.0, 0.0, 0.0]])),  # x: 37° north of east = 53° east of north
                       [[math.cos(math.radians(53)), math.sin(math.radians(53)), 0.0]], atol=1e-12)


# --- synthetic GNSS: known answers ------------------------------------------------------------

def long_track(seconds: float = 3000.0, rate_hz: float = 10.0) -> Track:
    t = np.arange(0.0, seconds, 1 / rate_hz)
    return Track(np.rint(t * 1e6).astype(np.int64), Trajectory().p(t), "test truth")


def test_model_errors_are_the_urban_models_and_seeded() -> None:
    """On a long track in a canyon (clearance 0): the error std is the model's sqrt(σ_ss² + σ²)
    (1.2 m bias, 0.1 m noise), the latency mean its canyon mean (0.6 s), the reported accuracy its
    white-noise std; same seed, same fixes; another seed, other fixes."""
    opts = GnssErrorOptions("model", rate_hz=5.0, seed=7)
    a = synthesize(long_track(), opts, FRAME)
    assert len(a) == 15000
    assert np.allclose(a.err_ned_m.std(axis=0), math.hypot(1.2, 0.1), rtol=0.12)
    lat = (a.t_arrival_us - a.t_validity_us) / 1e6
    assert abs(lat.mean() - 0.6) < 0.03 and lat.min() >= 0 and lat.max() <= 1.2
    assert np.allclose(a.h_acc_m, 0.1, rtol=1e-9)  # sqrt(0.08² × 1.5625) = 0.1
    b = synthesize(long_track(), opts, FRAME)
    assert np.array_equal(a.p_ned_m, b.p_ned_m) and np.array_equal(a.t_arrival_us, b.t_arrival_us)
    c = synthesize(long_track(), GnssErrorOptions("model", rate_hz=5.0, seed=8), FRAME)
    assert not np.allclose(a.err_ned_m, c.err_ned_m)
    open_sky = synthesize(long_track(), GnssErrorOptions("model", rate_hz=5.0, clearance_m=100.0), FRAME)
    latency = (open_sky.t_arrival_us - open_sky.t_validity_us) / 1e6
    assert open_sky.err_ned_m.std() < 0.15 and abs(latency.mean() - 0.1) < 0.02


def test_series_errors_interpolated_outages_wrapped_and_accuracy_modes(tmp_path: Path) -> None:
    """A 1 Hz series with err_n = t, a 3 s gap and reported accuracies: at 5 Hz from t = 2 s the
    error is the exact interpolation, epochs in the gap have no fix, the series wraps around
    when the flight is longer; accuracy modes: reported / none / eph (HDOP = h_acc / UERE)."""
    t = np.array([0, 1, 2, 3, 4, 5, 9, 10, 11, 12], dtype=float)
    err = np.column_stack((t, -2.0 + 0 * t, 0.5 + 0 * t))
    h = [f"{1 + k}" for k in range(len(t))]
    path = write_series(tmp_path / "s.csv", t, err, h, ["" for _ in t])
    track = long_track(20.0)
    def series(**kw: object) -> GnssErrorOptions:
        return GnssErrorOptions(str(path), rate_hz=5.0, series_start_s=2.0, **kw)  # type: ignore[arg-type]

    out = synthesize(track, series(velocity_std_m_s=None), FRAME)
    ts = 2.0 + (out.t_validity_us - track.t_us[0]) / 1e6  # series time, before wrapping
    span = 12.0 + 1.0
    ts = np.mod(ts, span)
    assert np.allclose(out.err_ned_m[:, 0], ts) and np.allclose(out.err_ned_m[:, 1:], [-2.0, 0.5])
    assert not np.any((ts > 5.0) & (ts < 9.0)) and not np.any(ts > 12.0)  # the gap and the wrap are outages
    assert out.info["series_outage_epochs"] > 0 and out.info["series_wrapped"]
    assert np.allclose(out.h_acc_m, np.array(h, dtype=float)[np.searchsorted(t, np.round(ts), side="left")])
    assert np.isnan(out.v_acc_m).all() and out.v_ned_m_s is None
    none = synthesize(track, series(accuracy="none"), FRAME)
    assert np.isnan(none.h_acc_m).all() and np.isnan(none.hdop).all() and np.isnan(none.vel_acc_m_s).all()
    eph = synthesize(track, series(accuracy="eph"), FRAME)
    assert np.isnan(eph.h_acc_m).all() and np.allclose(eph.hdop, out.h_acc_m / HDOP_UERE_M)
    long_series = write_series(tmp_path / "long.csv", np.arange(100.0), np.zeros((100, 3)))
    drawn = [synthesize(track, GnssErrorOptions(str(long_series), rate_hz=1.0, seed=s), FRAME)
             .info["series_start_s"] for s in (0, 1, 0)]
    assert drawn[0] == drawn[2] != drawn[1] and all(0 <= d <= 100 - 19 for d in drawn)


@pytest.mark.parametrize(("text", "words"), [
    ("t,err_n_m,err_e_m,err_d_m,h_acc_m,v_acc_m\n0,1,1,1,,\n1,1,1,1,,\n", "expected t_s,err_n_m"),
    ("t_s,err_n_m,err_e_m,err_d_m,h_acc_m,v_acc_m\n0,1,1,1,,\n1,x,1,1,,\n",
     "line 3: err_n_m 'x' is not a number"),
    ("t_s,err_n_m,err_e_m,err_d_m,h_acc_m,v_acc_m\n0,1,1,1,,\n0,1,1,1,,\n", "line 3: t_s 0.0 is not after"),
    ("t_s,err_n_m,err_e_m,err_d_m,h_acc_m,v_acc_m\n0,1,1,1,-1,\n1,1,1,1,,\n", "line 2: h_acc_m '-1'"),
    ("t_s,err_n_m,err_e_m,err_d_m,h_acc_m,v_acc_m\n0,1,1,nan,,\n1,1,1,1,,\n", "line 2: err_d_m 'nan'"),
    ("t_s,err_n_m,err_e_m,err_d_m,h_acc_m,v_acc_m\n0,1,1,1\n", "line 2: 4 fields"),
    ("t_s,err_n_m,err_e_m,err_d_m,h_acc_m,v_acc_m\n0,1,1,1,,\n", "1 rows"),
])
def test_bad_error_series_are_one_line_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                              text: str, words: str) -> None:
    bad = tmp_path / "bad.csv"
    bad.write_text(text)
    with pytest.raises(UserError, match=None) as info:
        load_error_series(bad)
    assert words in str(info.value), info.value
    flight = tmp_path / "flight"
    write_flight(flight, seconds=25.0)
    assert main(["replay", str(flight), "--gnss-errors", str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("beliefnav: error: ") and words in err and "\n" not in err
    assert not (tmp_path / "o").exists()


def test_damaged_flight_files_name_the_line_in_one_line(tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    """An IMU_1.csv cut mid-row, a text line in it, a GT.csv with a header only: one line naming the
    file's line (numpy's own row numbers count differently per error), no warning on stderr."""
    flight = tmp_path / "f"
    write_flight(flight, seconds=25.0)
    imu = (flight / "IMU_1.csv").read_text().splitlines(keepends=True)
    cases = {
        "cut": ("IMU_1.csv", "".join(imu[:101]) + imu[101][:imu[101].index(",", 3) + 3],
                "IMU_1.csv: line 102 has 2 columns, the header 10 (a truncated or malformed row)"),
        "text": ("IMU_1.csv", "".join(imu[:50]) + "0.5,x,1,2,3,4,5,6,7,8\n" + "".join(imu[50:]),
                 "IMU_1.csv: line 51, column 2: 'x' is not a number"),
        "empty_gt": ("GT.csv", (flight / "GT.csv").read_text().splitlines(keepends=True)[0],
                     "usable IMU rows and 0 truth rows; an ANSFL flight needs both"),
    }
    for name, (file, text, words) in cases.items():
        bad = tmp_path / name
        bad.mkdir()
        for f in ("IMU_1.csv", "GT.csv"):
            (bad / f).write_text((flight / f).read_text())
        (bad / file).write_text(text)
        assert main(["replay", str(bad), "--gnss-errors", "none", "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("beliefnav: error: ") and "\n" not in err and words in err, err


def test_a_lone_damaged_imu_time_drops_that_row_not_the_rest_of_the_flight(tmp_path: Path) -> None:
    """One IMU row stamped 1e6 s in the middle: it was kept and every later row dropped as 'not after
    the previous' (a 25 s flight replayed as '1000000 s' on its first half); now that row alone."""
    flight = tmp_path / "f"
    write_flight(flight, seconds=25.0)
    lines = (flight / "IMU_1.csv").read_text().splitlines(keepends=True)
    lines[1000] = "1000000.0," + lines[1000].split(",", 1)[1]
    (flight / "IMU_1.csv").write_text("".join(lines))
    s = core.replay(flight, "naive", gnss=GnssErrorOptions("none", rate_hz=5.0)).summary
    assert s["samples_rejected"]["codec"]["imu_row_dropped"] == 1
    assert s["duration_s"] < 30.0 and s["samples_used"]["imu"] == len(lines) - 2


def test_replay_of_a_synthetic_flight_with_exact_fixes(tmp_path: Path) -> None:
    """Exact fixes (no error) at 10 Hz arriving 200 ms late: the estimate follows the truth to a
    few cm, the raw fixes' error is 0 at validity and, at arrival, exactly the distance flown in
    the latency; every fix is pushed at its arrival, in order."""
    traj = write_flight(tmp_path / "f", seconds=40.0, offset_s=0.25)
    opts = GnssErrorOptions("none", rate_hz=10.0, latency_ms=200.0, velocity_std_m_s=0.0)
    res = core.replay(tmp_path / "f", "second-order", gnss=opts)
    s = res.summary
    truth = s["errors"]["truth"]
    assert truth["n"] > 350 and truth["error_horizontal_m"]["median"] < 0.05, truth
    raw = s["errors"]["raw_fixes"]
    assert raw["at_validity"]["error_3d_m"]["max"] < 1e-6
    src = AnsflSource(tmp_path / "f")
    t_v = src.flight.t_truth_s[0] + np.arange(0, 400) * 0.1
    t_v = t_v[t_v + 0.2 <= src.flight.t_truth_s[-1]]
    flown = np.linalg.norm((traj.p(t_v + 0.2) - traj.p(t_v))[:, :2], axis=1)
    assert abs(raw["at_arrival"]["error_horizontal_m"]["median"] - np.median(flown)) < 0.01
    assert s["synthetic_gnss"]["latency_s"]["mean"] == pytest.approx(0.2)
    assert s["navigator"]["gnss_fused"] == s["samples_used"]["gnss"] > 380


def test_synthetic_fixes_are_pushed_at_arrival_and_carry_velocity(tmp_path: Path) -> None:
    """Each fix comes right before the first IMU sample at or after its arrival time, with the
    base's velocity and the reported speed accuracy; the frame is the flight's anchor."""
    write_flight(tmp_path / "f", seconds=25.0)
    opts = GnssErrorOptions("model", rate_hz=5.0, seed=3)
    reader, frame = replace_gnss(open_log(tmp_path / "f"), open_log(tmp_path / "f"), opts, None)
    syn = reader.synthetic
    arrival = dict(zip(syn.t_validity_us.tolist(), syn.t_arrival_us.tolist(), strict=True))
    events = list(reader)
    fixes = [(k, e) for k, e in enumerate(events) if type(e) is GnssFix]
    assert len(fixes) > 100 and all(e.v_ned_m_s is not None and e.vel_acc_m_s == 0.2 for _, e in fixes)
    for k, fix in fixes:
        before = [e.t_us for e in events[:k] if type(e) is ImuSample]
        after = next(e.t_us for e in events[k:] if type(e) is ImuSample)
        assert (not before or before[-1] < arrival[fix.t_validity_us]) and after >= arrival[fix.t_validity_us]
    assert frame == FRAME


def test_cli_replays_a_flight_with_the_urban_model(tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    write_flight(tmp_path / "f", seconds=25.0)
    out = tmp_path / "o"
    assert main(["replay", str(tmp_path / "f" / "IMU_1.csv"), "--gnss-errors", "model", "--gnss-rate-hz", "1",
                 "--gnss-accuracy", "none", "--out", str(out), "--json", "--method", "naive",
                 "--no-figures"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["format"] == "ansfl"
    assert s["synthetic_gnss"]["rate_hz"] == 1.0 and s["synthetic_gnss"]["accuracy"] == "none"
    assert {"at_validity", "at_arrival", "reference"} <= set(s["errors"]["raw_fixes"])
    assert abs(s["clock_alignment"]["offset_s"] - 0.3) < 0.01 and (out / "estimates.csv").is_file()
    assert main(["replay", str(tmp_path / "f"), "--out", str(tmp_path / "o2")]) == 2
    assert "has no GNSS of its own: give --gnss-errors" in capsys.readouterr().err
    for bad, words in ((["--gnss-rate-hz", "0"], "--gnss-rate-hz 0.0"),
                       (["--gnss-velocity", "fast"], "--gnss-velocity"),
                       (["--gnss-set", "estimator.eta=1"], "only gnss.FIELD"),
                       (["--gnss-set", "gnss.sigma_bias_max_m=-1"], "sigma_bias_max_m"),
                       (["--gnss-base", "log"], "no 3-D fix of its own")):
        args = ["replay", str(tmp_path / "f"), "--gnss-errors", "model", *bad, "--out", str(tmp_path / "o3")]
        assert main(args) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("beliefnav: error: ") and words in err and "\n" not in err, err
    assert main(["replay", str(tmp_path), "--out", str(tmp_path / "o3")]) == 2
    assert "not an ANSFL flight" in capsys.readouterr().err


def test_other_logs_with_truth_or_their_own_fixes_as_the_base() -> None:
    """A SITL DataFlash log: fixes from its SIM truth; the real quad106 tlog (no truth): its own
    fixes degraded, and scored against them."""
    data = Path(__file__).parent / "data"
    s = core.replay(data / "arducopter_sitl_hover.bin", "second-order",
                    gnss=GnssErrorOptions("model", rate_hz=5.0)).summary
    assert s["synthetic_gnss"]["base"] == "truth (SIM)" and s["samples_used"]["gnss_log_fix_replaced"] > 300
    # "gnss" counts the fixes given to the estimator: the synthetic ones, not also the replaced (it did)
    used = s["samples_used"]
    assert used["gnss"] == s["synthetic_gnss"]["fixes"] - used.get("gnss_synthetic_after_last_imu", 0)
    assert s["errors"]["raw_fixes"]["at_validity"]["n"] > 100 and s["errors"]["truth"]["n"] > 1000
    q = core.replay(data / "quad106.tlog", "second-order",
                    gnss=GnssErrorOptions("none", rate_hz=1.0, base="log", latency_ms=0.0)).summary
    assert q["synthetic_gnss"]["base"] == q["errors"]["raw_fixes"]["reference"] == "the log's own fixes"
    assert q["errors"]["raw_fixes"]["at_validity"]["error_3d_m"]["max"] < 1e-6
    assert q["navigator"]["gnss_fused"] > 600


# --- the real corpus --------------------------------------------------------------------------

def test_real_flights_clock_fit_and_heading() -> None:
    """Every ANSFL flight: the clock fit explains most of the truth's horizontal acceleration
    (more than 60 % of its variance; measured 68–96 %), the offset lies in 0–1 s (measured
    0.11–0.75 s), the IMU's heading is within 10° of the truth track, and that heading error is
    confirmed independently by the drone's own compass (GT.csv compass_heading) to 3°."""
    root = real_flights()
    for d in sorted(root.glob("path_*")):
        fl = load_flight(d / "IMU_1.csv", d / "GT.csv")
        c = fl.clock
        assert 0.0 < c.offset_s < 1.0 and abs(c.yaw_deg) < 10.0, (d.name, c)
        assert 1 - (c.residual_rms_m_s2 / c.signal_rms_m_s2) ** 2 > 0.6 and c.samples > 150, (d.name, c)
        gt = np.genfromtxt(d / "GT.csv", delimiter=",", names=True)
        yaw_imu = np.unwrap(np.arctan2(*_x_axis_ne(fl.q_ned_frd)))  # heading of FRD x, east of north
        at = np.interp(gt["time"] + c.offset_s, fl.t_s, yaw_imu)
        diff = (np.degrees(at) - gt["compass_headingdegrees"] + 180.0) % 360.0 - 180.0
        assert abs(np.mean(diff) + c.yaw_deg) < 3.0, (d.name, np.mean(diff), c.yaw_deg)


def _x_axis_ne(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(east, north) components of the body x axis in NED, for arctan2(east, north)."""
    x = Rotation.from_quat(q[:, [1, 2, 3, 0]]).apply(np.array([1.0, 0.0, 0.0]))
    return x[:, 1], x[:, 0]


def test_real_flight_with_exact_fixes_follows_the_truth() -> None:
    """A real IMU with exact 5 Hz fixes (model latency): the estimate stays within decimetres of
    the RTK truth (the IMU's heading error and the latency are what is left)."""
    d = real_flights() / "path_2"
    s = core.replay(d, "second-order", gnss=GnssErrorOptions("none", rate_hz=5.0)).summary
    h = s["errors"]["truth"]["error_horizontal_m"]
    assert h["median"] < 0.4 and h["p95"] < 0.8, h
    assert s["wall_s"] < 3.0
