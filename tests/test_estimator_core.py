"""The C core (companion/estimator/_core.c) against independent references kept only here: a
pure-Python IMU history (the prefix integrals as plain float expressions, the form the core
replaced) and the numpy reference forms of model.py (F P Fᵀ + Q with dense F, the textbook
Kalman update)."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from companion.domain.rotation import rotation_scaled
from companion.estimator import _core, model
from companion.estimator.history import ImuHistory

N = model.N_STATE
IDENTITY9 = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
Row = tuple[float, ...]


class ReferenceHistory:
    """history.py's formulas as Python floats: rows (t_s, ã, S1, S2, R, M1, M2, (w, j), W, J, c (3), C (9)),
    zero-order hold; the hold limit max(hold_max_s, hold_periods × the period), the period the median of
    the last 8 intervals; a gap held for the limit then a virtual zero-acceleration sample; held time (an
    interval over 1.5 periods) with its densities and moments (a gap's: w over its hold, j over the whole
    interval), a coast with the dropped acceleration's (c_i = ã_i² C)."""

    def __init__(self, hold_max_s: float, hold_periods: float = 0.0) -> None:
        self.hold_max_s, self.hold_us = hold_max_s, int(round(hold_max_s * 1e6))
        self.hold_periods = hold_periods
        self.t0_us = 0
        self.t_us: list[int] = []
        self.rows: list[tuple[float, ...]] = []
        self.intervals: list[int] = []

    @staticmethod
    def _held(r: Row, t: float, dens: tuple[float, ...]) -> list[float]:
        """(w, j), W, J, c (3) and C (9) of the row at t after r, the interval's densities ``dens``
        (w, j, c_x, c_y, c_z)."""
        dt = t - r[0]
        m = (dt, dt * (r[0] + t) * 0.5, dt * (r[0] * r[0] + r[0] * t + t * t) / 3.0)
        w, j, *c = dens
        held = [w, j, *r[39:45]] if w == 0.0 and j == 0.0 else \
            [w, j, *(r[39 + i] + w * m[i] for i in range(3)), *(r[42 + i] + j * m[i] for i in range(3))]
        if not any(c):
            return [*held, 0.0, 0.0, 0.0, *r[48:57]]
        return [*held, *c, *(r[48 + 3 * a + i] + c[a] * m[i] for a in range(3) for i in range(3))]

    @classmethod
    def _next(cls, r: Row, t: float, a: Row, rot: Row, dens: tuple[float, ...] = (0.0,) * 5) -> Row:
        dt = t - r[0]
        dm = dt * (r[0] + t) * 0.5
        held = r[1:4] + r[10:19]
        i1 = [s + h * dt for s, h in zip(r[4:7] + r[19:28], held, strict=True)]
        i2 = [s + h * dm for s, h in zip(r[7:10] + r[28:37], held, strict=True)]
        return (t, *a, *i1[0:3], *i2[0:3], *rot, *i1[3:12], *i2[3:12], *cls._held(r, t, dens))

    def _period(self) -> int:
        last = sorted(self.intervals[-9:-1])  # the period: before this interval
        return last[(len(last) - 1) // 2] if last else 0

    def _densities(self, dt_us: int, t_prev: float, t_end: float) -> tuple[float, float]:
        p_us = self._period()
        if not p_us:
            return 0.0, 0.0
        L, p = t_end - t_prev, p_us * 1e-6
        if 3 * p_us >= 2 * dt_us or p >= L:
            return 0.0, 0.0
        return (L - p) / p, L * L / 3.0

    def append(self, t_us: int, ax: float, ay: float, az: float, rot: tuple[float, ...] = IDENTITY9) -> bool:
        if not self.rows:
            self.t0_us = t_us
            self.t_us.append(t_us)
            self.rows.append((0.0, ax, ay, az, *(0.0,) * 6, *rot, *(0.0,) * 38))
            return False
        r = self.rows[-1]
        t = (t_us - self.t0_us) * 1e-6
        dt_us = t_us - self.t_us[-1]
        self.intervals.append(dt_us)
        lim_us = self.hold_us
        if self.hold_periods > 0 and dt_us > self.hold_us:
            lim_us = max(lim_us, round(self.hold_periods * self._period()))
        gap = t - r[0] > (self.hold_max_s if lim_us == self.hold_us else lim_us * 1e-6)
        w, j = self._densities(dt_us, r[0], t)
        if gap:
            tv_us = self.t_us[-1] + lim_us
            tv = (tv_us - self.t0_us) * 1e-6
            self.t_us.append(tv_us)
            w = self._densities(dt_us, r[0], tv)[0]  # the white part: the hold only
            self.rows.append(self._next(r, tv, (0.0, 0.0, 0.0), r[10:19], (w, j, 0.0, 0.0, 0.0)))
            c = tuple(r[1 + i] * r[1 + i] * (t - tv) for i in range(3))
            dens = (0.0, j, *c)
        else:
            dens = (w, j, 0.0, 0.0, 0.0)
        self.t_us.append(t_us)
        self.rows.append(self._next(self.rows[-1], t, (ax, ay, az), tuple(rot), dens))
        return gap

    def integrals(self, t_us: int) -> tuple[float, ...]:
        k = max(i for i, t in enumerate(self.t_us) if t <= t_us)
        r = self.rows[k]
        t = (t_us - self.t0_us) * 1e-6
        dens = (*self.rows[k + 1][37:39], *self.rows[k + 1][45:48]) if k + 1 < len(self.rows) else (0.0,) * 5
        nxt = self._next(r, t, r[1:4], r[10:19], dens) if t != r[0] else r
        return (t, *nxt[4:10], *nxt[19:37], *nxt[39:45], *nxt[48:57])


def _rot9(rng: np.random.Generator) -> tuple[float, ...]:
    return tuple(Rotation.random(random_state=rng).as_matrix().ravel().tolist())


def _stream(rng: np.random.Generator, n: int = 400):
    """Irregular times (3-9 ms) with three gaps (0.08-0.5 s), random accelerations and attitudes."""
    dts = rng.integers(3000, 9000, size=n)
    dts[[n // 8, n // 8 + 1, n // 2]] = (80_000, 120_000, 500_000)
    t_us = (1_000_000 + np.concatenate([[0], np.cumsum(dts[1:])])).tolist()
    return t_us, rng.standard_normal((n, 3)).tolist(), [_rot9(rng) for _ in range(n)]


def _random_cov(rng: np.random.Generator) -> np.ndarray:
    A = rng.standard_normal((N, N))
    return A @ A.T + 0.1 * np.eye(N)


def _slow_stream(rng: np.random.Generator, n: int = 300):
    """A 10 Hz IMU (90-110 ms) with a lost sample (200 ms), two lost (300 ms) and an outage (1.5 s)."""
    dts = rng.integers(90_000, 110_000, size=n)
    dts[[n // 5, n // 3, n // 2]] = (200_000, 300_000, 1_500_000)
    t_us = (1_000_000 + np.concatenate([[0], np.cumsum(dts[1:])])).tolist()
    return t_us, rng.standard_normal((n, 3)).tolist(), [_rot9(rng) for _ in range(n)]


@pytest.mark.parametrize(("stream", "periods", "n_gaps"), [(_stream, 0.0, 3), (_stream, 2.5, 3),
                                                          (_slow_stream, 2.5, 3), (_slow_stream, 0.0, 299)])
def test_history_rows_and_integrals_equal_the_float_reference_bit_for_bit(stream, periods, n_gaps):
    """Rows, gaps and integrals (inside holds and coasts too) as the float reference, with the hold limit
    fixed and following the period: at 200 Hz the same gaps either way; at 10 Hz only the two-sample
    loss, the outage and the first interval (no period yet) are gaps with it, every interval without."""
    rng = np.random.default_rng(11)
    t_us, acc, rots = stream(rng)
    core, ref = ImuHistory(0.05, periods), ReferenceHistory(0.05, periods)
    gaps = []
    for t, a, r in zip(t_us, acc, rots, strict=True):
        gaps.append(core.append(t, *a, r))
        assert ref.append(t, *a, r) == gaps[-1]
    assert sum(gaps) == n_gaps and core.rows == ref.rows and core.t_us == ref.t_us
    assert any(r[45] != 0.0 for r in core.rows) and any(r[38] != 0.0 for r in core.rows)
    assert (core.first_t_us, core.last_t_us, core.t0_us) == (t_us[0], t_us[-1], t_us[0])
    assert len(core) == len(ref.rows)
    for t in [*rng.integers(t_us[0], t_us[-1] + 40_000, size=300).tolist(), *t_us[::37], *core.t_us[1::7]]:
        assert core.integrals(t) == ref.integrals(t)
    assert core.last_integrals() == ref.integrals(t_us[-1])
    # the batch path: the same rows as one by one
    batch = ImuHistory(0.05, periods)
    batch.append(t_us[0], *acc[0], rots[0])
    batch.append_batch(np.array(t_us[1:50]), np.array(acc[1:50]), np.array(rots[1:50]))
    assert batch.rows == ref.rows[:len(batch)] and batch.t_us == ref.t_us[:len(batch)]
    assert batch.last_t_us == t_us[49]


def test_history_trim_keeps_every_integral_after_the_cut_and_grows_past_its_buffer():
    rng = np.random.default_rng(12)
    core, ref = ImuHistory(0.05), ReferenceHistory(0.05)
    t = 0
    for k in range(5000):  # beyond the core's initial buffer, trimmed as the engine does
        t += 5000
        a, r = rng.standard_normal(3).tolist(), IDENTITY9 if k % 2 else _rot9(rng)
        core.append(t, *a, r)
        ref.append(t, *a, r)
        if k % 700 == 0:
            core.trim_before(t - 1_000_000)
    assert core.first_t_us <= t - 1_000_000 and len(core) < 600
    for q in range(t - 900_000, t + 1, 12_345):
        assert core.integrals(q) == ref.integrals(q)
    with pytest.raises(ValueError, match="before the IMU history"):
        core.integrals(core.first_t_us - 1)


def test_gated_push_counts_and_the_frd_path():
    core = ImuHistory(0.05)
    r = _rot9(np.random.default_rng(3))
    f = np.array([0.3, -0.2, -9.7])
    assert core.push_frd(0, f, r, 9.80665) is False
    fx, fy, fz = f.tolist()
    expected = (r[0] * fx + r[1] * fy + r[2] * fz, r[3] * fx + r[4] * fy + r[5] * fz,
                r[6] * fx + r[7] * fy + r[8] * fz + 9.80665)  # the navigator's float expression
    assert core.rows[0][1:4] == expected
    core.push(0, 0.0, 0.0, 0.0, r)  # not later than the last sample
    core.push(5000, math.nan, 0.0, 0.0, r)
    core.push_frd(5000, np.array([math.inf, 0.0, 0.0]), r, 9.8)
    core.push(200_000, 0.0, 0.0, 0.0, r)  # a gap: held, then coasting (a virtual sample)
    core.trim_len = 4
    assert core.push_frd(205_000, f[::-1].copy(), list(r), 9.8) is False  # lists and any 3-array work
    assert len(core) == 4 and core.t_us == [0, 50_000, 200_000, 205_000]
    assert core.counts == (3, 1, 2, 1, 0)  # used, gaps, not finite, time not increasing, out of range
    gated = ImuHistory(0.05, 0.0, 100.0)  # max_force_m_s2: |f| per axis beyond it is not used
    gated.push_frd(0, np.array([0.0, 100.0, -9.7]), r, 9.8)  # at the bound: used
    gated.push_frd(5000, np.array([0.0, 0.0, -100.5]), r, 9.8)
    gated.push_frd(10_000, np.array([1e300, 0.0, 0.0]), r, 9.8)
    gated.push_frd(15_000, np.array([math.inf, 0.0, 0.0]), r, 9.8)  # not finite: counted as such
    assert gated.counts == (1, 0, 1, 0, 2) and gated.t_us == [0]
    assert core.push(210_000, 0.0, 0.0, 0.0, r) is True  # longer than trim_len: time to trim
    with pytest.raises(ValueError):
        core.push(300_000, 0.0, 0.0, 0.0, r[:8])


def test_quaternion_rotation_equals_the_float_form_bit_for_bit():
    rng = np.random.default_rng(4)
    for q in rng.standard_normal((200, 4)).tolist():
        n2 = sum(v * v for v in q)
        assert _core.rotation_q(np.array(q)) == rotation_scaled(*q, 2.0 / n2)
    assert _core.rotation_q((0.0, 0.0, 0.0, 0.0)) is None
    assert _core.rotation_q((math.nan, 0.0, 0.0, 1.0)) is None


def test_block_prediction_output_and_update_equal_the_numpy_reference():
    rng = np.random.default_rng(5)
    w, e, q = 0.3**2, 0.2**2, 0.08**2
    prop = model.BlockPropagator(q, w, e)
    h = ImuHistory(0.05)
    t_us, acc, rots = _stream(rng, 60)
    for t, a, r in zip(t_us, acc, rots, strict=True):
        h.append(t, *a, r)
    for k in range(20):
        P = _random_cov(rng)
        x = tuple(rng.standard_normal(N).tolist())
        t_a, t_b = sorted(rng.integers(t_us[0], t_us[-1], size=2).tolist())
        a, b = h.integrals(t_a), h.integrals(t_b)
        T, alpha, q_b = (t_b - t_a) * 1e-6, 0.98, 0.01 * k
        x_ref, nA, nB = h.propagate_mean(x, t_a, t_b, alpha), *_core.rotation_blocks(a, b)
        A, B = -np.array(nA).reshape(3, 3), -np.array(nB).reshape(3, 3)
        P_ref = model.predict_block(P, T, A, B, alpha, q, q_b, w, e)
        x_p, P_p, hph, pht_p = prop.predict_from(x, P, a, b, T, alpha, q_b)
        assert x_p == x_ref
        np.testing.assert_allclose(P_p, P_ref, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(np.array(hph), model.hmh(P_ref), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(pht_p, np.diag(P_ref[0:3, 0:3] + P_ref[0:3, 6:9]), rtol=1e-12, atol=1e-12)
        x_o, out = prop.output_from(x, P, a, b, T, alpha, q_b)
        assert x_o == x_ref and out[0:9].tolist() == list(x_ref[0:9])
        newest = prop.output_from(x, P, a, h, T, alpha, q_b)  # the history itself: its newest sample
        assert newest[1].tolist() == prop.output_from(x, P, a, h.last_integrals(), T, alpha, q_b)[1].tolist()
        np.testing.assert_allclose(out[9:18], np.diag(P_ref)[0:9], rtol=1e-12, atol=1e-12)
        # the update at that prior
        z = rng.standard_normal(3)
        r = tuple(rng.uniform(0.01, 1.0, 3).tolist())
        xr, Pr, _, _, nis_r = model.update(np.array(x_p), P_p, z, np.diag(r))
        y = tuple((z - (np.array(x_p[0:3]) + np.array(x_p[6:9]))).tolist())
        xu, Pu, nis = _core.update(x_p, P_p, y, r)
        np.testing.assert_allclose(xu, xr, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(Pu, Pr, rtol=1e-10, atol=1e-12)
        np.testing.assert_array_equal(Pu, Pu.T)
        assert nis == pytest.approx(nis_r, rel=1e-12)
    # the output path reads any layout of P; bad shapes are errors, not garbage
    P = _random_cov(rng)
    a, b = h.integrals(t_us[3]), h.integrals(t_us[9])
    assert prop.output_from(x, np.asfortranarray(P), a, b, 0.1, 0.9, 0.0)[1].tolist() == \
        prop.output_from(x, P, a, b, 0.1, 0.9, 0.0)[1].tolist()
    with pytest.raises(ValueError):
        prop.predict(np.eye(9), 0.1, nA, nB, 0.9, 0.0)
    with pytest.raises(ValueError):
        prop.output_from(x[:14], P, a, b, 0.1, 0.9, 0.0)


def test_the_core_holds_no_memory_on_the_callers_arrays():
    """numpy keeps a buffer description on every array that exported its buffer, for the array's
    life: a sample list kept by the caller (a replay, the bench's one-hour flight) would grow by
    it. The per-sample path reads arrays without the buffer protocol."""
    import tracemalloc

    rng = np.random.default_rng(8)
    f, q = list(rng.standard_normal((4000, 3))), list(rng.standard_normal((4000, 4)))  # kept alive
    core = ImuHistory(0.05)
    tracemalloc.start()
    before = tracemalloc.get_traced_memory()[0]
    for k in range(4000):
        core.push_frd(5000 * k, f[k], _core.rotation_q(q[k]), 9.8)
        if k % 256 == 0:
            core.trim_before(5000 * k - 100_000)
    grown = tracemalloc.get_traced_memory()[0] - before
    tracemalloc.stop()
    assert grown < 50_000  # the history's own buffer; 36 bytes × 8000 arrays if descriptions were kept


def _reference_push(state: dict, sample: object) -> None:
    """``Navigator.push`` as it was in Python before the C front (the reference of ``_core.Front``):
    ``state`` holds the history, gravity, the latest rotation, the counts, the waiting list and the
    call logs of ``pushed`` and ``other``."""
    from companion.domain.samples import AttitudeSample, ImuSample
    kind = type(sample)
    if kind is ImuSample:
        r = state["rot"]
        if r is None:
            state["counts"]["imu_rejected_no_attitude"] += 1
            return
        if state["hist"].push_frd(sample.t_us, sample.acc_frd_m_s2, r, state["g"]) or state["waiting"]:
            state["pushed"].append(len(state["hist"]))
    elif kind is AttitudeSample:
        r = _core.rotation_q(sample.q_ned_frd)
        if r is None:
            state["counts"]["attitude_rejected_nonfinite"] += 1
            return
        state["rot"] = r
        state["counts"]["attitude_used"] += 1
    else:
        state["other"].append(sample)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_navigator_front_equals_the_python_push_it_replaced(seed):
    """``_core.Front`` (the navigator's push of attitude and IMU samples) against the Python push it
    replaced, on a random stream with IMU before any attitude, zero and NaN quaternions, specific
    forces not finite or beyond the bound, times not increasing, other samples and a waiting list:
    the same history rows (bits), counts, calls of ``pushed`` and ``other``."""
    from companion.domain.samples import AttitudeSample, GnssFix, ImuSample
    rng = np.random.default_rng(seed)
    states = []
    for _ in range(2):
        counts = {"attitude_used": 0, "attitude_rejected_nonfinite": 0, "imu_rejected_no_attitude": 0}
        states.append({"hist": _core.History(0.05, 2.0, 100.0), "g": 9.80665, "rot": None, "counts": counts,
                       "waiting": [], "pushed": [], "other": []})
    ref, c = states
    c["hist"].trim_len = 150
    ref["hist"].trim_len = 150
    front = _core.Front(c["hist"], c["g"], ImuSample, AttitudeSample, c["other"].append,
                        lambda: c["pushed"].append(len(c["hist"])), c["waiting"])
    names = ("attitude_used", "attitude_rejected_nonfinite", "imu_rejected_no_attitude")
    samples: list[object] = [ImuSample(0, np.array([0.0, 0.0, -9.8]), np.zeros(3))]  # before any attitude
    t = 0
    for k in range(600):
        t += int(rng.choice([5000, 5000, 5000, 0, -3000, 60_000]))
        q = rng.standard_normal(4)
        u = rng.random()
        if u < 0.05:
            q = np.zeros(4)
        elif u < 0.1:
            q[rng.integers(4)] = rng.choice([math.nan, math.inf])
        samples.append(AttitudeSample(t, q))
        f = rng.standard_normal(3) * 3.0 + np.array([0.0, 0.0, -9.8])
        u = rng.random()
        if u < 0.04:
            f[rng.integers(3)] = rng.choice([math.nan, math.inf, 150.0, -1e300])
        samples.append(ImuSample(t, f if k % 2 else tuple(f.tolist()), np.zeros(3)))
        if k % 97 == 5:
            samples.append(GnssFix(t, 1.0, 2.0, 3.0, 3, 10))
        if k == 300:
            c["waiting"].append((t + 1, None))
            ref["waiting"].append((t + 1, None))
    for s in samples:
        assert front(s) is None
        _reference_push(ref, s)
        assert front.rot == ref["rot"]
    assert c["hist"].rows == ref["hist"].rows and c["hist"].counts == ref["hist"].counts
    c["counts"] = {name: getattr(front, name) for name in names}
    assert c["counts"] == ref["counts"] and c["counts"]["attitude_rejected_nonfinite"] > 0
    assert c["pushed"] == ref["pushed"] and len(c["pushed"]) > 300  # the waiting list: at every sample
    assert c["other"] == ref["other"] and len(c["other"]) == 7
    front.rot = None
    front(ImuSample(t + 5000, np.zeros(3), np.zeros(3)))
    assert front.imu_rejected_no_attitude == ref["counts"]["imu_rejected_no_attitude"] + 1
    front.rot = np.eye(3).ravel()
    assert front.rot == (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    with pytest.raises(TypeError):
        front()
    with pytest.raises(ValueError):
        front(AttitudeSample(t, np.zeros(3)))  # not 4 numbers
    with pytest.raises(ValueError):
        front.rot = (1.0, 0.0)


def test_a_navigator_is_collected_with_its_front():
    """The front refers back to its navigator (its bound methods): the cycle is collected."""
    import gc
    import weakref

    from companion.estimator import Navigator
    nav = Navigator()
    ref = weakref.ref(nav)
    del nav
    gc.collect()
    assert ref() is None
