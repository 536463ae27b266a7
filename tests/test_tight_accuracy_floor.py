"""The tight filter's common-mode floor on its reported accuracy (``TightConfig.accuracy_floor_m``): the
position DOPs it scales (a known answer), the reported variances it raises (P × k + floor² × DOPs), and
the estimate it leaves alone (bit-identical)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.tight import TightConfig, TightNavigator
from companion.tight.model import position_dop_ned
from tests.gnss_helpers import hold_at_rest, store

STORE = store()


def test_position_dops_known_answer():
    """One satellite at the zenith, three on the horizon 120° apart, one clock: GᵀG is diagonal in N, E
    (1.5 each) and couples D with the clock ([[1, 1], [1, 4]]): q = (2/3, 2/3, 4/3). A second system's
    clock on one horizon satellite leaves its range to the clock alone: N, E lose it. Too few: NaN."""
    el, az = np.array([90.0, 0.0, 0.0, 0.0]), np.radians([0.0, 0.0, 120.0, 240.0])
    np.testing.assert_allclose(position_dop_ned(el, az, np.zeros(4, int)), [2 / 3, 2 / 3, 4 / 3], atol=1e-12)
    el5, az5 = np.append(el, 45.0), np.append(az, 0.3)
    one = position_dop_ned(el5, az5, np.zeros(5, int))
    two = position_dop_ned(el5, az5, np.array([0, 0, 0, 0, 1]))
    np.testing.assert_allclose(two, [2 / 3, 2 / 3, 4 / 3], atol=1e-12)  # the 5th only fixes its clock
    assert (one < two).all()
    assert np.isnan(position_dop_ned(el[:3], az[:3], np.zeros(3, int))).all()


def _fly(floor_m: float) -> TightNavigator:
    nav = TightNavigator(TightConfig(accuracy_floor_m=floor_m), "second-order", ephemerides=STORE)
    hold_at_rest(nav, STORE, 100)
    return nav


def test_floor_adds_in_quadrature_and_leaves_the_estimate_bit_identical():
    """Floor 3 m: the reported position variances are those without it + 9 m² × the last epoch's used
    satellites' DOPs (HDOP of the synthetic sky: 0.5-2), everything else (position, velocity, the
    velocity variances, the inflation) bit-identical."""
    base, floored = _fly(0.0), _fly(3.0)
    a, b = base.estimate(), floored.estimate()
    assert a is not None and b is not None
    for name in ("p_ned_m", "v_ned_m_s"):
        assert np.array_equal(getattr(a, name), getattr(b, name))
    assert np.array_equal(a.cov_diag[3:], b.cov_diag[3:])
    assert base.accuracy_inflation() == floored.accuracy_inflation()
    assert base.accuracy_floor_m2() is None
    last = floored.engine.entries[-1]
    u = np.flatnonzero(last.info.used)
    q = position_dop_ned(last.meas.elevation_deg[u], last.meas.azimuth_rad[u], last.meas.slot[u])
    assert 0.5 < math.sqrt(q[0] + q[1]) < 2.0
    np.testing.assert_allclose(b.cov_diag[0:3], np.asarray(a.cov_diag[0:3]) + 9.0 * q, rtol=1e-12)


@pytest.mark.parametrize("bad", [-1.0, math.nan, math.inf])
def test_floor_must_be_finite_and_not_negative(bad):
    with pytest.raises(ValueError, match="accuracy_floor_m"):
        TightConfig(accuracy_floor_m=bad).validate()
