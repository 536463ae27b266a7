"""Zenoh codec: every topic round-trips exactly, both ways, and malformed payloads are named."""

import json
import math

import numpy as np
import pytest

from companion.domain.samples import GnssFix, NavEstimate, Setpoint, TruthState
from companion.telemetry import codec as zc


def samples(rng: np.random.Generator) -> dict[str, object]:
    v = lambda: rng.normal(size=3)  # noqa: E731
    est = NavEstimate(123_456, v(), v(), v(), rng.uniform(0.01, 1, 9), 0.73, float("nan"), "second-order",
                      pos_horiz_test_ratio=0.42, gnss_rejected_innovation=3)
    fix = GnssFix(1_000_000, 47.3977419, 8.5455938, 488.25, 3, 12, 0.8, float("nan"))
    return {
        "estimate": est,
        "belief": zc.Belief.of(est),
        "health": zc.Health(5_000, {"imu_used": 200, "gnss_rejected_fix_type": 3}, "degraded"),
        "truth": TruthState(7_000, v(), v(), np.array([1.0, 0, 0, 0]), v(), 0.31, float("nan")),
        "gnss": zc.GnssReport(1_250_000, fix),
        "setpoint": Setpoint(9_000, v(), v(), v()),
        "route": zc.RouteInfo(0, "test", 2, rng.normal(size=(5, 3)), 42.5,
                              np.array([[0.0, 0, 10, 20], [30, 5, 40, 15]]), v(),
                              np.array([52.52, 13.405, 35.0])),
        "status": zc.FlightStatus(11_000, "HOLD", True),
    }


def assert_same(a, b):
    assert type(a) is type(b)
    for name in a.__slots__:
        x, y = getattr(a, name), getattr(b, name)
        if isinstance(x, np.ndarray):
            np.testing.assert_array_equal(x, y)  # exact: JSON floats round-trip bit for bit
        elif isinstance(x, float) and math.isnan(x):
            assert math.isnan(y)
        elif hasattr(x, "__slots__"):
            assert_same(x, y)
        else:
            assert x == y, name


def test_all_topics_round_trip_exactly():
    objs = samples(np.random.default_rng(1))
    assert set(objs) == set(zc.TOPICS)
    for topic, obj in objs.items():
        payload = zc.encode(topic, obj, sent_unix_ns=17)
        back, sent = zc.decode(topic, payload)
        assert sent == 17
        assert_same(obj, back)
        # and the other way: JSON -> object -> JSON is the identity
        assert zc.encode(topic, back, sent_unix_ns=17) == payload


def test_fields_added_later_may_be_missing_from_older_payloads():
    """An older publisher (or recording) sends no estimate gate fields and no route home: decoded
    with the type's defaults; any other missing field is still malformed."""
    objs = samples(np.random.default_rng(3))
    later = {"estimate": ("pos_horiz_test_ratio", "gnss_rejected_innovation"), "route": ("home_lla",)}
    for topic, added in later.items():
        d = json.loads(zc.encode(topic, objs[topic], 5))
        for name in added:
            del d[name]
        back, _ = zc.decode(topic, json.dumps(d).encode())
        default = type(objs[topic])(**{k: getattr(back, k) for k in back.__slots__ if k not in added})
        assert_same(back, default)
    d = json.loads(zc.encode("status", objs["status"], 5))
    assert d["armed"] is True and d["mode"] == "HOLD"
    with pytest.raises(zc.MalformedPayloadError, match=r"status\.armed: expected true or false"):
        zc.decode("status", json.dumps({**d, "armed": 1}).encode())
    del d["mode"]
    with pytest.raises(zc.MalformedPayloadError, match=r"status\.mode: missing"):
        zc.decode("status", json.dumps(d).encode())


def test_payload_is_plain_json_with_documented_fields():
    objs = samples(np.random.default_rng(2))
    d = json.loads(zc.encode("gnss", objs["gnss"], 5))
    assert d["latency_s"] == pytest.approx(0.25)
    assert d["v_acc_m"] is None  # NaN travels as null
    d = json.loads(zc.encode("estimate", objs["estimate"], 5))
    assert d["nis"] is None and len(d["cov_diag"]) == 9 and d["method"] == "second-order"


@pytest.mark.parametrize("hdop", [1.35, float("nan")])
def test_gnss_hdop_round_trips_and_nan_travels_as_null(hdop):
    fix = GnssFix(1_000_000, 47.3977419, 8.5455938, 488.25, 3, 12, 0.8, 1.1, hdop)
    payload = zc.encode("gnss", zc.GnssReport(1_200_000, fix), 5)
    assert json.loads(payload)["hdop"] == (None if math.isnan(hdop) else hdop)
    back, _ = zc.decode("gnss", payload)
    assert_same(zc.GnssReport(1_200_000, fix), back)
    with pytest.raises(zc.MalformedPayloadError, match=r"gnss\.hdop: expected a finite number"):
        zc.decode("gnss", payload.replace(b'"hdop":', b'"hdop":"x","_":'))


def test_key_round_trip_and_foreign_keys():
    key = zc.key_for("uav1", "companion", "estimate")
    assert key == "beliefnav/uav1/companion/estimate"
    assert zc.split_key(key) == ("uav1", "companion", "estimate")
    for bad in ("beliefnav/uav1/estimate", "other/uav1/companion/estimate", "beliefnav//companion/x"):
        with pytest.raises(zc.MalformedPayloadError):
            zc.split_key(bad)
    with pytest.raises(ValueError):
        zc.key_for("uav/1", "companion", "estimate")


@pytest.mark.parametrize(
    ("topic", "payload", "field"),
    [
        ("estimate", b"\xff\xfe", "not JSON"),
        ("estimate", b"[1, 2]", "expected a JSON object"),
        ("belief", b'{"t_us": 1, "beta": 0.5, "nis": 1.0}', "belief.method: missing"),
        ("belief", b'{"t_us": 1.5, "beta": 0.5, "nis": 1.0, "method": "x"}', "belief.t_us"),
        ("belief", b'{"t_us": 1, "beta": null, "nis": 1.0, "method": "x"}', "belief.beta"),
        ("belief", b'{"t_us": 1, "beta": true, "nis": 1.0, "method": "x"}', "belief.beta"),
        ("setpoint", b'{"t_us": 1, "p_ned_m": [1, 2], "v_ned_m_s": [0,0,0], "a_ned_m_s2": [0,0,0]}',
         "setpoint.p_ned_m: expected shape 3"),
        ("setpoint", b'{"t_us": 1, "p_ned_m": [1, null, 3], "v_ned_m_s": [0,0,0], "a_ned_m_s2": [0,0,0]}',
         "setpoint.p_ned_m: expected finite"),
        ("setpoint", b'{"t_us": 1, "p_ned_m": ["a", 2, 3], "v_ned_m_s": [0,0,0], "a_ned_m_s2": [0,0,0]}',
         "setpoint.p_ned_m"),
        ("health", b'{"t_us": 1, "counters": {"a": "x"}, "status": "ok"}', "health.counters.a"),
        ("nonsense", b"{}", "unknown topic"),
    ],
)
def test_malformed_payloads_raise_one_named_error(topic, payload, field):
    with pytest.raises(zc.MalformedPayloadError, match=field.replace(".", r"\.")) as info:
        zc.decode(topic, payload)
    assert "\n" not in str(info.value)


def test_encode_rejects_wrong_type():
    with pytest.raises(TypeError, match="carries Setpoint"):
        zc.encode("setpoint", zc.Belief(1, 0.5, 1.0, "x"), 0)


def test_nesting_depth_is_counted_on_the_parsed_payload():
    """Known answers: the top level is depth 1; brackets inside strings do not count."""
    import json

    from companion.telemetry.codec import _nested_deeper_than

    assert not _nested_deeper_than(json.loads('{"a": "[[[[[[[[[[[[", "b": [[1, 2], [3]]}'), 3)
    assert _nested_deeper_than(json.loads('{"b": [[1, 2], [3]]}'), 2)
    assert _nested_deeper_than(json.loads("[" * 9 + "]" * 9), 8)
    assert not _nested_deeper_than(json.loads("[" * 8 + "]" * 8), 8)
    assert not _nested_deeper_than(5, 0)


def test_vector_fast_path_agrees_with_the_general_path():
    """A list of n finite JSON floats takes the one-numpy-call path; anything else the validating
    one: the same arrays (float64, exact values) and the same named errors either way."""
    vec3, opt3 = zc._dec_array((3,)), zc._dec_array((3,), optional=True)
    for v in ([0.5, -0.0, 1e308], [1, 2.5, 3]):  # all floats: fast path; with an int: general path
        a = vec3(v, "x")
        assert a.dtype == np.float64 and a.shape == (3,)
        np.testing.assert_array_equal(a, [float(x) for x in v])
        assert math.copysign(1.0, a[1]) == math.copysign(1.0, float(v[1]))  # -0.0 kept
    np.testing.assert_array_equal(opt3([1.0, None, 3.0], "x"), [1.0, np.nan, 3.0])
    for bad, msg in (([float("inf"), 1.0, 2.0], "x: expected finite"),
                     ([float("nan")] * 3, "x: expected finite"),
                     ([1.0, 2.0], "x: expected shape 3, got 2"), ([1.0] * 4, "x: expected shape 3, got 4"),
                     ((1.0, 2.0, 3.0), "x: expected a list")):
        with pytest.raises(zc.MalformedPayloadError, match=msg):
            vec3(bad, "x")
