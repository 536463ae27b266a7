"""``beliefnav replay``: bad logs end in one line and a non-zero exit; good logs give estimates,
counted rejections and error statistics named by reference."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from companion.domain.geodesy import LocalNedFrame
from companion.domain.samples import AttitudeSample, GnssFix, ImuSample, NavEstimate, TruthState
from companion.errors import UserError
from companion.mavlink import codec as mc
from companion.mavlink.tlog import TlogWriter
from gcs_tools.cli import main
from gcs_tools.replay import core
from gcs_tools.replay.events import ReaderStats
from gcs_tools.replay.tlog_source import TlogSource

QUAD106 = Path(__file__).parent / "data" / "quad106.tlog"
HOME = LocalNedFrame(-37.86, 144.76, 20.0)
SPEED_N_M_S = 1.0
GNSS_DELAY_US = 200_000


class LastFixNavigator:
    """Test double honouring the Navigator contract: reports the last fix's position.

    Lets the replay plumbing be checked with known answers independently of the filter."""

    def __init__(self, method: str, frame: LocalNedFrame) -> None:
        self.frame, self.method = frame, method
        self.pushed: list[object] = []
        self.p: np.ndarray | None = None
        self.t_us = 0

    def push(self, sample: object) -> None:
        self.pushed.append(sample)
        if isinstance(sample, GnssFix):
            self.p = self.frame.to_ned_m(sample.lat_deg, sample.lon_deg, sample.alt_m)
        elif isinstance(sample, ImuSample):
            self.t_us = sample.t_us

    def estimate(self) -> NavEstimate | None:
        if self.p is None:
            return None
        z = np.zeros(3)
        return NavEstimate(self.t_us, self.p, z, z, np.ones(9), 1.0, math.nan, self.method)

    def counters(self) -> dict[str, int]:
        return {"pushed": len(self.pushed)}


def write_flight(path: Path, seconds: float = 4.0, *, gnss: bool = True, bad_imu_every: int = 0) -> None:
    """Straight flight north at 1 m/s: HIGHRES_IMU + RAW_IMU (a second IMU source), attitude,
    SIM_STATE truth each tick, late GNSS at 5 Hz, GLOBAL_POSITION_INT at 10 Hz."""
    with TlogWriter(path) as w:
        for k in range(int(seconds * 100)):
            t_us = 10_000 * k
            stamp = 1_700_000_000_000_000 + t_us
            p = np.array([SPEED_N_M_S * t_us / 1e6, 0.0, -10.0])
            acc = np.array([math.nan if bad_imu_every and k % bad_imu_every == 5 else 0.0, 0.0, -9.81])
            w.write(stamp, mc.encode_imu(ImuSample(t_us, acc, np.zeros(3))))
            w.write(stamp, mc.mavlink.MAVLink_raw_imu_message(t_us, 0, 0, -1000, 0, 0, 0, 0, 0, 0, 0, 0))
            w.write(stamp, mc.encode_attitude(AttitudeSample(t_us, np.array([1.0, 0, 0, 0]))))
            w.write(stamp, mc.encode_truth(TruthState(t_us, p, np.array([SPEED_N_M_S, 0, 0]),
                                                      np.array([1.0, 0, 0, 0])), HOME))
            if k % 10 == 0:
                lat, lon, alt = HOME.to_geodetic(p)
                w.write(stamp, mc.mavlink.MAVLink_global_position_int_message(
                    t_us // 1000, round(lat * 1e7), round(lon * 1e7), round(alt * 1000), 0, 100, 0, 0, 0))
            if gnss and k % 20 == 0 and t_us >= GNSS_DELAY_US:
                t_valid = t_us - GNSS_DELAY_US
                lat, lon, alt = HOME.to_geodetic(np.array([SPEED_N_M_S * t_valid / 1e6, 0.0, -10.0]))
                w.write(stamp, mc.encode_gnss(GnssFix(t_valid, lat, lon, alt, 3, 12)))


def test_replay_plumbing_with_known_answers(tmp_path: Path) -> None:
    log = tmp_path / "flight.tlog"
    write_flight(log, bad_imu_every=50)
    navs: list[LastFixNavigator] = []

    def factory(method: str, frame: LocalNedFrame) -> LastFixNavigator:
        navs.append(LastFixNavigator(method, frame))
        return navs[-1]

    result = core.replay(log, "naive", home=HOME, rate_hz=0, navigator=factory)
    s = result.summary
    pushed = navs[0].pushed
    assert s["sources"] == {"imu": "HIGHRES_IMU", "attitude": "ATTITUDE_QUATERNION", "gnss": "GPS_RAW_INT"}
    assert s["samples_used"]["imu"] == 400 - 8 and s["samples_rejected"]["codec"] == {"imu_non_finite": 8}
    assert s["samples_used"]["imu_other_source_ignored"] == 400  # RAW_IMU never fed twice
    assert s["samples_used"]["gnss"] == 20 - 1
    assert len(pushed) == s["navigator"]["pushed"] == 392 + 400 + 19
    t_imu = [p.t_us for p in pushed if isinstance(p, ImuSample)]
    assert t_imu == sorted(t_imu)
    # the double lags truth by the GNSS delay plus up to one fix period (0.2 .. 0.4 s at 1 m/s)
    truth = s["errors"]["truth"]["error_horizontal_m"]
    assert 0.19 < truth["median"] < 0.41 and truth["max"] < 0.41
    assert set(s["errors"]) == {"gnss", "truth", "autopilot_estimate"}
    assert s["errors"]["truth"]["source"] == "SIM_STATE"
    ap = s["errors"]["autopilot_estimate"]
    assert ap["source"] == "GLOBAL_POSITION_INT" and ap["alignment"] == "geodetic"
    assert abs(ap["error_horizontal_m"]["median"] - truth["median"]) < 0.05


def test_cli_writes_csv_and_strict_json(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    log = tmp_path / "flight.tlog"
    write_flight(log)
    monkeypatch.setattr(core, "default_navigator",
                        lambda method, frame, *setup: LastFixNavigator(method, frame))
    out = tmp_path / "out"
    assert main(["replay", str(log), "--method", "naive", "--out", str(out), "--rate-hz", "10",
                 "--no-figures"]) == 0
    table = np.loadtxt(out / "estimates.csv", delimiter=",", skiprows=1)
    header = (out / "estimates.csv").read_text().splitlines()[0].split(",")
    assert tuple(header) == core.CSV_COLUMNS and table.shape[1] == len(core.CSV_COLUMNS)
    assert 30 <= table.shape[0] <= 40 and np.all(np.diff(table[:, 0]) >= 0.1 - 1e-9)
    summary = json.loads((out / "summary.json").read_text(), parse_constant=lambda c: pytest.fail(c))
    assert summary["nis"] == {"n": 0} and summary["beta"]["median"] == 1.0


@pytest.mark.parametrize(
    ("content", "reason"),
    [
        (b"", "no readable MAVLink frames"),
        (np.random.default_rng(5).integers(0, 256, 5000, dtype=np.uint8).tobytes(), "no readable MAVLink"),
        (None, "no usable GPS_RAW_INT 3-D fix"),
    ],
)
def test_unusable_logs_end_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], content: bytes | None, reason: str
) -> None:
    log = tmp_path / "bad.tlog"
    if content is None:
        write_flight(log, seconds=0.5, gnss=False)
    else:
        log.write_bytes(content)
    assert main(["replay", str(log), "--method", "naive", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("beliefnav: error: ") and reason in err and "\n" not in err
    assert not (tmp_path / "o").exists()


def test_a_device_instead_of_a_log_is_a_one_line_error(tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["replay", "/dev/null", "--out", str(tmp_path / "o")]) == 2  # was a FileNotFoundError
    assert "/dev/null: not a regular file (a log) or a directory" in capsys.readouterr().err


def test_synthetic_fixes_for_a_file_that_is_no_log_name_that(tmp_path: Path,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    """It named '--gnss-base log' (not given) for a README or a RINEX file replayed by mistake."""
    text = tmp_path / "notes.txt"
    text.write_text("not a flight log\n" * 20)
    assert main(["replay", str(text), "--gnss-errors", "model", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"beliefnav: error: {text}: not a flight log (no readable tlog records): nothing to make "
                   "fixes from")


def test_bad_home_is_a_one_line_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["replay", str(QUAD106), "--out", str(tmp_path), "--home", "91,0,0"]) == 2
    assert "--home" in capsys.readouterr().err


@pytest.mark.parametrize("rate", ["-1", "nan", "inf"])
def test_bad_rate_is_a_one_line_error(tmp_path: Path, capsys: pytest.CaptureFixture[str], rate: str) -> None:
    """Not silently one estimate row per IMU sample, or as fast as possible (what 0 asks for)."""
    assert main(["replay", str(QUAD106), "--out", str(tmp_path / "o"), f"--rate-hz={rate}"]) == 2
    assert f"--rate-hz {rate}: expected a rate >= 0" in capsys.readouterr().err
    assert main(["replay", str(QUAD106), "--out", str(tmp_path / "o"), f"--speed={rate}"]) == 2
    assert f"--speed {rate}: expected a factor >= 0" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_synthetic_gnss_options_without_effect_are_one_line_errors(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Each replayed the log's own fixes (or the model) as if the option had not been given."""
    given = {"--gnss-accuracy": "none", "--seed": "3", "--gnss-rate-hz": "2", "--gnss-velocity": "none",
             "--gnss-clearance-m": "20"}
    cases = [([option, value], f"{option} needs --gnss-errors") for option, value in given.items()]
    cases.append((["--gnss-errors", "model", "--gnss-series-start-s", "5"],
                  "--gnss-series-start-s goes with an error series"))
    for extra, words in cases:
        assert main(["replay", str(QUAD106), "--out", str(tmp_path / "o"), *extra]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("beliefnav: error: ") and words in err and "\n" not in err, err


class _ReadOnce:
    """quad106's events as the CLI's tlog reader (``TlogSource``) yields them, read from the file once:
    each pass yields the same (immutable) events, then ends in that reader's final state (its
    counters added to those the replay counted, its sources and references)."""

    format = TlogSource.format
    anchor = TlogSource.anchor

    def __init__(self, path: Path, read: TlogSource | None = None, events: list | None = None) -> None:
        self._read, self._events = read, events
        self._path = path
        self.stats = ReaderStats()
        self.sources, self.references = TlogSource(path).sources, {}

    def again(self) -> _ReadOnce:
        if self._events is None:
            self._read = TlogSource(self._path)
            self._events = list(self._read)
        return _ReadOnce(self._path, self._read, self._events)

    def first_fix(self) -> GnssFix | None:
        return TlogSource(self._path).first_fix()

    def __iter__(self):
        assert self._read is not None and self._events is not None
        yield from self._events
        final, st = self._read.stats, self.stats
        st.decoded.update(final.decoded)
        st.rejected.update(final.rejected)
        st.skipped.update(final.skipped)
        st.skipped_bytes, st.records, st.position, st.size = (final.skipped_bytes, final.records,
                                                              final.position, final.size)
        self.sources.update(self._read.sources)
        self.references.update(self._read.references)


def test_real_log_every_method() -> None:
    """quad106 (open sky, 668 s): finite output throughout, within metres of GNSS, β high.
    The log is read once and every method fed its events; the last method replayed from the file
    itself gives the same table, summary, tracks and GNSS record bit for bit as from the events (used
    by every method before it)."""
    estimator = pytest.importorskip("companion.estimator")
    if not hasattr(estimator, "Navigator"):
        pytest.skip("companion.estimator.Navigator has not landed yet")
    log = _ReadOnce(QUAD106)
    for method in estimator.METHODS:
        if method in ("map-beta", "map-hmm"):  # a foreign log has no map: refused, not "open sky"
            with pytest.raises(UserError, match=f"'{method}' needs the mission's map"):
                core.replay(QUAD106, method)
            continue
        result = core.replay(QUAD106, method, reader=log.again())
        s, table = result.summary, result.table
        assert s["samples_used"]["imu"] == 32936 and s["samples_used"]["gnss"] == 3339, method
        assert not s["samples_rejected"]["reader"] and not s["samples_rejected"]["codec"], method
        assert np.isfinite(table[:, :10]).all() and np.isfinite(table[:, 11:]).all(), method
        gnss = s["errors"]["gnss"]["error_horizontal_m"]
        assert gnss["median"] < 2.0 and gnss["p95"] < 5.0, (method, gnss)
        if "order" in method:
            assert s["beta"]["median"] > 0.8, (method, s["beta"])
        fed = result
    read = core.replay(QUAD106, fed.summary["method"])
    assert read.table.tobytes() == fed.table.tobytes() and read.t_us.tobytes() == fed.t_us.tobytes()
    assert _without_timing(read.summary) == _without_timing(fed.summary)
    assert read.tracks.keys() == fed.tracks.keys() and read.gnss.keys() == fed.gnss.keys()
    assert all(read.tracks[k].tobytes() == fed.tracks[k].tobytes() for k in read.tracks)
    assert all(read.gnss[f][c].tobytes() == fed.gnss[f][c].tobytes() for f in read.gnss for c in read.gnss[f])


def _without_timing(summary: dict) -> str:
    return json.dumps({k: v for k, v in summary.items() if k not in ("timing_s", "wall_s", "cpu_s",
                                                                     "realtime_factor")}, sort_keys=True)


def test_mission_option_sets_home_and_the_missions_estimator_config(tmp_path, capsys):
    """``--mission`` replays with the filter the SITL estimator ran (its ``estimator:`` section)."""
    from companion.estimator import EstimatorConfig
    from companion.mission import load_mission
    from companion.wiring import mission_estimator_config

    mission = load_mission("default")
    assert mission_estimator_config(mission) != EstimatorConfig()
    short = tmp_path / "short.tlog"
    short.write_bytes(QUAD106.read_bytes()[:400_000])

    def run(name: str, *extra: str) -> tuple[dict, np.ndarray]:
        out = tmp_path / name
        assert main(["replay", str(short), "--out", str(out), "--no-progress", "--no-figures", *extra]) == 0
        table = np.loadtxt(out / "estimates.csv", delimiter=",", skiprows=1)
        return json.loads((out / "summary.json").read_text()), table

    plain, plain_rows = run("defaults")
    h = plain["home"]
    same_home = f"{h['lat_deg']!r},{h['lon_deg']!r},{h['alt_m']!r}"
    _, tuned_rows = run("mission-config", "--mission", "default", f"--home={same_home}")
    var_v = list(core.CSV_COLUMNS).index("var_v_n_m2_s2")
    assert plain_rows.shape == tuned_rows.shape
    assert not np.allclose(plain_rows[:, var_v], tuned_rows[:, var_v])  # the mission's process noise
    # without --home the home is the mission's: Berlin, 12,000 km from this Australian log, where the
    # local frame gives wrong numbers (distance to the fixes 8.9 m instead of 0.2): refused in one line
    assert main(["replay", str(short), "--out", str(tmp_path / "far"), "--mission", "default"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and f"home {mission.frame.home_lat_deg:g}," in err
    assert "km from the log's first 3-D fix (-37.85" in err and "the log was not flown there" in err
    assert not (tmp_path / "far").exists()
    assert main(["replay", str(short), "--out", str(tmp_path / "far"), "--home", "52.52,13.405,35"]) == 2
    assert "12,093 km from the log's first 3-D fix" in capsys.readouterr().err
    assert main(["replay", str(short), "--out", str(tmp_path / "x"), "--mission", "nonexistent"]) == 2
    assert "nonexistent" in capsys.readouterr().err


def test_bad_home_is_one_line_for_replay_and_export(tmp_path, capsys):
    """replay and export share the one --home parser (companion.domain.geodesy.parse_home)."""
    from gcs_tools.cli import main

    log = str(Path(__file__).parent / "data" / "quad106.tlog")
    assert main(["replay", log, "--home", "91,0,0", "--out", str(tmp_path / "r")]) == 2
    assert "--home '91,0,0': latitude/longitude out of range" in capsys.readouterr().err
    assert main(["export", log, "--home", "1,2", "--format", "csv", "--out", str(tmp_path / "e.csv")]) == 2
    assert "--home '1,2': expected lat,lon,alt" in capsys.readouterr().err
