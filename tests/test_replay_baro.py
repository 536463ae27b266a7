"""The replay readers' barometer: ULog vehicle_air_data baro_alt_meter, DataFlash BARO Alt, tlog HIGHRES_IMU
pressure_alt (bit 11) ride on the next IMU sample (``ImuSample.pressure_alt_m``); a log without one has
none."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from companion.domain.samples import ImuSample
from gcs_tools.replay.dataflash import DataFlashSource
from gcs_tools.replay.tlog_source import TlogSource
from gcs_tools.replay.ulog import ULogSource

DATA = Path(__file__).parent / "data"


def _baro(src) -> tuple[int, np.ndarray]:  # type: ignore[no-untyped-def]
    imu = [e for e in src if type(e) is ImuSample]
    return len(imu), np.array([e.pressure_alt_m for e in imu if e.pressure_alt_m is not None])


def test_ulog_air_data_is_px4s_pressure_altitude_on_the_next_imu_sample():
    src = ULogSource(DATA / "sample_px4_events.ulg")
    n_imu, alt = _baro(src)
    # one per air-data message that an IMU sample followed (two before one IMU sample: the later kept)
    assert 0 < len(alt) <= src.stats.decoded["baro"] == 623 and n_imu == src.stats.decoded["imu"]
    assert np.all(np.abs(alt - 488.0) < 5.0)  # PX4's pressure altitude, standard atmosphere (AMSL-like)


def test_dataflash_baro_is_ardupilots_height_above_its_ground_calibration():
    src = DataFlashSource(DATA / "arducopter_sitl_hover.bin")
    _, alt = _baro(src)
    assert 0 < len(alt) <= src.stats.decoded["baro"] == 772
    assert abs(alt[0]) < 0.5 and np.isfinite(alt).all()  # zeroed on the ground at start


def test_a_tlog_without_bit_11_has_no_barometer():
    n_imu, alt = _baro(TlogSource(DATA / "quad106.tlog"))  # fields_updated 63, abs_pressure 1013.25
    assert n_imu > 30_000 and len(alt) == 0
