"""The loose filter's per-sample speed-ups compute the same numbers, bit for bit, as what they replace:
the consistency factor's sums on floats (``consistency.fit_add3``, ``consistency.fit_inflation3``)
against ``consistency.Fit``'s numpy path, the vertical scatter of one axis (``consistency.Scatter1``) in
the engine against the two-axis ``Scatter`` given the axis twice, and ``samples.new_nav_estimate``
against ``NavEstimate(...)``."""

from __future__ import annotations

import dataclasses
import inspect
from typing import NamedTuple

import numpy as np
import pytest

from companion.domain.samples import AttitudeSample, ImuSample, NavEstimate, new_nav_estimate
from companion.estimator import engine as engine_module
from companion.estimator.config import EstimatorConfig
from companion.estimator.consistency import AXES3, Fit, Scatter, fit_add3, fit_inflation3, fix_floor
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
