"""``beliefnav replay LOG --rinex-obs OBS --rinex-nav NAV``: SPP fixes from RINEX, joined to the log's
boot time through SYSTEM_TIME, replace the log's fixes; ``--smartloc`` GNSS-only; ``--coupling``."""

from __future__ import annotations

import fcntl
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from companion.gnss.constants import C_M_S
from companion.gnss.geometry import geodetic_to_ecef
from companion.gnss.systems import System
from companion.gnss.timescale import BootTimeMap, unix_to_gps_s
from companion.mavlink.tlog import read_tlog
from gcs_tools.gnss.rinex import write_nav, write_obs
from gcs_tools.gnss.synthetic import observe_many
from gcs_tools.gnss.timebase import log_time_map
from tests.gnss_helpers import CLOCKS_M, constellation, store

QUAD106 = Path(__file__).parent / "data" / "quad106.tlog"
UNIX0_S = 1_700_000_000.0  # quad106's SYSTEM_TIME: time_unix_usec = 1.7e15 + time_boot_ms * 1000


def test_log_time_map_from_system_time():
    m = log_time_map(QUAD106)
    assert m.pairs_used > 600 and m.rejected == 0 and abs(m.drift) < 1e-9
    t_gps = unix_to_gps_s(UNIX0_S + 100.0)
    assert m.boot_us(t_gps) == 100_000_000  # Unix 1.7e9 s is 2023-11-14: GPST − UTC = 18 s applied


@pytest.fixture(scope="module")
def rinex_for_quad106(tmp_path_factory):
    """RINEX files seen from quad106's own GPS_RAW_INT positions once per second (receiver clock 10 µs),
    and the true positions. Written once per test run: this module and test_rinex2 read the same files
    (deterministic); under pytest-xdist the first worker writes them under a lock, the others read."""
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent  # the run's directory, shared by its workers
    out = root / "rinex-quad106"
    with open(root / "rinex-quad106.lock", "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        if not (out / "truth.npz").exists():
            out.mkdir(exist_ok=True)
            t_us, p = zip(*_write_rinex_for_quad106(out), strict=True)
            np.savez(out / "truth-partial.npz", t_us=np.array(t_us, dtype=np.int64), p=np.array(p))
            (out / "truth-partial.npz").rename(out / "truth.npz")  # complete, or absent
    with np.load(out / "truth.npz") as saved:
        truth = [(int(t), p) for t, p in zip(saved["t_us"], saved["p"], strict=True)]
    return out / "q.obs", out / "q.nav", truth


def _write_rinex_for_quad106(out: Path) -> list[tuple[int, np.ndarray]]:
    tmap = BootTimeMap.from_system_time(np.array([UNIX0_S * 1e6]), np.array([0.0]))
    t_mid = tmap.gps_s(300e6)
    st = store(t_mid)
    fixes = [
        (m.time_usec, m.lat * 1e-7, m.lon * 1e-7, m.alt * 1e-3)
        for _, m in read_tlog(QUAD106, types=("GPS_RAW_INT",))
        if m.fix_type >= 3
    ]
    truth, t_gps, vel = [], [], []
    last_s = -1
    ecef = [geodetic_to_ecef(math.radians(lat), math.radians(lon), alt) for _, lat, lon, alt in fixes]
    for i, (t_us, *_) in enumerate(fixes):
        if t_us // 1_000_000 == last_s:
            continue
        last_s = t_us // 1_000_000
        p = ecef[i]
        j0, j1 = max(i - 1, 0), min(i + 1, len(fixes) - 1)  # the receiver's velocity (its Doppler)
        vel.append((ecef[j1] - ecef[j0]) / max((fixes[j1][0] - fixes[j0][0]) * 1e-6, 1e-3))
        t_gps.append(tmap.gps_s(t_us))
        truth.append((t_us, p))
    # every epoch at once: what observe() gives one epoch at a time, number for number (14 s -> 2 s CPU)
    epochs = [ep for ep, _ in observe_many(st, t_gps, np.array([p for _, p in truth]).reshape(-1, 3),
                                           np.array(vel).reshape(-1, 3), atmosphere=False)]
    kep, glo = constellation(t_mid)
    write_nav(out / "q.nav", kep, glo)
    write_obs(out / "q.obs", epochs, "GPS", glonass_channels={g.prn: g.channel for g in glo})
    return truth


def test_rinex_fixes_land_on_the_log_fixes(rinex_for_quad106):
    from companion.gnss.spp import SppConfig
    from gcs_tools.gnss.replay import rinex_log_reader

    obs, nav, truth = rinex_for_quad106
    reader, note = rinex_log_reader(QUAD106, obs, [nav], SppConfig(tropo=False))
    assert note["solutions"] == note["epochs"] == len(truth)
    got = {f.t_validity_us: f for f in reader.fixes}
    for t_us, p in truth[::50]:
        f = got[t_us]  # validity = the receiver's tag − its clock offset, on boot time, to the µs
        q = geodetic_to_ecef(math.radians(f.lat_deg), math.radians(f.lon_deg), f.alt_m)
        assert np.linalg.norm(q - p) < 0.01 and f.fix_type == 3 and f.h_acc_m > 0
    assert CLOCKS_M[System.GPS] / C_M_S > 5e-6  # (the tag really was offset)
    events = list(reader)
    assert reader.stats.rejected["log_fix_replaced"] > 600
    assert reader.stats.decoded["gnss_external"] == len(truth)
    n_fix = sum(1 for e in events if type(e).__name__ == "GnssFix")
    assert n_fix == len(truth)


def test_replay_cli_with_rinex_and_coupling_options(rinex_for_quad106, tmp_path):
    obs, nav, truth = rinex_for_quad106
    out = tmp_path / "rep"
    cmd = [
        sys.executable,
        "-m",
        "gcs_tools",
        "replay",
        str(QUAD106),
        "--rinex-obs",
        str(obs),
        "--rinex-nav",
        str(nav),
        "--coupling",
        "loose",
        "--out",
        str(out),
        "--no-progress",
        "--no-telemetry",
        "--no-figures",  # the figures are test_replay_figures'; not drawn here, ~2 s of CPU a run
    ]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    s = json.loads((out / "summary.json").read_text())
    assert s["sources"]["gnss"].startswith("RINEX q.obs") and s["raw_gnss"]["coupling"] == "loose"
    assert s["navigator"]["gnss_fused"] > 600
    # SPP fixes without the troposphere model error would be metres off: with it, the estimate
    # follows them as it follows the log's own fixes
    assert s["errors"]["gnss"]["error_horizontal_m"]["median"] < 2.0
    tight = subprocess.run(
        cmd[:9] + ["--coupling", "tight", "--out", str(tmp_path / "t"), "--no-progress", "--no-figures"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert tight.returncode == 0, tight.stderr
    t = json.loads((tmp_path / "t" / "summary.json").read_text())
    nav_t = t["navigator"]
    assert t["raw_gnss"]["coupling"] == "tight" and nav_t["gnss_fused"] >= len(truth) - 2
    assert nav_t["gnss_resets"] == 0 and nav_t["sat_used"] > 6 * len(truth)
    from gcs_tools.replay import gnss_record

    ep = gnss_record.read(tmp_path / "t" / "gnss_epochs.csv")  # one row per raw epoch, as the counters
    assert len(ep["t_s"]) == t["raw_gnss"]["epochs"] and (ep["reason"] == "start").sum() == 1
    assert np.nansum(ep["n_used"]) == nav_t["sat_used"]
    assert np.nansum(ep["n_excluded"]) == nav_t["sat_rejected"]
    assert (ep["reset"] == 0).all() and not (tmp_path / "t" / "gnss_fixes.csv").exists()
    # the same pseudoranges (and models) as the loose run's single-point fixes: the tight estimate lands
    # where the loose one does (both in the frame of the first single-point solution)
    assert t["home"] == s["home"]
    est = np.genfromtxt(tmp_path / "t" / "estimates.csv", delimiter=",", names=True)
    ref = np.genfromtxt(out / "estimates.csv", delimiter=",", names=True)
    ref = ref[ref["t_s"] > ref["t_s"][0] + 10.0]
    err = np.hypot(np.interp(ref["t_s"], est["t_s"], est["p_n_m"]) - ref["p_n_m"],
                   np.interp(ref["t_s"], est["t_s"], est["p_e_m"]) - ref["p_e_m"])
    assert np.median(err) < 1.0, np.median(err)
    bad_method = ["--coupling", "tight", "--method", "adaptive", "--out", str(tmp_path / "b")]
    badm = subprocess.run(cmd[:9] + bad_method, capture_output=True, text=True, timeout=60)
    assert badm.returncode == 2 and "second-order" in badm.stderr and badm.stderr.count("\n") == 1
    nonav = subprocess.run(
        cmd[:7] + ["--out", str(tmp_path / "n")], capture_output=True, text=True, timeout=60
    )
    assert nonav.returncode == 2 and "--rinex-nav" in nonav.stderr


def test_never_initialised_names_what_the_estimator_refused(tmp_path):
    """Replacement fixes all stamped before the log's first IMU sample (a clock join gone wrong, e.g. a
    simulated receiver's UBX without its receiver.json): the one line says so, not only the counts."""
    from companion.domain.geodesy import LocalNedFrame
    from companion.domain.samples import GnssFix
    from companion.errors import UserError
    from gcs_tools.gnss.replay import LogWithFixes
    from gcs_tools.replay import core
    from gcs_tools.replay.logs import open_log

    short = tmp_path / "short.tlog"
    short.write_bytes(QUAD106.read_bytes()[:300_000])
    fixes = [GnssFix(1_000 + k, -37.86, 144.76, 10.0, 3, 10) for k in range(5)]
    reader = LogWithFixes(open_log(short), fixes, "too early")
    with pytest.raises(UserError, match="never initialised") as info:
        core.replay(short, "naive", reader=reader, home=LocalNedFrame(-37.86, 144.76, 10.0))
    assert "; GNSS refused by the estimator: before imu 5)" in str(info.value), info.value


def test_raw_gnss_option_errors_are_one_line(tmp_path, capsys):
    """--ubx is raw GNSS for the tight filter; the smartLoc drive has no mission (no map of Berlin)."""
    from gcs_tools.cli import main

    cases = (
        (["replay", str(QUAD106), "--ubx", str(tmp_path / "r.ubx")], "--ubx goes with --coupling tight"),
        (["replay", str(QUAD106), "--ubx", str(tmp_path / "r.ubx"), "--coupling", "tight"], "no such file"),
        (["replay", "--smartloc", str(tmp_path / "in.txt"), "--coupling", "tight", "--mission", "test"],
         "no map of Berlin"),
        (["replay", "--smartloc", str(tmp_path / "in.txt"), "--mission", "test"],  # loose too
         "no map of Berlin"),
        (["replay", "--smartloc", str(tmp_path / "in.txt"), "--no-odometry"],  # was silently without effect
         "--no-odometry goes with --smartloc --coupling tight"),
        (["replay", "--smartloc", str(tmp_path / "in.txt"), "--coupling", "tigth"],
         "(did you mean 'tight'?)"),
    )
    data = Path(__file__).parent / "data"
    rinex = ["--rinex-obs", str(data / "synthetic_gnss.obs"), "--rinex-nav", str(data / "synthetic_gnss.nav")]
    short = tmp_path / "short.tlog"
    short.write_bytes(QUAD106.read_bytes()[:300_000])
    cases += (  # RINEX of another day: the one line says where its fixes went, not only the log's count
        (["replay", str(short), *rinex], "never initialised ("),
    )
    for args, message in cases:
        assert main([*args, "--out", str(tmp_path / "o"), "--no-telemetry"]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1, err
    assert "refused while reading: log fix replaced " in err and ", external fix after log 3)" in err


SMARTLOC = (Path(__file__).resolve().parents[1] / "../shared/data/urban/smartloc"
            / "Berlin_Potsdamer_Platz_Input.txt")


def test_smartloc_stamps_on_boot_time_one_rule_for_both_readers():
    """smartLoc stamps are a millisecond grid written with sub-µs float error: rounded to the nearest µs
    they land on it (truncation put 281.99899983 s 1 µs early); the loose and the tight readers give the
    truth (and the epochs) the same boot times."""
    import os

    from gcs_tools.gnss import smartloc
    from gcs_tools.gnss.replay import SMARTLOC_T0_US, SmartLocSource, smartloc_boot_us
    from gcs_tools.gnss.tight_replay import SmartLocRawSource
    from gcs_tools.replay.events import Reference

    assert smartloc_boot_us(281.99899983, 0.0) == 281_999_000 + SMARTLOC_T0_US
    assert smartloc_boot_us(0.29999995231628, 0.0) == 300_000 + SMARTLOC_T0_US
    np.testing.assert_array_equal(smartloc_boot_us(np.array([10.0000004, 10.2999996]), 10.0),
                                  [SMARTLOC_T0_US, SMARTLOC_T0_US + 300_000])
    if not SMARTLOC.is_file():
        if os.environ.get("CI") == "true":
            pytest.fail(f"{SMARTLOC}: the smartLoc data set is missing in CI")
        pytest.skip("smartLoc data set not beside the repository (../shared/data/urban/smartloc)")
    data, truth = smartloc.read_drive(SMARTLOC, None)
    raw = SmartLocRawSource(data.epochs, data.odometry, truth.t_s, truth.p_ecef_m)
    loose = SmartLocSource([], truth.t_s, truth.p_ecef_m, raw.t0_s)
    t_raw = [e.t_us for e in raw if type(e) is Reference]
    t_loose = [e.t_us for e in loose if type(e) is Reference]
    assert t_raw == t_loose and len(t_raw) == len(truth.t_s)
    assert all((t - SMARTLOC_T0_US) % 1000 == 0 for t in t_raw)  # each on its millisecond
