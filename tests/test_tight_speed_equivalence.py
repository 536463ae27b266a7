"""The tight filter's speed changes keep every bit: the C update (``_tight.update``), which sums the range
rates' H P and S = H P Hᵀ over H's nonzero columns only, against a plain-Python transcription of its dense
loops (IEEE double arithmetic in the same order: what the C core computed before); the satellite cache's
step in C (``_tight.carry_states``) against the numpy expressions it replaced; ``GnssEpoch.replace``'s
slot path against ``dataclasses.replace``; no import inside the first epochs; ``prepare_epoch``'s C path
(``_tight.prepare``) against its numpy form, to 1e-12 relative (the C library's ``asin``, ``atan2`` and
``pow`` and unfused 3-term dot products against numpy's own, which differ in the last bits)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from companion.gnss.observations import GnssEpoch, make_epoch
from companion.tight import _tight, engine, model
from companion.tight.config import TightConfig
from companion.tight.model import I_DRIFT, N_STATE
from tests.gnss_helpers import RX_ECEF, T0, observe
from tests.test_tight import FRAME, STORE, _sats, _state, c_core_inputs

C_M_S = 299792458.0
W_C = 7.2921151467e-5 / C_M_S


# The numpy forms the C functions replaced (what the filter computed before), the references below.
def _cn0_add_numpy(cal, cn0_dbhz: np.ndarray) -> None:
    from companion.tight.cn0cal import BIN_DB, HI_DBHZ, LO_DBHZ

    c = np.asarray(cn0_dbhz, dtype=float)
    c = np.minimum(np.maximum(c[np.isfinite(c)], LO_DBHZ), HI_DBHZ)  # np.clip's values
    if c.size:
        idx = np.minimum(((c - cal._edges[0]) / BIN_DB).astype(int), len(cal._hist) - 1)
        cal._hist += np.bincount(idx, minlength=len(cal._hist))
        cal.n += int(c.size)


def _cn0_level_numpy(cal) -> float:
    from companion.tight.cn0cal import BIN_DB

    if cal.n == 0:
        return float("nan")
    cum = np.cumsum(cal._hist)
    target = cal.quantile * cal.n
    i = min(int(np.searchsorted(cum, target, side="left")), len(cal._hist) - 1)
    below = cum[i - 1] if i > 0 else 0.0
    frac = (target - below) / cal._hist[i] if cal._hist[i] > 0 else 0.5
    return float(cal._edges[i] + frac * BIN_DB)


def _report_cov_numpy(out: np.ndarray, scale: np.ndarray | None, snap) -> np.ndarray:
    from companion.estimator.consistency import snapshot_axis

    cov = out[9:18] if scale is None else out[9:18] * scale
    k, f_h, f_v, d = snap
    cov = cov.copy() if scale is None else cov
    cov[0] = snapshot_axis(float(out[9]), k, f_h, d[0])
    cov[1] = snapshot_axis(float(out[10]), k, f_h, d[1])
    cov[2] = snapshot_axis(float(out[11]), k, f_v, d[2])
    return cov


def _predict_mean_numpy(x: np.ndarray, m15, T: float, live: tuple[bool, ...]) -> np.ndarray:
    from companion.tight.model import I_CLK

    x = x.copy()
    x[0:12] = np.asarray(m15)[model.NAV_OF_LOOSE]
    x[I_CLK:I_DRIFT] += T * x[I_DRIFT] * np.asarray(live, dtype=float)
    return x


def _receiver(x: list[float], r0: list[float], C: list[list[float]]) -> tuple[list[float], list[float]]:
    r = [r0[i] + C[i][0] * x[0] + C[i][1] * x[1] + C[i][2] * x[2] for i in range(3)]
    ve = [C[i][0] * x[3] + C[i][1] * x[4] + C[i][2] * x[5] for i in range(3)]
    return r, ve


def _range_rate_row(x: list[float], r0: list[float], C: list[list[float]], rs: list[float], us: list[float],
                    n: int) -> tuple[float, list[float]]:
    """_tight.c's range_rate_row, line by line."""
    r, ve = _receiver(x, r0, C)
    d = [rs[0] - r[0], rs[1] - r[1], rs[2] - r[2]]
    rng = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    line = [d[0] / rng, d[1] / rng, d[2] / rng]
    dv = [us[0] - ve[0], us[1] - ve[1], us[2] - ve[2]]
    g = line[0] * dv[0] + line[1] * dv[1] + line[2] * dv[2]
    sv = line[0] * us[0] + line[1] * us[1] + line[2] * us[2]
    f = 1.0 - sv / C_M_S
    sag = W_C * (us[0] * r[1] + rs[0] * ve[1] - us[1] * r[0] - rs[1] * ve[0])
    dm_dr, dm_dv = [0.0] * 3, [0.0] * 3
    for k in range(3):
        dg, ds = -(dv[k] - g * line[k]) / rng, -(us[k] - sv * line[k]) / rng
        dm_dr[k] = dg * f - (g / C_M_S) * ds
        dm_dv[k] = -line[k] * f
    dm_dr[0] -= W_C * us[1]
    dm_dr[1] += W_C * us[0]
    dm_dv[0] -= W_C * rs[1]
    dm_dv[1] += W_C * rs[0]
    h = [0.0] * n
    for k in range(3):
        h[k] = dm_dr[0] * C[0][k] + dm_dr[1] * C[1][k] + dm_dr[2] * C[2][k]
        h[3 + k] = dm_dv[0] * C[0][k] + dm_dv[1] * C[1][k] + dm_dv[2] * C[2][k]
    h[I_DRIFT] = 1.0
    return g * f + sag + x[I_DRIFT], h


def _chol(A: list[list[float]]) -> None:
    k = len(A)
    for j in range(k):
        s = A[j][j]
        for c in range(j):
            s -= A[j][c] * A[j][c]
        assert s > 0.0
        d = math.sqrt(s)
        A[j][j] = d
        for i in range(j + 1, k):
            t = A[i][j]
            for c in range(j):
                t -= A[i][c] * A[j][c]
            A[i][j] = t / d


def dense_update(x, P, H, HP, y, r, used, r0, C, sat_pos, sat_vel, z_rate, r_rate, gate2):
    """``_tight.update`` with every sum over all N columns (its loops before the speed change)."""
    n = len(x)
    x, P, H, HP = x.tolist(), P.tolist(), H.tolist(), HP.tolist()
    r0, C, sat_pos, sat_vel = r0.tolist(), C.tolist(), sat_pos.tolist(), sat_vel.tolist()
    Hs, HPs, ys, rs, n_rate = [], [], [], [], 0
    for i in range(len(y)):
        if used[i] != 0.0:
            Hs.append(H[i])
            HPs.append(HP[i])
            ys.append(float(y[i]))
            rs.append(float(r[i]))
    for i in range(len(y)):
        if used[i] == 0.0 or not math.isfinite(z_rate[i]) or not math.isfinite(sat_vel[i][0]):
            continue
        pred, h = _range_rate_row(x, r0, C, sat_pos[i], sat_vel[i], n)
        yr, s0 = float(z_rate[i]) - pred, 0.0
        hp = []
        for c in range(n):
            v = 0.0
            for j in range(n):
                v += h[j] * P[j][c]
            hp.append(v)
        for c in range(n):
            s0 += hp[c] * h[c]
        if yr * yr <= gate2 * (s0 + r_rate[i]):
            Hs.append(h)
            HPs.append(hp)
            ys.append(yr)
            rs.append(float(r_rate[i]))
            n_rate += 1
    k = len(ys)
    xo, Po, nis = list(x), [list(row) for row in P], math.nan
    if k:
        S = [[0.0] * k for _ in range(k)]
        for i in range(k):
            for j in range(i + 1):
                s = 0.0
                for c in range(n):
                    s += HPs[i][c] * Hs[j][c]
                S[i][j] = S[j][i] = s + (rs[i] if i == j else 0.0)
        _chol(S)
        W = [[ys[i], *HPs[i]] for i in range(k)]
        for i in range(k):
            for j in range(i):
                w = S[i][j]
                for c in range(n + 1):
                    W[i][c] -= w * W[j][c]
            for c in range(n + 1):
                W[i][c] /= S[i][i]
        nis = 0.0
        for i in range(k):
            nis += W[i][0] * W[i][0]
        for c in range(n):
            s = 0.0
            for i in range(k):
                s += W[i][1 + c] * W[i][0]
            xo[c] += s
        for a in range(n):
            for c in range(a, n):
                s = 0.0
                for i in range(k):
                    s += W[i][1 + a] * W[i][1 + c]
                Po[a][c] -= s
                if c != a:
                    Po[c][a] -= s
        for a in range(n):
            for c in range(a + 1, n):
                Po[a][c] = Po[c][a] = 0.5 * (Po[a][c] + Po[c][a])
    return np.array(xo), np.array(Po), nis, n_rate


@pytest.mark.parametrize("seed", [3, 12, 40])
@pytest.mark.parametrize("n_state", [N_STATE, N_STATE + 1])
def test_c_update_equals_its_dense_sums_bit_for_bit(seed, n_state):
    """Random states and covariances (with zero rows: the heading states at rest, and negative
    covariances: the signed zeros of the left-out terms), some satellites unused, some without Doppler,
    every clock slot: the sparse sums give exactly the dense ones."""
    rng = np.random.default_rng(seed)
    P = c_core_inputs(rng, n_state)[0]
    P[I_DRIFT + 1:I_DRIFT + 3, :] = P[:, I_DRIFT + 1:I_DRIFT + 3] = 0.0  # the odometry heading: not started
    x = np.append(_state(rng), rng.normal(0.0, 3.0, n_state - N_STATE))
    sysv, _, pos, vel = _sats()
    slot = model.SLOT_OF[sysv]
    r0, C = FRAME.r0_ecef_m, FRAME.c_ecef_ned
    z = model.pseudorange(x[:N_STATE], FRAME, pos, slot)[0] + rng.normal(0, 5, len(slot))
    y, H, HP, _, _ = _tight.innovations(x, P, r0, C, pos, slot.astype(float), z)
    used = (rng.uniform(size=len(y)) > 0.2).astype(float)
    r = rng.uniform(4, 100, len(y))
    z_rate = model.range_rate(x[:N_STATE], FRAME, pos, vel)[0] + rng.normal(0, 0.3, len(y))
    z_rate[::5] = np.nan
    r_rate = rng.uniform(0.05, 1.0, len(y))
    args = (x, P, H, HP, y, r, used, r0, C, pos, vel, z_rate, r_rate, 25.0)
    x_c, P_c, nis_c, n_c = _tight.update(*args)
    x_d, P_d, nis_d, n_d = dense_update(*args)
    assert n_c == n_d > 0 and int(used.sum()) > 4
    assert np.array_equal(x_c, x_d) and np.array_equal(P_c, P_d) and nis_c == nis_d


def test_c_update_with_a_non_finite_covariance_takes_the_dense_sums():
    """A NaN in P (a broken state) where every range rate's H is zero: the full sums, as before (0 · NaN is
    NaN, so nothing may be left out): the range rates' H P and gates see it and refuse them all, as the dense
    loops did; summed over the nonzero columns they would have passed."""
    rng = np.random.default_rng(5)
    P = c_core_inputs(rng, N_STATE)[0]
    P[I_DRIFT + 1, I_DRIFT + 1] = np.nan  # the odometry heading's variance
    x = _state(rng)
    sysv, _, pos, vel = _sats()
    slot = model.SLOT_OF[sysv]
    r0, C = FRAME.r0_ecef_m, FRAME.c_ecef_ned
    z = model.pseudorange(x, FRAME, pos, slot)[0] + rng.normal(0, 5, len(slot))
    y, H, HP, _, _ = _tight.innovations(x, P, r0, C, pos, slot.astype(float), z)
    z_rate = model.range_rate(x, FRAME, pos, vel)[0]
    args = (x, P, H, HP, y, np.full(len(y), 25.0), np.ones(len(y)), r0, C, pos, vel, z_rate,
            np.full(len(y), 0.1), 25.0)
    x_c, P_c, nis_c, n_c = _tight.update(*args)
    x_d, P_d, nis_d, n_d = dense_update(*args)
    assert n_c == n_d == 0
    assert np.array_equal(x_c, x_d) and np.array_equal(P_c, P_d, equal_nan=True) and nis_c == nis_d
    assert np.isnan(P_c[I_DRIFT + 1, I_DRIFT + 1]) and np.isfinite(x_c).all()


def test_c_carry_states_equals_the_numpy_step_bit_for_bit():
    """satcache's p + v dt + ½ a dt², v + a dt, clock + drift dt and valid == 1 as numpy computed them (an
    anchor table's rows, NaN rows of satellites without a state, dt of either sign and 0)."""
    rng = np.random.default_rng(7)
    n = 40
    out = np.column_stack((rng.normal(0, 2e7, (n, 3)), rng.normal(0, 3e3, (n, 3)),
                           rng.normal(0, 0.6, (n, 3)), rng.normal(0, 1e-4, n), rng.normal(0, 1e-11, n),
                           (rng.uniform(size=n) > 0.2) * 1.0))
    out[3] = np.nan
    dt = rng.uniform(-2.5, 2.5, n)
    dt[5] = 0.0
    pos, vel, clock, drift, anchored = _tight.carry_states(out, dt)
    d = dt[:, None]
    assert np.array_equal(pos, out[:, 0:3] + out[:, 3:6] * d + 0.5 * out[:, 6:9] * d * d, equal_nan=True)
    assert np.array_equal(vel, out[:, 3:6] + out[:, 6:9] * d, equal_nan=True)
    assert np.array_equal(clock, out[:, 9] + out[:, 10] * dt, equal_nan=True)
    assert np.array_equal(drift, out[:, 10], equal_nan=True)
    assert anchored.dtype == bool and np.array_equal(anchored, out[:, 11] == 1.0) and not anchored[3]
    assert all(len(a) == 0 for a in _tight.carry_states(np.zeros((0, 12)), np.zeros(0)))


@pytest.mark.parametrize("changes", [
    {"cn0_dbhz": np.array([30.0, 35.0, 40.0])},
    {"sat_pos_ecef_m": np.ones((3, 3)), "sat_vel_ecef_m_s": np.zeros((0, 3)), "sat_clock_s": np.ones(3)},
    {"t_gps_s": 5.0, "corrected": True},
    {"pseudorange_m": np.array([1.0, 2.0]), "system": np.array([1, 1]), "prn": np.array([3, 4])},
])
def test_gnss_epoch_replace_is_dataclasses_replace(changes):
    """The same fields (an empty per-satellite array becoming NaN rows, as the constructor does)."""
    e = make_epoch(100.0, [1, 1, 3], [3, 4, 7], [2.1e7, 2.2e7, 2.3e7], cn0_dbhz=[40.0, 41.0, 42.0])
    if "pseudorange_m" in changes:  # another number of satellites: every per-satellite field given
        per_sat = ("pseudorange_var_m2", "pseudorange_rate_m_s", "cn0_dbhz", "elevation_deg", "azimuth_deg",
                   "sat_pos_ecef_m", "sat_vel_ecef_m_s", "sat_clock_s", "sat_clock_drift_s_s")
        vectors = ("sat_pos_ecef_m", "sat_vel_ecef_m_s")
        changes = {**changes, **{f: np.zeros((2, 3)) if f in vectors else np.zeros(2) for f in per_sat}}
    got, want = e.replace(**changes), dataclasses.replace(e, **changes)
    for f in dataclasses.fields(GnssEpoch):
        a, b = getattr(got, f.name), getattr(want, f.name)
        assert type(a) is type(b)
        assert np.array_equal(a, b, equal_nan=True) if isinstance(a, np.ndarray) else a == b
        assert a is b or f.name in changes or (isinstance(a, np.ndarray) and a.size and np.isnan(a).all())


def test_gnss_epoch_replace_refuses_what_the_constructor_refuses():
    e = make_epoch(100.0, [1, 1], [3, 4], [2.1e7, 2.2e7])
    with pytest.raises(ValueError, match="cn0_dbhz"):
        e.replace(cn0_dbhz=np.zeros(3))
    with pytest.raises(TypeError):
        e.replace(cn0=np.zeros(2))


def test_no_import_falls_inside_the_first_epochs():
    """What the first epochs need (scipy.special for the χ² tests: ~0.3 s of CPU) is imported when the
    navigator is built, not inside the first epoch a live receiver sends (a fresh interpreter: this
    process has imported everything already)."""
    import subprocess
    import sys
    import textwrap

    code = textwrap.dedent("""
        import sys
        import numpy as np
        from companion.domain.samples import AttitudeSample, ImuSample
        from companion.tight import RawGnss, TightConfig
        from companion.wiring import tight_navigator_for
        from gcs_tools.bench.tight import _epochs, store
        st = store()
        epochs = _epochs(st, 3)
        nav = tight_navigator_for(None, "second-order", config=TightConfig(elevation_mask_deg=-90.0),
                                  ephemerides=st)
        before = set(sys.modules)
        for k, ep in enumerate(epochs):
            t_us = 1_000_000 + 200_000 * k
            nav.push(AttitudeSample(t_us, np.array([1.0, 0.0, 0.0, 0.0])))
            nav.push(ImuSample(t_us, np.array([0.0, 0.0, -9.80665]), np.zeros(3)))
            nav.push(RawGnss(t_us, ep))
            nav.estimate()
        c = nav.counters()
        assert (c["gnss_epochs"], c["gnss_fused"]) == (3, 2), c  # the first starts the filter
        print(" ".join(sorted(set(sys.modules) - before)))
        """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split() == [], out.stdout


def _raw_epoch(rng: np.random.Generator) -> tuple[GnssEpoch, np.ndarray]:
    """A receiver's raw epoch over every synthetic satellite (GLONASS among them, some below the
    horizon) with its satellite states attached and atmospheric delays, as the navigator prepares it."""
    from companion.gnss import attach_broadcast

    ep, _ = observe(STORE, T0 + 30.0, RX_ECEF, mask_deg=-90.0)
    ep, _ = attach_broadcast(ep, STORE)
    ep = ep.replace(corrected=False, sat_clock_s=rng.normal(0.0, 1e-4, ep.n),
                    sat_clock_drift_s_s=rng.normal(0.0, 1e-11, ep.n), cn0_dbhz=rng.uniform(15.0, 52.0, ep.n))
    return ep, rng.uniform(2.0, 30.0, ep.n)


def _assert_prepared_equal(got: engine.SatEpoch, want: engine.SatEpoch) -> None:
    exact = ("key", "slot", "slot_f", "z_m", "r_uniform_m2", "sat_pos_ecef_m", "sat_vel_ecef_m_s",
             "z_rate_m_s", "systems")
    assert want.key_sorted is None and got.key_sorted is not None  # the C path's own: the keys in order
    assert np.array_equal(got.key_sorted[0], np.sort(want.key)) and np.array_equal(
        got.key[got.key_sorted[1]], got.key_sorted[0])
    for name in engine.SatEpoch._fields[1:-1]:
        a, b = getattr(got, name), getattr(want, name)
        if name in exact:
            assert (a == b) if isinstance(a, tuple) else np.array_equal(a, b, equal_nan=True), name
        else:
            assert a.shape == b.shape and np.isfinite(a).all() and np.isfinite(b).all(), name
            assert np.abs(a - b).max() <= 1e-12 * np.abs(b).max(), name  # per quantity, relative
    assert got.epoch is want.epoch


@pytest.mark.parametrize("damage", [None, "cn0", "drift", "velocity", "rate"])
def test_c_prepare_equals_the_numpy_preparation(damage):
    """Every field of a raw epoch's preparation (all satellites kept: mask −90°), undamaged and with
    missing C/N0, clock drift, satellite velocity or Doppler (the numpy path's NaN handling)."""
    rng = np.random.default_rng(11)
    cfg = TightConfig(elevation_mask_deg=-90.0)
    ep, atm = _raw_epoch(rng)
    assert (ep.system == int(engine._GLONASS)).any() and ep.n > 20
    every = np.arange(ep.n)
    if damage == "cn0":
        ep = ep.replace(cn0_dbhz=np.where(every % 3 == 0, np.nan, ep.cn0_dbhz))
    elif damage == "drift":
        ep = ep.replace(sat_clock_drift_s_s=np.where(every % 4 == 1, np.nan, ep.sat_clock_drift_s_s))
    elif damage == "velocity":
        vel = ep.sat_vel_ecef_m_s.copy()
        vel[2, 1] = np.nan
        vel[7] = np.inf
        ep = ep.replace(sat_vel_ecef_m_s=vel)
    elif damage == "rate":
        ep = ep.replace(pseudorange_rate_m_s=np.where(every % 5 == 2, np.nan, ep.pseudorange_rate_m_s))
    got = engine.prepare_epoch(ep, FRAME, cfg, None, atm)
    want = engine._prepare_numpy(ep, FRAME, cfg, None, atm)
    assert got is not None and want is not None
    _assert_prepared_equal(got, want)
    if damage in ("velocity", "rate"):  # the C path's own (a NaN rate and velocity rows), and not vacuous
        assert np.isnan(got.z_rate_m_s).sum() in (2, len(range(2, ep.n, 5)))
    # the same satellites again: the cached keys and slots are the same, read-only arrays
    again = engine.prepare_epoch(ep, FRAME, cfg, None, atm)
    assert again is not None and again.key is got.key and not again.key.flags.writeable


@pytest.mark.parametrize("drop", ["mask", "pseudorange", "clock", "position"])
def test_c_prepare_leaves_a_dropped_observation_to_numpy(drop):
    """An observation the mask or a non-finite input drops: the C path declines (None) and the numpy
    path selects, as before."""
    rng = np.random.default_rng(12)
    cfg = TightConfig(elevation_mask_deg=-90.0 if drop != "mask" else 10.0)
    ep, atm = _raw_epoch(rng)
    if drop == "pseudorange":
        ep = ep.replace(pseudorange_m=np.where(np.arange(ep.n) == 3, np.nan, ep.pseudorange_m))
    elif drop == "clock":
        ep = ep.replace(sat_clock_s=np.where(np.arange(ep.n) == 4, np.nan, ep.sat_clock_s))
    elif drop == "position":
        pos = ep.sat_pos_ecef_m.copy()
        pos[5, 0] = np.nan
        ep = ep.replace(sat_pos_ecef_m=pos)
    args = (ep.sat_pos_ecef_m, FRAME.r0_ecef_m, FRAME.c_ecef_ned, ep.pseudorange_m, ep.sat_clock_s, atm,
            ep.pseudorange_rate_m_s, ep.sat_clock_drift_s_s, ep.cn0_dbhz, np.ones(ep.n), ep.sat_vel_ecef_m_s,
            engine._prepare_params(cfg))
    assert _tight.prepare(*args) is None
    got = engine.prepare_epoch(ep, FRAME, cfg, None, atm)
    want = engine._prepare_numpy(ep, FRAME, cfg, None, atm)
    assert got is not None and want is not None and got.epoch.n == want.epoch.n < ep.n
    assert got.key_sorted is None and want.key_sorted is None
    for name in engine.SatEpoch._fields[1:-1]:
        a, b = getattr(got, name), getattr(want, name)
        assert (a == b) if isinstance(a, tuple) else np.array_equal(a, b, equal_nan=True), name


def test_c_cn0_calibration_equals_its_numpy_form_bit_for_bit():
    """``Cn0Calibration.add`` and ``level_dbhz`` (in C) against their numpy forms over epochs
    with NaN, infinite and out-of-range values, fractional C/N0 and empty epochs: the same histogram, count
    and quantile, bit for bit, after every epoch (quantiles near both ends included)."""
    from companion.tight.cn0cal import Cn0Calibration

    rng = np.random.default_rng(13)
    for quantile in (0.0, 0.2, 0.75, 1.0):
        c, ref = Cn0Calibration(quantile, 45.0, 50.0), Cn0Calibration(quantile, 45.0, 50.0)
        assert math.isnan(c.level_dbhz()) and math.isnan(_cn0_level_numpy(ref))
        for k in range(60):
            cn0 = rng.normal(38.0, 9.0, rng.integers(0, 25)) if k != 5 else np.zeros(0)
            if k % 4 == 1 and len(cn0) > 3:
                cn0[0], cn0[1], cn0[2] = np.nan, np.inf, -5.0
            if k % 6 == 2 and len(cn0) > 1:
                cn0[0], cn0[-1] = 95.0, 80.0
            if k % 5 == 0:
                cn0 = np.round(cn0)
            c.add(cn0)
            _cn0_add_numpy(ref, cn0)
            assert np.array_equal(c._hist, ref._hist) and c.n == ref.n
            got, want = c.level_dbhz(), _cn0_level_numpy(ref)
            assert got == want or (math.isnan(got) and math.isnan(want))
            assert c.calibrated(cn0).tobytes() == (np.asarray(cn0, float) - ref.offset_db()).tobytes()
        assert c.n > 500


def _same_states(got, want) -> None:
    (sa, ta), (sb, tb) = got, want
    for a, b in zip(sa, sb, strict=True):
        assert a.dtype == b.dtype and np.array_equal(a, b, equal_nan=True)
    assert np.array_equal(ta, tb, equal_nan=True)


@pytest.mark.parametrize("case", ["tracked", "unknown", "nan", "boundary", "empty"])
def test_c_transmission_states_equal_the_numpy_ones_bit_for_bit(case):
    """``SatelliteCache.transmission_states`` (one anchor: in C) against ``ephemeris.transmission_states``
    on the same cache (a fresh one each, so both evaluate the same anchors): every satellite tracked, one
    without an ephemeris (not valid: no clock step back), a NaN pseudorange and anchors that differ across
    the epoch (both the general path), no satellite."""
    from companion.gnss.ephemeris import transmission_states
    from companion.tight.satcache import SatelliteCache

    t = T0 + 30.0 if case != "boundary" else T0 + 2.5 + 0.0734  # t − P/c straddles a 5 s anchor's edge
    ep, _ = observe(STORE, t, RX_ECEF, mask_deg=-90.0)
    if case == "unknown":
        ep = ep.replace(prn=np.where(np.arange(ep.n) == 3, 99, ep.prn).astype(ep.prn.dtype))
    elif case == "nan":
        ep = ep.replace(pseudorange_m=np.where(np.arange(ep.n) == 4, np.nan, ep.pseudorange_m))
    elif case == "empty":
        ep = ep.select(np.zeros(ep.n, dtype=bool))
    t0, k = _tight.transmit_anchor(ep.t_gps_s, ep.pseudorange_m, 5.0)
    assert np.array_equal(t0, ep.t_gps_s - ep.pseudorange_m / C_M_S, equal_nan=True)
    assert (k is None) == (case in ("nan", "boundary", "empty"))
    for _ in range(2):  # the second: the anchor's rows and the keys from the caches
        a, b = SatelliteCache(STORE, 5.0), SatelliteCache(STORE, 5.0)
        _same_states(a.transmission_states(ep), transmission_states(b, ep))
    if case == "unknown":
        valid = a.transmission_states(ep)[0].valid
        assert not valid[3] and valid.sum() == ep.n - 1
    assert a.keys(ep.system, ep.prn) == (ep.system.astype(np.int64) * 1000 + ep.prn).tolist()


def test_c_anchors_are_numpys():
    t = np.array([0.0, 2.5, 7.5, -2.5, 12.4999, np.nan, np.inf, -np.inf, 1.1e9 + 0.3, -7.49])
    assert _tight.anchors(t, 5.0) == np.rint(np.where(np.isfinite(t), t, 0.0) / 5.0).astype(np.int64).tolist()
    assert _tight.anchors(np.array([1e300]), 5.0) is None  # beyond an int64: the caller's numpy


def test_c_report_cov_equals_the_numpy_report_bit_for_bit():
    """``estimate``'s variances with the snapshots' floors (``_tight.report_cov``) against the numpy and
    ``snapshot_axis`` form they replaced, with and without the scale k
    on the positions, floors None or not, each term winning, NaN and infinite variances."""
    from companion.estimator.consistency import SnapshotFloor, variance_scale
    rng = np.random.default_rng(14)
    wins = set()
    for trial in range(400):
        out = rng.lognormal(0.0, 2.0, 18)
        if trial % 17 == 0:
            out[rng.integers(9, 18)] = np.nan
        if trial % 23 == 0:
            out[rng.integers(9, 12)] = np.inf
        k = 1.0 if trial % 3 == 0 else float(rng.uniform(1.0, 4.0))
        floors = [None if rng.uniform() < 0.2 else SnapshotFloor(*rng.lognormal(0.0, 1.5, 4))
                  for _ in range(2)]
        d = tuple(float(v) for v in (rng.lognormal(0.0, 2.0, 3) if trial % 2 else np.zeros(3)))
        snap = (k, floors[0], floors[1], d)
        got = _tight.report_cov(out, k, floors[0], floors[1], *d)
        want = _report_cov_numpy(out, variance_scale(k), snap)
        assert got.tobytes() == want.tobytes()
        wins.add("k p" if got[0] == out[9] * k else "delay" if got[0] == d[0] else "floor")
    assert wins == {"k p", "delay", "floor"}  # each term won somewhere
    with pytest.raises(TypeError):
        _tight.report_cov(np.zeros(18), 1.0, (1.0, 2.0), None, 0.0, 0.0, 0.0)
    with pytest.raises(ValueError):
        _tight.report_cov(np.zeros(9), 1.0, None, None, 0.0, 0.0, 0.0)


def test_fit_fed_in_key_order_holds_the_same_sums():
    """The fusion hands ``Fit.add`` its channels sorted by key (``SatEpoch.key_sorted``) instead of in the
    receiver's order: the same sums for every channel, bit for bit, through satellites setting and rising
    (the general path) and the same ones epoch after epoch (the fast path)."""
    from companion.estimator.consistency import Fit

    rng = np.random.default_rng(15)
    pool = np.arange(1000, 1040)
    a = b = Fit()
    for k in range(80):
        keys = rng.permutation(pool[rng.integers(0, 5):rng.integers(25, 40)] if k % 9 == 0 else pool[5:25])
        nu = rng.normal(0.0, 1.0, len(keys))
        order = np.argsort(keys, kind="stable")
        a = a.add(1_000_000 + 200_000 * k, keys, nu, 20.0)
        b = b.add(1_000_000 + 200_000 * k, keys[order], nu[order], 20.0)
        assert np.array_equal(a.key, b.key) and a.nu_sum.tobytes() == b.nu_sum.tobytes()
        assert a.w2_sum.tobytes() == b.w2_sum.tobytes() and a.inflation() == b.inflation()


@pytest.mark.parametrize("n_state", [N_STATE, N_STATE + 1])
def test_c_predict_mean_equals_the_numpy_prediction_bit_for_bit(n_state):
    """``_tight.predict_mean`` against the numpy it replaced in ``_predict``: random
    states (with the barometer's offset too), live and dead clocks, T of either sign and 0, NaN."""
    rng = np.random.default_rng(16)
    for trial in range(200):
        x = rng.normal(0.0, 1e3, n_state)
        m15 = tuple(rng.normal(0.0, 50.0, 15).tolist())
        if trial % 13 == 0:
            x[I_DRIFT] = np.nan
        live = tuple(bool(v) for v in rng.integers(0, 2, 6))
        T = float(rng.choice([0.0, -0.2, 0.2, 1.7, rng.uniform(0, 5)]))
        got = _tight.predict_mean(x, m15, T, live)
        want = _predict_mean_numpy(x, m15, T, live)
        assert got.tobytes() == want.tobytes() and got is not x and x.shape == got.shape
    with pytest.raises(ValueError):
        _tight.predict_mean(np.zeros(N_STATE), (0.0,) * 14, 0.1, (True,) * 6)
