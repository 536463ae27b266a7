"""The loose filter's per-sample speed-ups compute the same numbers, bit for bit, as what they replace:
the consistency factor's sums on floats (``consistency.fit_add3``, ``consistency.fit_inflation3``)
against ``consistency.Fit``'s numpy path, the vertical scatter of one axis (``consistency.Scatter1``) in
the engine against the two-axis ``Scatter`` given the axis twice, and ``samples.new_nav_estimate``
against ``NavEstimate(...)``, and the C core's per-fix sums (``Scatter.add``, ``Scatter1.add``, ``fit_add3``)
against the Python forms they replaced (kept here)."""

from __future__ import annotations

import dataclasses
import inspect
import math
from typing import NamedTuple

import numpy as np
import pytest

from companion.domain.samples import AttitudeSample, ImuSample, NavEstimate, new_nav_estimate
from companion.estimator import engine as engine_module
from companion.estimator.config import EstimatorConfig
from companion.estimator.consistency import AXES3, Fit, Scatter, Scatter1, fit_add3, fit_inflation3, fix_floor
from companion.estimator.engine import FusionEngine
from tests.estimator_streams import OPEN_SKY, drive, multipath_stream

CFG = EstimatorConfig()


def test_fit_on_floats_equals_the_numpy_fit():
    """Innovations from unit to 3σ with irregular intervals (the factor then well above 1): every sum
    and every factor equal to ``Fit.add`` / ``Fit.inflation``'s, bit for bit."""
    rng = np.random.default_rng(3)
    ref, fast, t = Fit(), Fit(), 0
    assert fit_inflation3(fast) == ref.inflation() == 1.0  # no fix yet
    above = 0
    for k in range(3000):
        t += int(rng.integers(20_000, 400_000))
        nu = rng.standard_normal(3) * (3.0 if (k // 200) % 2 else 1.0) + (0.5 if k % 500 < 100 else 0.0)
        ref = ref.add(t, AXES3, nu, 5.0)
        fast = fit_add3(fast, t, *nu.tolist(), 5.0)
        assert fast.key is AXES3 and fast.t_us == ref.t_us == t
        assert fast.nu_sum.tolist() == ref.nu_sum.tolist() and fast.w2_sum.tolist() == ref.w2_sum.tolist()
        assert fit_inflation3(fast) == ref.inflation()
        above += ref.inflation() > 1.0
    assert 300 < above < 2900  # both sides of the floor at 1 were compared


def test_the_engine_fit_equals_the_numpy_fit(monkeypatch):
    """On a stream with multipath segments (the factor above 1), every entry's Fit and factor equal, bit
    for bit, those of the same engine adding each fix's innovations through ``Fit.add``."""
    stream = multipath_stream(np.random.default_rng(7), CFG, [(6.0, 0.0), (10.0, 1.2)])
    fast = FusionEngine(CFG, "second-order", context=OPEN_SKY)
    drive(stream, fast, stream.fix_t_us)
    monkeypatch.setattr(engine_module, "fit_add3",
                        lambda fit, t, a, b, c, w: fit.add(t, AXES3, np.array((a, b, c)), w))
    ref = FusionEngine(CFG, "second-order", context=OPEN_SKY)
    drive(stream, ref, stream.fix_t_us)
    assert len(fast.entries) == len(ref.entries) > 40  # (the last history_s of them)
    for a, b in zip(fast.entries, ref.entries, strict=True):
        assert a.t_us == b.t_us and a.x == b.x and a.fit.t_us == b.fit.t_us
        assert a.fit.nu_sum.tolist() == b.fit.nu_sum.tolist()
        assert a.fit.w2_sum.tolist() == b.fit.w2_sum.tolist()
        assert fit_inflation3(a.fit) == b.fit.inflation()
    assert max(e.fit.inflation() for e in ref.entries) > 1.5


class _TwoEqualAxes(NamedTuple):
    """The vertical scatter as the engine kept it before ``Scatter1``: a two-axis ``Scatter`` given the
    one axis twice."""

    s: Scatter = Scatter()

    def add(self, t_us: int, z: float, v: float, window_s: float) -> _TwoEqualAxes:
        return _TwoEqualAxes(self.s.add(t_us, (z, z), (v, v), window_s))

    def variance(self) -> float:
        return self.s.variance()

    def correlation(self) -> float:
        return self.s.correlation()


def test_the_engine_vertical_scatter_equals_two_equal_axes(monkeypatch):
    """On a stream with multipath segments (the fixes correlated), every entry's vertical scatter
    (``consistency.Scatter1``) holds the sums, and gives the floor (``fix_floor``), of the same engine
    keeping a two-axis ``Scatter`` of the vertical given twice, bit for bit; the states are the same."""
    stream = multipath_stream(np.random.default_rng(7), CFG, [(6.0, 0.0), (10.0, 1.2)])
    fast = FusionEngine(CFG, "second-order", context=OPEN_SKY)
    drive(stream, fast, stream.fix_t_us)
    monkeypatch.setattr(engine_module, "Scatter1", _TwoEqualAxes)
    ref = FusionEngine(CFG, "second-order", context=OPEN_SKY)
    drive(stream, ref, stream.fix_t_us)
    assert len(fast.entries) == len(ref.entries) > 40
    for a, b in zip(fast.entries, ref.entries, strict=True):
        sa, sb = a.scatter_v, b.scatter_v.s
        assert a.t_us == b.t_us and a.x == b.x and sa.t_us == sb.t_us
        assert (sa.q, sa.q_sum, sa.q2_sum) == (sb.q[0], sb.q_sum[0], sb.q2_sum[0])
        assert (sa.q, sa.q_sum, sa.q2_sum) == (sb.q[1], sb.q_sum[1], sb.q2_sum[1])
        assert (sa.w_sum, sa.w2_sum, sa.d1_sum, sa.d2_sum, sa.d_w_sum) == (
            sb.w_sum, sb.w2_sum, sb.d1_sum, sb.d2_sum, sb.d_w_sum)
        assert fix_floor(sa, a.r_nominal_m2[2]) == fix_floor(sb, b.r_nominal_m2[2])
        assert sa.variance() == sb.variance() and sa.correlation() == sb.correlation()
    last = fast.entries[-1].scatter_v
    assert last.correlation() > 1.0 and last.variance() > 0.0  # not a trivial 1 = 1


@pytest.mark.parametrize("kwargs", [{}, {"pos_valid": False, "gnss_resets": 3, "vel_test_ratio": 0.5}])
def test_new_nav_estimate_is_nav_estimate(kwargs):
    """The same object as the dataclass's constructor: type, every field, defaults, frozen."""
    args = (7, np.ones(3), np.zeros(3), np.full(3, 2.0), np.arange(9.0), 0.25, 1.5, "second-order")
    a, b = new_nav_estimate(*args, **kwargs), NavEstimate(*args, **kwargs)
    assert type(a) is NavEstimate and repr(a) == repr(b)
    for f in dataclasses.fields(NavEstimate):
        assert getattr(a, f.name) is getattr(b, f.name) or getattr(a, f.name) == getattr(b, f.name)
    with pytest.raises(dataclasses.FrozenInstanceError):
        a.t_us = 8  # type: ignore[misc]


@pytest.mark.parametrize("cls", [ImuSample, AttitudeSample])
def test_sample_init_through_the_slots_is_the_dataclass_init(cls):
    """The per-sample types' ``__init__`` (set through the slots) against a dataclass's own generated one for
    the same fields: the same signature, every field the very object given, defaults, keywords, frozen, the
    same errors."""
    ref = dataclasses.dataclass(frozen=True, slots=True)(type(cls.__name__, (), {
        "__annotations__": {f.name: f.type for f in dataclasses.fields(cls)},
        **{f.name: f.default for f in dataclasses.fields(cls) if f.default is not dataclasses.MISSING}}))
    assert inspect.signature(cls) == inspect.signature(ref)
    assert cls.__init__ is not ref.__init__ and cls.__init__.__qualname__ == f"{cls.__name__}.__init__"
    values = [7, np.ones(3), np.zeros(3), 12.5][:len(dataclasses.fields(cls))]
    names = [f.name for f in dataclasses.fields(cls)]
    for args, kwargs in ((values, {}), (values[:2], dict(zip(names[2:], values[2:], strict=True))),
                         ([], dict(zip(names, values, strict=True))), (values[:3], {})):
        if len(args) + len(kwargs) < sum(f.default is dataclasses.MISSING for f in dataclasses.fields(cls)):
            continue
        a, b = cls(*args, **kwargs), ref(*args, **kwargs)
        for name in names:
            assert getattr(a, name) is getattr(b, name)
        with pytest.raises(dataclasses.FrozenInstanceError):
            a.t_us = 8
    for bad_args, bad_kwargs in ((values[:1], {}), (values + [1, 2], {}), (values, {"t_us": 3}),
                                 (values, {"nope": 1})):
        with pytest.raises(TypeError) as got:
            cls(*bad_args, **bad_kwargs)
        with pytest.raises(TypeError) as want:
            ref(*bad_args, **bad_kwargs)
        assert str(got.value).split("(")[1:] == str(want.value).split("(")[1:]


def test_the_sorted_union_equals_numpys():
    """``Fit.add``'s union of channel keys equals ``np.union1d``'s (empty, disjoint, overlapping,
    repeated keys)."""
    from companion.estimator.consistency import _sorted_union

    rng = np.random.default_rng(11)
    empty = np.zeros(0, dtype=np.int64)
    cases = [(empty, empty), (empty, AXES3), (AXES3, empty)]
    cases += [(np.unique(rng.integers(0, 40, rng.integers(0, 12))), rng.integers(0, 40, rng.integers(0, 12)))
              for _ in range(500)]
    for a, b in cases:
        got, want = _sorted_union(a, b), np.union1d(a, b)
        assert got.dtype == want.dtype and got.tolist() == want.tolist()


def test_no_import_falls_inside_the_first_fixes():
    """Nothing is imported while the first fixes are fused (``np.unique`` imported ``numpy.ma``, 11 ms,
    inside the first fix): a fresh interpreter, the benchmark's flight."""
    import subprocess
    import sys
    import textwrap

    code = textwrap.dedent("""
        import sys
        from gcs_tools.bench import estimator as be
        from companion.wiring import navigator_for
        samples = be.flight(3.0, None)
        nav = navigator_for(None, be.METHOD, frame=be.HOME)
        before = set(sys.modules)
        for s in samples:
            nav.push(s)
            nav.estimate()
        assert nav.counters()["gnss_fused"] > 50, nav.counters()
        print(" ".join(sorted(set(sys.modules) - before)))
        """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split() == [], out.stdout


def _scatter_add_reference(self: Scatter, t_us: int, z: tuple[float, float], v: tuple[float, float],
                           window_s: float) -> Scatter:
    """``Scatter.add`` as it was in Python (what the C core's ``scatter_add`` replaced)."""
    t0, z0, v0, q, qp, w, w2, s, s2, d1, d2, dw = self
    if t0 < 0:
        return Scatter(t_us, z, v, (0.0, 0.0), None, 1.0, 1.0, (0.0, 0.0), (0.0, 0.0))
    dt = (t_us - t0) * 1e-6
    a = math.exp(-dt / window_s)
    h = 0.5 * dt
    q0 = q[0] + (z[0] - z0[0]) - h * (v[0] + v0[0])
    q1 = q[1] + (z[1] - z0[1]) - h * (v[1] + v0[1])
    d1, d2, dw = a * d1, a * d2, a * dw
    if qp is not None:
        d1 += (q0 - q[0]) ** 2 + (q1 - q[1]) ** 2
        d2 += (q0 - qp[0]) ** 2 + (q1 - qp[1]) ** 2
        dw += 1.0
    s, s2 = (a * s[0] + q0, a * s[1] + q1), (a * s2[0] + q0 * q0, a * s2[1] + q1 * q1)
    return Scatter(t_us, z, v, (q0, q1), q, a * w + 1.0, a * a * w2 + 1.0, s, s2, d1, d2, dw)


def _scatter1_add_reference(self: Scatter1, t_us: int, z: float, v: float, window_s: float) -> Scatter1:
    """``Scatter1.add`` as it was in Python (what the C core's ``scatter1_add`` replaced)."""
    t0, z0, v0, q0, qp, w, w2, s, s2, d1, d2, dw = self
    if t0 < 0:
        return Scatter1(t_us, z, v, 0.0, None, 1.0, 1.0, 0.0, 0.0)
    dt = (t_us - t0) * 1e-6
    a = math.exp(-dt / window_s)
    q = q0 + (z - z0) - (0.5 * dt) * (v + v0)
    d1, d2, dw = a * d1, a * d2, a * dw
    if qp is not None:
        e1, e2 = (q - q0) ** 2, (q - qp) ** 2
        d1 += e1 + e1
        d2 += e2 + e2
        dw += 1.0
    return Scatter1(t_us, z, v, q, q0, a * w + 1.0, a * a * w2 + 1.0, a * s + q, a * s2 + q * q, d1, d2, dw)


def _same(a: object, b: object) -> bool:
    """Equal, NaN equal to NaN, recursively through tuples; the same types."""
    if isinstance(a, tuple) or isinstance(b, tuple):
        return (type(a) is type(b) and len(a) == len(b)  # type: ignore[arg-type]
                and all(_same(x, y) for x, y in zip(a, b, strict=True)))  # type: ignore[call-overload]
    if isinstance(a, float) and isinstance(b, float) and a != a:
        return b != b
    return type(a) is type(b) and a == b


@pytest.mark.parametrize("seed", [0, 1])
def test_the_scatters_add_in_c_as_in_python(seed):
    """``Scatter.add`` and ``Scatter1.add`` (the C core's ``scatter_add``/``scatter1_add`` after the first
    fix) against their Python forms: every field the same bits and types (the fix and velocity the very
    objects given, the previous q kept) over random series with gaps, equal times, NaN and infinite
    fixes, and the same OverflowError where a squared change overflows."""
    rng = np.random.default_rng(seed)
    c2, r2, c1, r1 = Scatter(), Scatter(), Scatter1(), Scatter1()
    t = 0
    for k in range(2000):
        t += int(rng.choice([0, 50_000, 200_000, 3_000_000]))
        z = tuple((rng.standard_normal(2) * float(rng.choice([0.1, 10.0]))).tolist())
        v = tuple(rng.standard_normal(2).tolist())
        if k % 97 == 13:
            z = (float(rng.choice([math.nan, math.inf])), z[1])
        c2, r2 = c2.add(t, z, v, 20.0), _scatter_add_reference(r2, t, z, v, 20.0)
        c1, r1 = c1.add(t, z[0], v[0], 20.0), _scatter1_add_reference(r1, t, z[0], v[0], 20.0)
        assert _same(c2, r2) and _same(c1, r1), k
        assert c2.z is z and c2.v is v and c1.z is z[0]
        assert c2.statistics() == r2.statistics() or _same(c2.statistics(), r2.statistics())
        if k % 300 == 299:  # start again (a NaN poisons the sums for good)
            c2, r2, c1, r1 = Scatter(), Scatter(), Scatter1(), Scatter1()
    big = Scatter().add(0, (0.0, 0.0), (0.0, 0.0), 20.0).add(1000, (1e200, 0.0), (0.0, 0.0), 20.0)
    with pytest.raises(OverflowError):
        _scatter_add_reference(big, 2000, (-1e200, 0.0), (0.0, 0.0), 20.0)
    with pytest.raises(OverflowError):
        big.add(2000, (-1e200, 0.0), (0.0, 0.0), 20.0)
    big1 = Scatter1().add(0, 0.0, 0.0, 20.0).add(1000, 1e200, 0.0, 20.0)
    with pytest.raises(OverflowError):
        _scatter1_add_reference(big1, 2000, -1e200, 0.0, 20.0)
    with pytest.raises(OverflowError):
        big1.add(2000, -1e200, 0.0, 20.0)


def test_fit_add3_with_nan_and_infinite_innovations_as_the_numpy_fit():
    """``fit_add3`` (its sums in the C core) against ``Fit.add`` where innovations are NaN or infinite."""
    ref, fast, t = Fit(), Fit(), 0
    nus = [(0.1, -0.2, 0.3), (math.nan, 0.0, 1.0), (math.inf, -math.inf, 0.0), (1.0, 2.0, 3.0)]
    for k, nu in enumerate(nus):
        t += 100_000 * (k + 1)
        ref, fast = ref.add(t, AXES3, np.array(nu), 5.0), fit_add3(fast, t, *nu, 5.0)
        assert type(fast) is Fit and fast.key is AXES3 and fast.t_us == t
        np.testing.assert_array_equal(fast.nu_sum, ref.nu_sum)
        np.testing.assert_array_equal(fast.w2_sum, ref.w2_sum)


def _reported_reference(a: np.ndarray, k: float, floor: tuple[float, float, float, float] | None
                        ) -> tuple[np.ndarray, ...]:
    """What ``Navigator.estimate`` reported from a snapshot's ``out`` before the C core's ``reported``: the
    position variances × k (``variance_scale``), floored per axis where the fixes are correlated."""
    from companion.estimator.consistency import floored_axis, variance_scale
    scale = variance_scale(k)
    var = a[9:18] if scale is None else a[9:18] * scale
    if floor is not None:
        var = var.copy() if scale is None else var
        c, s2, c_v, s2_v = floor
        if c > 1.0:
            var[0], var[1] = floored_axis(float(a[9]), k, c, s2), floored_axis(float(a[10]), k, c, s2)
        if c_v > 1.0:
            var[2] = floored_axis(float(a[11]), k, c_v, s2_v)
    return a[0:3], a[3:6], a[6:9], var


def test_the_reported_estimate_in_c_as_in_python():
    """``_core.reported`` against the navigator's former numpy form: the same bits (NaN where NaN) on random
    snapshots with NaN, infinite, zero and negative entries, factors 1 and above, floors absent, inactive
    (c ≤ 1) and active on either axis; new arrays, the snapshot untouched."""
    from companion.estimator._core import reported
    rng = np.random.default_rng(11)
    special = [math.nan, math.inf, -math.inf, 0.0, -0.0, -1.0, 1e-300]
    for n in range(3000):
        a = rng.standard_normal(18) * 10.0
        a[9:18] = np.abs(a[9:18])
        if n % 3 == 0:
            a[rng.integers(18)] = special[int(rng.integers(len(special)))]
        k = 1.0 if n % 2 else float(1.0 + rng.exponential(2.0))
        floor: tuple[float, float, float, float] | None = None
        if n % 5:
            floor = (float(rng.choice([0.5, 1.0, 3.0, 100.0])), float(rng.exponential(1.0)),
                     float(rng.choice([1.0, 1.5, 40.0])), float(rng.choice([0.0, 2.0, math.inf])))
        before = a.copy()
        got, want = reported(a, k, floor), _reported_reference(a, k, floor)
        for g, w in zip(got, want, strict=True):
            assert g.dtype == np.float64 and g.shape == w.shape and not np.shares_memory(g, a)
            np.testing.assert_array_equal(g, w)
            assert np.signbit(g).tolist() == np.signbit(w).tolist()
        np.testing.assert_array_equal(a, before)
    with pytest.raises(ValueError):
        reported(np.zeros(17), 1.0, None)


@pytest.mark.parametrize("kwargs", [{}, {"pos_valid": False, "gnss_resets": 3, "vel_test_ratio": 0.5}])
def test_the_navigator_estimate_built_in_c_is_nav_estimate(kwargs):
    """``_core.slots_new`` through NavEstimate's slots (the navigator's estimate()): the same object as the
    dataclass's constructor given every field (type, each field the very object, frozen); a wrong count or a
    non-descriptor is a TypeError."""
    from companion.estimator._core import slots_new
    from companion.estimator.navigator import _ESTIMATE_FIELDS
    args = (7, np.ones(3), np.zeros(3), np.full(3, 2.0), np.arange(9.0), 0.25, 1.5, "second-order")
    b = NavEstimate(*args, **kwargs)
    values = [getattr(b, f.name) for f in dataclasses.fields(NavEstimate)]
    a = slots_new(NavEstimate, _ESTIMATE_FIELDS, *values)
    assert type(a) is NavEstimate and repr(a) == repr(b) and a == b
    for f in dataclasses.fields(NavEstimate):
        assert getattr(a, f.name) is getattr(b, f.name)
    with pytest.raises(dataclasses.FrozenInstanceError):
        a.t_us = 8  # type: ignore[misc]
    with pytest.raises(TypeError):
        slots_new(NavEstimate, _ESTIMATE_FIELDS, *values[:-1])
    with pytest.raises(TypeError):
        slots_new(NavEstimate, (1,) * len(values), *values)


def test_the_named_tuples_built_without_their_new_get_every_field():
    """``_new(Cls, (...))`` (tuple.__new__, the engine's and consistency's per-fix and per-estimate path)
    skips the NamedTuple's own __new__ and its defaults: every such call in the code passes all the fields."""
    import ast

    from companion.estimator import belief, consistency, engine
    names = {**vars(engine), **vars(consistency), **vars(belief)}
    n_calls = 0
    for module in (engine, consistency):
        for node in ast.walk(ast.parse(inspect.getsource(module))):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "_new":
                cls = names[node.args[0].id]  # type: ignore[attr-defined]
                assert isinstance(node.args[1], ast.Tuple) and len(node.args[1].elts) == len(cls._fields), cls
                n_calls += 1
    assert n_calls >= 4


def test_the_navigator_floor_and_factor_in_c_as_in_python():
    """``_core.fix_floors`` and ``_core.inflation3`` (the navigator's accuracy_inflation) against
    ``consistency.fix_floor`` of each scatter and ``fit_inflation3``: the same bits on scatters of random
    series (independent, correlated, a few fixes, NaN), stated variances finite, infinite, NaN; None exactly
    where neither correlation is above 1."""
    from companion.estimator._core import fix_floors, inflation3
    rng = np.random.default_rng(21)
    n_floor = n_none = 0
    for n in range(400):
        h, v, t, bias = Scatter(), Scatter1(), 0, np.zeros(3)
        rho = float(rng.choice([0.0, 0.9, 0.99]))
        for _ in range(int(rng.integers(1, 60))):
            t += 200_000
            bias = rho * bias + rng.standard_normal(3)
            z = tuple((bias * float(rng.choice([0.1, 2.0]))).tolist())
            h, v = h.add(t, (z[0], z[1]), (0.0, 0.0), 20.0), v.add(t, z[2], 0.0, 20.0)
        if n % 41 == 0:
            h = h._replace(q2_sum=(math.nan, h.q2_sum[1]))
        r_h, r_v = (float(rng.choice([0.01, 4.0, math.inf, math.nan])) for _ in range(2))
        want_h, want_v = fix_floor(h, r_h), fix_floor(v, r_v)
        got = fix_floors(h, v, r_h, r_v)
        if want_h[0] > 1.0 or want_v[0] > 1.0:
            assert got is not None
            assert _same(got, (*want_h, *want_v)), (got, want_h, want_v)
            n_floor += 1
        else:
            assert got is None
            n_none += 1
    assert n_floor > 50 and n_none > 50
    fit = Fit()
    for k, nu in enumerate([(0.1, -0.2, 0.3), (3.0, 2.0, -4.0), (math.nan, 0.0, 1.0), (math.inf, 0.0, 0.0)]):
        fit = fit_add3(fit, 100_000 * (k + 1), *nu, 5.0)
        got_k, want_k = inflation3(fit.nu_sum, fit.w2_sum), fit_inflation3(fit)
        assert got_k == want_k or (got_k != got_k and want_k != want_k)
    empty = Fit(AXES3, np.zeros(3), np.zeros(3), 0)
    assert inflation3(empty.nu_sum, empty.w2_sum) == 1.0 == fit_inflation3(empty)
