"""The tightly coupled filter's barometer (companion.tight.engine ``push_baro``, the baro offset state
``model.I_BARO``): Jacobian, C core with the 22nd state, out-of-sequence exactness, gate, consistency on the
filter's own model, bit-identity without a barometer, and the navigator's path from ``ImuSample``."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import chi2

from companion.domain.samples import AttitudeSample, ImuSample
from companion.mavlink import codec as mc
from companion.tight import TightConfig, TightNavigator, _tight, model
from companion.tight.engine import Baro, TightEngine
from companion.tight.model import I_BARO, N_STATE, N_STATE_BARO
from tests.gnss_helpers import hold_at_rest
from tests.test_mavlink_codec import wire
from tests.test_tight import (
    FRAME,
    STORE,
    _feed,
    _numeric_jacobian,
    _sats,
    _state,
    _synthetic_epochs,
    c_core_inputs,
)

PERIOD_US = 200_000  # epochs and baro samples


def test_baro_jacobian_matches_finite_differences_and_the_pseudoranges_ignore_b_baro():
    rng = np.random.default_rng(1)
    x = np.r_[_state(rng), rng.normal(0, 30)]
    pred, h = model.baro_height(x)
    assert pred == pytest.approx(x[I_BARO] - x[2], abs=0)
    num = _numeric_jacobian(lambda z: np.array([model.baro_height(z)[0]]), x, np.full(N_STATE_BARO, 1e-3))
    np.testing.assert_allclose(num[0], h, atol=1e-9)
    sysv, _, pos, vel = _sats()
    _, H, _ = model.pseudorange(x, FRAME, pos, model.SLOT_OF[sysv])
    _, Hr = model.range_rate(x, FRAME, pos, vel)
    assert H.shape == Hr.shape == (len(sysv), N_STATE_BARO)
    assert not H[:, I_BARO].any() and not Hr[:, I_BARO].any()


def test_c_core_with_the_baro_state_equals_the_numpy_forms():
    rng = np.random.default_rng(2)
    P, T, nA, nB, live, q = c_core_inputs(rng, N_STATE_BARO)
    q_baro = 0.04
    F = model.transition(T, nA.ravel(), nB.ravel(), live, n=N_STATE_BARO)
    want = F @ P @ F.T + model.process_noise(T, nA.ravel(), live, *q, q_baro=q_baro, n=N_STATE_BARO)
    no_hold = (None, None, 0.0, 0.0, 0.0, 0.0)
    got = _tight.predict_cov(P, T, nA.ravel(), nB.ravel(), live, *q, True, *no_hold, q_baro)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
    # the 21-state block of a 22-state prediction is the 21-state prediction of that block, bit for bit,
    # when b_baro is uncorrelated (the C core's sums only gain exact zeros)
    P0 = P.copy()
    P0[I_BARO, :N_STATE] = P0[:N_STATE, I_BARO] = 0.0
    got0 = _tight.predict_cov(P0, T, nA.ravel(), nB.ravel(), live, *q, True)
    got21 = _tight.predict_cov(P0[:N_STATE, :N_STATE], T, nA.ravel(), nB.ravel(), live, *q, True)
    assert np.array_equal(got0[:N_STATE, :N_STATE], got21)
    with pytest.raises(ValueError, match="shapes"):
        _tight.predict_cov(np.eye(23), T, nA.ravel(), nB.ravel(), live, *q, True)
    sysv, _, pos, vel = _sats()
    slot = model.SLOT_OF[sysv]
    x = np.r_[_state(rng), 12.0]
    z = model.pseudorange(x, FRAME, pos, slot)[0] + rng.normal(0, 5, len(slot))
    r0, C = FRAME.r0_ecef_m, FRAME.c_ecef_ned
    y, H, HP, s0, _ = _tight.innovations(x, P, r0, C, pos, slot.astype(float), z)
    pred, H_ref, _ = model.pseudorange(x, FRAME, pos, slot)
    np.testing.assert_allclose(H, H_ref, atol=1e-12)
    np.testing.assert_allclose(HP, H_ref @ P, rtol=1e-12, atol=1e-9)
    used = np.ones(len(y))
    r = rng.uniform(4, 100, len(y))
    z_rate = model.range_rate(x, FRAME, pos, vel)[0] + rng.normal(0, 0.3, len(y))
    r_rate = np.full(len(y), 0.25)
    x_c, P_c, _, n_rate = _tight.update(x, P, H, HP, y, r, used, r0, C, pos, vel, z_rate, r_rate, 1e6)
    _, Hr = model.range_rate(x, FRAME, pos, vel)
    Hs = np.vstack((H_ref, Hr))
    ys = np.concatenate((y, z_rate - model.range_rate(x, FRAME, pos, vel)[0]))
    S = Hs @ P @ Hs.T + np.diag(np.concatenate((r, r_rate)))
    K = P @ Hs.T @ np.linalg.inv(S)
    assert n_rate == len(y)
    np.testing.assert_allclose(x_c, x + K @ ys, rtol=1e-9, atol=1e-7)
    np.testing.assert_allclose(P_c, P - K @ Hs @ P, rtol=1e-9, atol=1e-9)


def _baro_truth(rng: np.random.Generator, truth: list[np.ndarray], cfg: TightConfig, b0: float,
                dt_s: float = 0.2) -> tuple[np.ndarray, np.ndarray]:
    """(barometer heights, true b_baro) at the epochs' times: −p_D + b, b a random walk of the filter's
    density from ``b0``, white noise of the filter's σ."""
    n = len(truth)
    b = b0 + np.cumsum(np.r_[0.0, rng.normal(0, cfg.sigma_baro_drift_m_sqrt_s * math.sqrt(dt_s), n - 1)])
    h = np.array([-x[2] for x in truth]) + b + rng.normal(0, cfg.sigma_baro_m, n)
    return h, b


def _feed_baro(cfg: TightConfig, epochs, heights, t_us, order, eng: TightEngine | None = None,
               baro_offset_us: int = 100_000) -> TightEngine:
    """As test_tight._feed, with a barometer sample ``baro_offset_us`` after each epoch, pushed as soon as
    the IMU passed it (the barometer in time order; the epochs in ``order``, a late one after later ones)."""
    baro_next = 0

    def on_imu(eng: TightEngine, pushed: int) -> None:
        nonlocal baro_next
        while baro_next < len(heights) and t_us[baro_next] + baro_offset_us <= pushed:
            if eng.entries:  # (before the start a sample is dropped: in order it would be too)
                eng.push_baro(t_us[baro_next] + baro_offset_us, float(heights[baro_next]))
            baro_next += 1

    return _feed(cfg, "naive", epochs, t_us, order, eng=eng, on_imu=on_imu)


def test_out_of_sequence_epochs_with_baro_equal_in_order():
    cfg = TightConfig.for_ground_vehicle()
    rng = np.random.default_rng(4)
    epochs, truth = _synthetic_epochs(rng, cfg, 40, bias={0: (30.0, 10)})
    heights, _ = _baro_truth(rng, truth, cfg, 57.0)
    t_us = [1_000_000 + PERIOD_US * k for k in range(len(epochs))]
    a = _feed_baro(cfg, epochs, heights, t_us, list(range(len(epochs))))
    order = list(range(len(epochs)))
    for k in range(2, len(order) - 3, 5):  # several epochs arrive after later ones (and later baro samples)
        order[k], order[k + 3] = order[k + 3], order[k]
    b = _feed_baro(cfg, epochs, heights, t_us, order)
    assert b.counts["gnss_refused"] > 0 and a.counts["baro_started"] >= 1 and a.counts["baro_fused"] > 20
    assert len(a.entries) == len(b.entries)
    assert sum(isinstance(e.meas, Baro) for e in b.entries) > 3  # baro entries inside the history
    for ea, eb in zip(a.entries, b.entries, strict=True):
        assert ea.t_us == eb.t_us and len(ea.x) == len(eb.x)
        np.testing.assert_allclose(eb.x, ea.x, rtol=0, atol=1e-9)
        np.testing.assert_allclose(eb.P, ea.P, rtol=0, atol=1e-9)
    assert len(a.entries[-1].x) == N_STATE_BARO


# NaN (the codec's for a damaged field), and finite values no atmosphere gives (a damaged log's: the
# replay readers pass ULog/DataFlash values as they are)
@pytest.mark.parametrize("bad", [math.nan, math.inf, 1e30, -1e6])
def test_no_barometer_or_only_rejected_samples_leave_the_filter_bit_identical(bad):
    cfg = TightConfig.for_ground_vehicle()
    rng = np.random.default_rng(6)
    epochs, _ = _synthetic_epochs(rng, cfg, 20)
    t_us = [1_000_000 + PERIOD_US * k for k in range(len(epochs))]
    order = list(range(len(epochs)))
    a = _feed_baro(cfg, epochs, [], t_us, order)
    b = _feed_baro(cfg, epochs, np.full(len(epochs), bad), t_us, order)
    assert b.counts["baro_rejected_invalid"] > 0 and "baro_started" not in b.counts
    for ea, eb in zip(a.entries, b.entries, strict=True):
        assert len(eb.x) == N_STATE and np.array_equal(ea.x, eb.x) and np.array_equal(ea.P, eb.P)


def _first_baro(cfg: TightConfig, epochs, t_us, height_m: float):  # type: ignore[no-untyped-def]
    """(engine, the prediction (x, P) the first baro sample met, its entry): three epochs, then the sample."""
    eng = TightEngine(cfg, "naive", frame=FRAME)
    eng.push_acc(0, 0.0, 0.0, 0.0)
    for k in range(3):
        eng.push_acc(t_us[k], 0.0, 0.0, 0.0)
        eng.push_epoch(t_us[k], epochs[k])
    before = eng.entries[-1]
    eng.push_acc(t_us[2] + 20_000, 0.0, 0.0, 0.0)
    eng.push_baro(t_us[2] + 20_000, height_m)
    after = eng.entries[-1]
    x, P = eng._predict(before, after.t_us, after.ints)
    return eng, x, P, after


def test_baro_starts_as_a_relative_height_and_gates_an_outlier():
    cfg = TightConfig.for_ground_vehicle()
    rng = np.random.default_rng(8)
    epochs, truth = _synthetic_epochs(rng, cfg, 30)
    heights, _ = _baro_truth(rng, truth, cfg, -120.0)
    heights[20] += 40.0  # a pressure step (a door, a gust): 80 σ
    t_us = [1_000_000 + PERIOD_US * k for k in range(len(epochs))]
    eng = _feed_baro(cfg, epochs, heights, t_us, list(range(len(epochs))))
    c = eng.counts
    assert c["baro_started"] == 1 and c["baro_rejected_gate"] == 1
    # the start: b = h + p_D, its variance P_DD + R and its covariance P_D· (the height is not moved)
    _, x_pred, P_pred, after = _first_baro(cfg, epochs, t_us, 33.0)
    assert after.x[I_BARO] == 33.0 + x_pred[2]
    np.testing.assert_array_equal(after.x[:N_STATE], x_pred)
    assert after.P[I_BARO, I_BARO] == P_pred[2, 2] + cfg.sigma_baro_m**2
    np.testing.assert_array_equal(after.P[I_BARO, :N_STATE], P_pred[2])


def test_baro_nees_and_nis_within_chi2_bounds_on_the_filters_own_model():
    cfg = TightConfig.for_ground_vehicle(sigma_clock0_m=1e3)
    rng = np.random.default_rng(9)
    runs, n = 30, 60
    innov: list[float] = []

    class Recording(TightEngine):
        def _fuse_baro(self, prev, t_us, m, x, P, ints):  # type: ignore[no-untyped-def]
            if len(x) == N_STATE_BARO:
                pred, h = model.baro_height(x)
                innov.append((m.height_m - pred) ** 2 / (float(h @ P @ h) + m.r_m2))
            return super()._fuse_baro(prev, t_us, m, x, P, ints)

    nees, nees_v = [], []
    for _ in range(runs):
        epochs, truth = _synthetic_epochs(rng, cfg, n)
        heights, b = _baro_truth(rng, truth, cfg, rng.normal(0, 100))
        t_us = [1_000_000 + PERIOD_US * k for k in range(n)]
        eng = _feed_baro(cfg, epochs, heights, t_us, list(range(n)), eng=Recording(cfg, "naive", frame=FRAME),
                         baro_offset_us=0)
        e = eng.entries[-1]  # the last epoch, after the last baro sample at its time
        assert e.t_us == t_us[-1] and len(e.x) == N_STATE_BARO
        idx = [0, 1, 2, 3, 4, 5, I_BARO]
        d = np.r_[(e.x[:N_STATE] - truth[-1])[0:6], e.x[I_BARO] - b[-1]]
        nees.append(float(d @ np.linalg.solve(e.P[np.ix_(idx, idx)], d)))
        nees_v.append(float(d[2] ** 2 / e.P[2, 2]))
    lo, hi = chi2.ppf([0.005, 0.995], 7 * runs) / runs
    assert lo < np.mean(nees) < hi, np.mean(nees)
    lo, hi = chi2.ppf([0.005, 0.995], runs) / runs
    assert lo < np.mean(nees_v) < hi, np.mean(nees_v)
    m = len(innov)
    lo, hi = chi2.ppf([0.005, 0.995], m) / m
    assert m > runs * (n - 5) and lo < np.mean(innov) < hi, np.mean(innov)


def test_navigator_takes_highres_imus_pressure_altitude_one_per_period():
    cfg = TightConfig()
    nav = TightNavigator(cfg, "second-order", ephemerides=STORE)
    hold_at_rest(nav, STORE, 100)  # 2 s: the filter started
    q, f = np.array([1.0, 0.0, 0.0, 0.0]), np.array([0.0, 0.0, -9.80665])
    t0 = 1_000_000 + 20_000 * 100
    for k in range(50):  # 1 s at 50 Hz with a barometer 80 m above the filter's height
        t = t0 + 20_000 * k
        nav.push(AttitudeSample(t, q))
        # through HIGHRES_IMU's bytes, as the companion receives it (codec.decode_imu: bit 11)
        s = ImuSample(t, f, np.zeros(3), 80.0 + 0.01 * k)
        nav.push(mc.decode_imu(wire(mc.encode_imu(s, 1003.0, 30.0))))
    nav.push(mc.decode_imu(wire(mc.encode_imu(ImuSample(t0 + 20_000 * 50, f, np.zeros(3), 1e6)))))  # absurd
    c = nav.counters()
    assert c["baro_started"] == 1 and c["baro_samples"] == 5 and c["baro_fused"] == 4  # one per 0.2 s
    assert c["baro_rejected_invalid"] == 1
    e = nav.engine.entries[-1]
    # the barometer's height as predicted follows it (its climb of 0.4 m partly taken by the datum)
    assert len(e.x) == N_STATE_BARO and model.baro_height(e.x)[0] == pytest.approx(80.0 + 0.01 * 40, abs=0.3)
    # a log's HIGHRES_IMU without bit 11 (fields_updated 63, a constant 1013.25 hPa) has no barometer
    logged = mc.mavlink.MAVLink_highres_imu_message(t0 + 20_000 * 60, *f, 0, 0, 0, 0, 0, 0, 1013.25, 0, 0, 0,
                                                    63, 0)
    nav.push(mc.decode_imu(wire(logged)))
    assert nav.counters()["baro_samples"] == 5


def test_a_known_datum_starts_b_baro_absolute_and_fuses_the_first_sample():
    cfg = TightConfig.for_ground_vehicle(baro_datum_m=40.0, baro_datum_sigma_m=2.0)
    rng = np.random.default_rng(10)
    epochs, _ = _synthetic_epochs(rng, cfg, 3)
    t_us = [1_000_000 + PERIOD_US * k for k in range(3)]
    eng, x, P, after = _first_baro(cfg, epochs, t_us, 45.0)
    # the update of [x, 40] with P ⊕ 2² by h = 45: the known answer of a scalar Kalman update
    xa, Pa = np.r_[x, 40.0], np.zeros((N_STATE_BARO, N_STATE_BARO))
    Pa[:N_STATE, :N_STATE], Pa[I_BARO, I_BARO] = P, 4.0
    _, h = model.baro_height(xa)
    s = h @ Pa @ h + cfg.sigma_baro_m**2
    k = Pa @ h / s
    np.testing.assert_allclose(after.x, xa + k * (45.0 - (40.0 - x[2])), rtol=0, atol=1e-9)
    np.testing.assert_allclose(after.P, Pa - np.outer(k, Pa @ h), rtol=0, atol=1e-9)
    assert eng.counts["baro_fused"] == 1 and after.P[2, 2] < P[2, 2]  # the height moved
    # a first sample far from the filter's height (its start, a single-point solution, tens of metres off in a
    # canyon) is fused all the same: it sets the height; a later one as far is gated
    eng, x, P, after = _first_baro(cfg, epochs, t_us, 40.0 - x[2] + 500.0)
    assert eng.counts["baro_fused"] == 1 and abs(after.x[2] - x[2]) > 100.0
    eng.push_acc(t_us[2] + 40_000 + PERIOD_US, 0.0, 0.0, 0.0)
    eng.push_baro(t_us[2] + 40_000 + PERIOD_US, 40.0 - after.x[2] + 500.0)
    assert eng.counts["baro_rejected_gate"] == 1
    with pytest.raises(ValueError, match="baro_datum"):
        TightConfig(baro_datum_m=math.inf).validate()


def test_a_datum_step_is_gated_then_restarts_the_datum_and_late_epochs_still_equal_in_order():
    """ArduPilot SITL's pressure_alt is 0 until its barometer is calibrated, then its altitude (a 97 m
    step). The step is gated, and after baro_restart_s of gated samples b_baro re-starts relative (once),
    the height untouched; the barometer is fused again after it; late epochs re-fused equal in order."""
    cfg = TightConfig.for_ground_vehicle()
    rng = np.random.default_rng(12)
    epochs, truth = _synthetic_epochs(rng, cfg, 80)
    heights, _ = _baro_truth(rng, truth, cfg, 0.0)
    heights[20:] += 97.0
    t_us = [1_000_000 + PERIOD_US * k for k in range(len(epochs))]
    a = _feed_baro(cfg, epochs, heights, t_us, list(range(len(epochs))))
    c = a.counts
    assert c["baro_datum_restarts"] == 1
    restart_samples = int(cfg.baro_restart_s / cfg.baro_period_s)
    assert restart_samples <= c["baro_rejected_gate"] <= restart_samples + 1
    after = t_us[20] + cfg.baro_restart_s * 1e6
    fused_after = [e for e in a.entries if isinstance(e.meas, Baro) and e.t_us > after]
    assert fused_after and all(e.baro_gated_since_us == -1 for e in fused_after[1:])
    last = a.entries[-1]
    assert abs(last.x[I_BARO] - 97.0) < 5.0 and abs(last.x[2] - truth[-1][2]) < 5.0
    order = list(range(len(epochs)))
    for k in range(2, len(order) - 3, 5):
        order[k], order[k + 3] = order[k + 3], order[k]
    b = _feed_baro(cfg, epochs, heights, t_us, order)
    assert b.counts["gnss_refused"] > 0 and b.counts["baro_datum_restarts"] >= 1
    assert len(a.entries) == len(b.entries)
    for ea, eb in zip(a.entries, b.entries, strict=True):
        assert ea.t_us == eb.t_us and ea.baro_gated_since_us == eb.baro_gated_since_us
        np.testing.assert_allclose(eb.x, ea.x, rtol=0, atol=1e-9)
        np.testing.assert_allclose(eb.P, ea.P, rtol=0, atol=1e-9)
