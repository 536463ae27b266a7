"""Variants of a smartLoc drive (gcs_tools.evaluate.tight_variants) and the receiver's C/N0 calibration
(companion.tight.cn0cal): known answers on tiny synthetic drives."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.errors import UserError
from companion.gnss import make_epoch
from companion.gnss.systems import System
from companion.tight import RawGnss, TightConfig, TightNavigator
from companion.tight.cn0cal import Cn0Calibration
from gcs_tools.evaluate import tight_variants as tv
from gcs_tools.gnss.smartloc import SmartLocInput, Truth
from tests.gnss_helpers import RX_ECEF, T0, observe, store

G, R, E = int(System.GPS), int(System.GLONASS), int(System.GALILEO)


def _drive(n: int = 10, dt: float = 0.2) -> tv.Drive:
    """n epochs at dt s from t = 100 s: a GPS, a GLONASS and a Galileo satellite; odometry every 0.1 s."""
    eps = [make_epoch(100.0 + k * dt, [G, R, E], [1, 2, 3], [2e7 + k, 2.1e7, 2.2e7],
                      pseudorange_var_m2=[1.0, 4.0, 9.0], cn0_dbhz=[40.0, 35.0, 45.0],
                      sat_pos_ecef_m=np.full((3, 3), 2e7), elevation_deg=[50.0, 30.0, 70.0],
                      corrected=True, time_base="dataset") for k in range(n)]
    t_odo = 100.0 + 0.1 * np.arange(2 * n)
    odo = np.column_stack([t_odo, np.full(2 * n, 5.0), np.zeros(2 * n)])
    t_truth = 99.0 + 0.2 * np.arange(n + 10)
    return SmartLocInput(eps, odo), Truth(t_truth, np.tile(RX_ECEF, (n + 10, 1)))


def test_variants_do_what_they_say():
    d = _drive()
    data, truth = d
    # systems
    assert all(e.system.tolist() == [G] for e in tv.apply("gps-only", d)[0].epochs)
    assert all(e.system.tolist() == [G, E] for e in tv.apply("no-glonass", d)[0].epochs)
    # odd-PRN GPS satellites as Galileo ones, ISB_M later (PRN 1 here); the others untouched
    gm = tv.apply("galileo-mix", d)[0].epochs[2]
    assert gm.system.tolist() == [E, R, E]
    assert gm.pseudorange_m[0] == data.epochs[2].pseudorange_m[0] + tv.ISB_M
    np.testing.assert_array_equal(gm.pseudorange_m[1:], data.epochs[2].pseudorange_m[1:])
    # 1 Hz from 5 Hz: the first epoch of every second (t = 100.0, 101.0)
    assert [round(e.t_gps_s, 6) for e in tv.apply("1hz", d)[0].epochs] == [100.0, 101.0]
    # C/N0 offsets, signed, composable; nothing else touched
    for name, db in (("cn0-6", -6.0), ("cn0+3", 3.0), ("cn0-10", -10.0)):
        v = tv.apply(name, d)[0]
        assert v.epochs[3].cn0_dbhz.tolist() == [40.0 + db, 35.0 + db, 45.0 + db]
        np.testing.assert_array_equal(v.epochs[3].pseudorange_m, data.epochs[3].pseudorange_m)
    both = tv.apply("cn0+3+no-odometry", d)
    assert both[0].epochs[0].cn0_dbhz[0] == 43.0 and both[0].odometry.shape == (0, 3)
    assert np.isnan(tv.apply("cn0-missing", d)[0].epochs[1].cn0_dbhz).all()
    el = tv.apply("el-missing", d)[0].epochs[1]
    assert np.isnan(el.elevation_deg).all() and el.cn0_dbhz.tolist() == [40.0, 35.0, 45.0]
    # the variance column constant (the median of the given ones: 4) or missing
    assert tv.apply("var-constant", d)[0].epochs[0].pseudorange_var_m2.tolist() == [4.0, 4.0, 4.0]
    assert np.isnan(tv.apply("var-missing", d)[0].epochs[0].pseudorange_var_m2).all()
    # halves at the middle time 100.9 s: epochs, odometry and the truth (1 s beyond) cut alike
    a, ta = tv.apply("first-half", d)
    b, tb = tv.apply("second-half", d)
    assert len(a.epochs) == 5 and len(b.epochs) == 5 and b.epochs[0].t_gps_s == pytest.approx(101.0)
    assert a.odometry[:, 0].max() < 100.9 <= b.odometry[:, 0].min()
    assert ta.t_s.max() < 101.9 and tb.t_s.min() >= 99.9
    # a 2 s gap from the middle time: 10 epochs at 0.2 s span 1.8 s, so every one from 100.9 s goes
    kept = [round(e.t_gps_s, 6) for e in tv.apply("gap-2s", d)[0].epochs]
    assert kept == [100.0, 100.2, 100.4, 100.6, 100.8]
    g = tv.gap(_drive(40), start_s=102.0)[0]  # 8 s: the 10 epochs in [102, 104) removed
    assert len(g.epochs) == 30 and not any(102.0 <= e.t_gps_s < 104.0 for e in g.epochs)
    # odometry rates (10 Hz here): 50 Hz interpolated onto its grid; 1 Hz the first sample of every second
    fast = tv.apply("odo-50hz", d)[0].odometry
    assert len(fast) == 96 and np.allclose(np.diff(fast[:, 0]), 0.02) and (fast[:, 1] == 5.0).all()
    slow = tv.apply("odo-1hz", d)[0].odometry
    assert slow[:, 0].tolist() == [100.0, 101.0] and slow.shape[1] == 3
    # a time shift moves epochs, odometry and truth together
    s, ts = tv.apply("time-shift", d)
    assert s.epochs[0].t_gps_s == 100.0 + tv.TIME_SHIFT_S and s.odometry[0, 0] == 100.0 + tv.TIME_SHIFT_S
    assert ts.t_s[0] == 99.0 + tv.TIME_SHIFT_S
    # the input is not modified
    assert data.epochs[0].cn0_dbhz.tolist() == [40.0, 35.0, 45.0] and len(data.odometry) == 20
    assert truth.t_s[0] == 99.0
    with pytest.raises(UserError, match="unknown variant 'glonass-only'"):
        tv.apply("glonass-only", d)


def test_cn0_calibration_quantile_and_offset():
    cal = Cn0Calibration(0.5, 45.0, 0.0)
    assert cal.offset_db() == 0.0 and math.isnan(cal.level_dbhz())
    cal.add(np.array([40.0, 40.0, 50.0, 50.0, math.nan]))  # the median: the edge between the 40 and 50 bins
    assert cal.n == 4 and cal.level_dbhz() == pytest.approx(40.5)
    cal = Cn0Calibration(0.9, 45.0, 0.0)
    cal.add(np.full(100, 48.0))  # one bin [47.5, 48.5): its 90 % point 48.4
    assert cal.level_dbhz() == pytest.approx(48.4) and cal.offset_db() == pytest.approx(3.4)
    np.testing.assert_allclose(cal.calibrated(np.array([48.0, 30.0])), [44.6, 26.6])
    shrunk = Cn0Calibration(0.9, 45.0, 100.0)  # shrunk towards the reference while few values are seen
    shrunk.add(np.full(100, 48.0))
    assert shrunk.offset_db() == pytest.approx(1.7)


def _navigator_run(offset_db: float, cfg: TightConfig) -> tuple[TightNavigator, list]:
    """A receiver at rest seeing the synthetic sky (C/N0 30-50 dB-Hz by elevation) plus ``offset_db``."""
    from companion.domain.samples import AttitudeSample, ImuSample

    sky = store()
    nav = TightNavigator(cfg, "second-order", ephemerides=sky)
    q, f = np.array([1.0, 0.0, 0.0, 0.0]), np.array([0.0, 0.0, -9.80665])
    prepared = []
    for k in range(150):
        t_us = 1_000_000 + 20_000 * k
        nav.push(AttitudeSample(t_us, q))
        nav.push(ImuSample(t_us, f, np.zeros(3)))
        if k % 10 == 0:
            ep, _ = observe(sky, T0 + k * 0.02, RX_ECEF)
            nav.push(RawGnss(t_us, ep.replace(cn0_dbhz=ep.cn0_dbhz + offset_db)))
            m = nav.engine.entries[-1].meas
            if m is not None:  # (the first epoch starts the filter: an anchor)
                prepared.append(m)
    return nav, prepared


def test_a_receivers_c_n0_offset_changes_nothing_once_calibrated():
    """Another receiver reporting every C/N0 8 dB lower: with the calibration (no shrinkage) the prepared
    σ model and prior, hence the estimate and its covariance, are the reference receiver's; with the
    calibration off (absolute C/N0) they are not."""
    for cfg, same in ((TightConfig(cn0_calibration_prior_obs=0.0), True),
                      (TightConfig(cn0_calibration_ref_dbhz=math.nan), False)):
        ref, m_ref = _navigator_run(0.0, cfg)
        low, m_low = _navigator_run(-8.0, cfg)
        assert len(m_ref) == len(m_low) >= 14
        r_ref = np.concatenate([m.r_model_m2 for m in m_ref])
        r_low = np.concatenate([m.r_model_m2 for m in m_low])
        th_ref = np.concatenate([m.theta_prior for m in m_ref])
        th_low = np.concatenate([m.theta_prior for m in m_low])
        e_ref, e_low = ref.estimate(), low.estimate()
        assert e_ref is not None and e_low is not None
        if same:
            np.testing.assert_allclose(r_low, r_ref, rtol=1e-9)
            np.testing.assert_allclose(th_low, th_ref, atol=1e-9)
            # (1e-5: the reported accuracy's snapshot floor takes the correlation c of the epochs' own
            # positions from their steps, here sub-millimetre (noise-free ranges: a scatter of 5e-7 m²), so
            # the weights' 1e-9 differences show in c at 3e-6)
            np.testing.assert_allclose(e_low.cov_diag, e_ref.cov_diag, rtol=1e-5)
            np.testing.assert_allclose(e_low.p_ned_m, e_ref.p_ned_m, atol=1e-6)
        else:  # absolute C/N0: 8 dB weaker is 10^0.8 times the variance, the prior 1.2 lower
            assert np.median(r_low / r_ref) > 4.0 and np.median(th_ref - th_low) == pytest.approx(1.2)
            assert not np.allclose(e_low.cov_diag, e_ref.cov_diag, rtol=1e-3)
