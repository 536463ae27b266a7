"""The tight filter's IMU check on real flights (``python -m gcs_tools.evaluate.real_tight``): the IMU
variants' readers, the metrics' known answers, the dead reckoning against a synthetic flight's truth,
and bad arguments."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from ansfl_helpers import smartloc_drive_slice, write_flight
from scipy.spatial.transform import Rotation

from companion.domain.samples import AttitudeSample, ImuSample
from gcs_tools.evaluate import real_tight as rt
from gcs_tools.replay.core import CSV_COLUMNS


class _Reader:
    format = "test"
    references: dict[str, object] = {}

    def __init__(self, events: list[object]) -> None:
        self.events, self.stats, self.sources = events, object(), {"imu": "x", "attitude": "y"}

    def describe_empty(self) -> str:
        return "empty"

    def __iter__(self):
        return iter(self.events)


def _events() -> list[object]:
    q = Rotation.from_euler("ZYX", [30.0, 5.0, -3.0], degrees=True).as_quat()  # x, y, z, w
    return [AttitudeSample(10, np.array([q[3], q[0], q[1], q[2]])),
            ImuSample(10, np.array([0.5, -0.2, -9.7]), np.array([0.01, 0.02, 0.03]))]


def test_imu_mode_passes_every_event_unchanged():
    ev = _events()
    assert list(rt.ImuVariant(_Reader(ev), "imu", 7.0)) == ev  # the same objects, in order


def test_level_mode_is_a_level_zero_acceleration_input():
    att, imu = rt.ImuVariant(_Reader(_events()), "level")
    np.testing.assert_array_equal(att.q_ned_frd, [1.0, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(imu.acc_frd_m_s2, [0.0, 0.0, -9.80665])
    np.testing.assert_array_equal(imu.gyro_frd_rad_s, [0.0, 0.0, 0.0])
    assert (att.t_us, imu.t_us) == (10, 10)


def test_heading_mode_turns_the_attitude_about_down_by_yaw():
    att, imu = rt.ImuVariant(_Reader(_events()), "heading", 12.0)
    w, x, y, z = att.q_ned_frd
    yaw, pitch, roll = Rotation.from_quat([x, y, z, w]).as_euler("ZYX", degrees=True)
    np.testing.assert_allclose([yaw, pitch, roll], [42.0, 5.0, -3.0], atol=1e-9)  # heading +12°, tilt kept
    np.testing.assert_array_equal(imu.acc_frd_m_s2, [0.5, -0.2, -9.7])  # the IMU sample as recorded


def test_quaternion_product_known_answer():
    q90 = np.array([math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4)])  # 90° about down
    r = rt.quat_mul(q90, q90)
    np.testing.assert_allclose(r, [0.0, 0.0, 0.0, 1.0], atol=1e-12)  # 180° about down


def test_nees_and_model_sigma_known_answers():
    err, var = np.array([[1.0, 2.0], [3.0, 0.0]]), np.array([[1.0, 4.0], [9.0, 1.0]])
    np.testing.assert_allclose(rt.nees(err, var), [2.0, 1.0])
    assert rt.model_velocity_sigma(4.0, 0.5, 0.3, 0.4) == pytest.approx(math.sqrt(0.25 * 4 + 0.25 * 16))


def test_against_truth_known_errors():
    t_tr = np.arange(0.0, 30.0, 0.1)
    truth = np.column_stack((t_tr, 2.0 * t_tr, np.zeros_like(t_tr), np.zeros_like(t_tr)))  # 2 m/s north
    t_us = np.rint(np.arange(0.0, 30.0, 0.05) * 1e6).astype(np.int64)
    table = np.zeros((len(t_us), len(CSV_COLUMNS) - 1))
    col = {c: i for i, c in enumerate(CSV_COLUMNS[1:])}
    t = t_us * 1e-6
    table[:, col["p_n_m"]] = 2.0 * t + 3.0  # 3 m north of the truth, 4 m east
    table[:, col["p_e_m"]] = 4.0
    table[:, col["v_n_m_s"]] = 2.5  # 0.5 m/s too fast
    for c, v in (("var_p_n_m2", 9.0), ("var_p_e_m2", 16.0), ("var_v_n_m2_s2", 0.25), ("var_v_e_m2_s2", 1.0)):
        table[:, col[c]] = v
    m = rt.against_truth(t_us, table, truth)
    for k in ("median", "p95", "max", "median_0_10", "median_10_20", "median_20_end"):
        assert m[k] == pytest.approx(5.0)
    assert m["velocity_error_rms"] == pytest.approx(0.5)
    assert m["velocity_sigma_rms"] == pytest.approx(math.sqrt(1.25))
    assert m["nees_velocity"] == pytest.approx(1.0) and m["nees_position"] == pytest.approx(2.0)


def test_dead_reckoning_of_an_exact_imu_is_exact_and_a_heading_error_drifts(tmp_path: Path):
    write_flight(tmp_path / "exact", seconds=30.0, offset_s=0.2)
    write_flight(tmp_path / "heading", seconds=30.0, offset_s=0.2, heading_error_deg=10.0)
    exact, turned = rt.dead_reckoning(tmp_path / "exact"), rt.dead_reckoning(tmp_path / "heading")
    rms_exact = [float(np.sqrt(np.mean(exact[T] ** 2))) for T in rt.HORIZONS_S]
    rms_turned = [float(np.sqrt(np.mean(turned[T] ** 2))) for T in rt.HORIZONS_S]
    assert max(rms_exact) < 0.1  # the truth's ±0.2 s central differences of a curving track (measured 0.06)
    # 10° of heading: 2 sin 5° ≈ 0.17 × the velocity change over T (this track's: up to ~4 m/s)
    assert max(rms_turned) > 0.4 and max(rms_turned) > 5 * max(rms_exact)


def test_bad_arguments_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]):
    assert rt.main(["--errors", "model", "--out", str(tmp_path / "o")]) == 2
    assert rt.main(["--errors", "smartloc-sats:x_Input.txt", "--variants", "imu,bogus",
                    "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(line.startswith("real_tight: error: ") for line in err)


@pytest.fixture(scope="module")
def drive_and_flight(tmp_path_factory: pytest.TempPathFactory) -> tuple[str, Path]:
    """The smartLoc drive's first minute (as tests/test_transplant.py cuts it) and a 20 s synthetic flight."""
    out = tmp_path_factory.mktemp("smartloc")
    drive = smartloc_drive_slice(out, 60.0)
    write_flight(out / "f", seconds=20.0, offset_s=0.2, seed=3)
    return f"smartloc-sats:{drive}", out / "f"


def test_the_imu_variant_is_the_campaigns_tight_row_and_the_others_differ(drive_and_flight: tuple[str, Path]):
    from gcs_tools.evaluate import real

    errors, flight = drive_and_flight
    campaign = real.run([flight], [errors], ["reported"], ["naive"], [0], velocity_std_m_s=None)
    row = next(r for r in campaign["runs"] if r["row"] == "tight-second-order")
    runs = {v: rt.run_variant(flight, errors, 0, v, None) for v in ("imu", "gnss-only", "imu-clean")}
    # the same replay: its errors from the estimate rows at the truth samples, the campaign's from the
    # replay's own comparison (the same samples): equal to the estimate rows' interpolation
    assert runs["imu"]["median"] == pytest.approx(row["median"], abs=0.02)
    assert runs["imu"]["max"] == pytest.approx(row["max"], abs=0.02)
    assert runs["gnss-only"]["median"] != runs["imu"]["median"]
    assert runs["imu-clean"]["median"] < 0.5 * runs["imu"]["median"]  # Berlin's residuals removed
    assert runs["imu"]["heading_error_deg"] == pytest.approx(0.0, abs=0.5)  # the synthetic flight's heading


def test_placement_reads_the_flights_windows_of_the_drive(drive_and_flight: tuple[str, Path]):
    errors, flight = drive_and_flight
    rows = rt.placement(errors, [flight], [0, 1])
    assert rows[0]["window"] == "whole drive" and len(rows) == 3
    for r in rows[1:]:
        assert 18.5 < r["span_s"] < 20.0 and 0.0 <= r["start_s"] <= 60.0 - r["span_s"]
        for name in ("spp", "drive_whole", "drive_restarted"):
            assert 0.0 < r[f"{name}_median"] <= r[f"{name}_p95"]
