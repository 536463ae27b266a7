"""The broadcast accuracy's consumers: a satellite whose ephemeris says "no accuracy prediction"
(Galileo NAPA, GPS/BeiDou URA index 15: ``accuracy_m`` inf) is left out of the single-point solution
and of the tightly coupled filter, counted by name; "not given" (NaN) and a given accuracy (SISA
3.12 m) are used. Known answers on a constructed sky: the solution without the satellite, exactly."""

from __future__ import annotations

import dataclasses
import math
from collections import Counter

import numpy as np
import pytest

from companion.gnss import SppConfig, attach_broadcast, solve_position
from companion.gnss.ephemeris import EphemerisStore
from companion.gnss.inav import SISA_NAPA, sisa_m
from companion.gnss.lnav import ura_m
from companion.gnss.systems import System
from companion.tight import TightConfig, TightNavigator
from simvehicle.constellation import BROADCAST_ACCURACY_M, constellation
from tests.gnss_helpers import KLOBUCHAR, RX_ECEF, T0, hold_at_rest, observe
from tests.gnss_helpers import constellation as synthetic_sky

KEP, GLO = synthetic_sky()


def _sky(target: tuple[int, int], accuracy_m: float) -> EphemerisStore:
    """The synthetic sky with every Keplerian satellite at SISA 3.12 m / URA 2.4 m and ``target``
    (system, prn) at ``accuracy_m``."""
    kep = [dataclasses.replace(e, accuracy_m=accuracy_m if (e.system, e.prn) == target else
                               sisa_m(107) if e.system == System.GALILEO else ura_m(0)) for e in KEP]
    return EphemerisStore(kep, GLO, KLOBUCHAR)


def _visible(system: System) -> tuple[int, int]:
    ep, _ = observe(_sky((0, 0), 0.0), T0, RX_ECEF)
    prn = int(ep.prn[ep.system == system][0])
    return int(system), prn


GAL = _visible(System.GALILEO)
GPS = _visible(System.GPS)


def _epoch():
    """A raw epoch (pseudoranges with clocks and atmosphere, no satellite states) of the whole sky."""
    ep, _ = observe(_sky((0, 0), 0.0), T0, RX_ECEF)
    return ep.replace(sat_pos_ecef_m=np.full((ep.n, 3), np.nan))


@pytest.mark.parametrize(("target", "no_prediction"), [(GAL, sisa_m(SISA_NAPA)), (GPS, ura_m(15))])
def test_no_prediction_is_left_out_of_the_single_point_solution_and_counted(target, no_prediction):
    """NAPA (Galileo) / URA 15 (GPS): the satellite is removed, counted ``no_accuracy_prediction``,
    and the solution equals the one without it (to 1e-9); SISA 3.12 m / URA 2.4 m and not given
    (NaN) keep it: the same epoch, bit for bit, as today."""
    assert math.isinf(no_prediction)
    raw = _epoch()
    key = (raw.system == target[0]) & (raw.prn == target[1])
    assert key.sum() == 1
    cfg = SppConfig()
    given, n_given = attach_broadcast(raw, _sky(target, sisa_m(107) if target == GAL else ura_m(0)))
    unknown, n_unknown = attach_broadcast(raw, _sky(target, math.nan))
    assert n_given == n_unknown == 0 and given.n == unknown.n == raw.n
    for a, b in ((given.sat_pos_ecef_m, unknown.sat_pos_ecef_m), (given.sat_clock_s, unknown.sat_clock_s)):
        np.testing.assert_array_equal(a, b)
    rejected: Counter[str] = Counter()
    out, n_out = attach_broadcast(raw, _sky(target, no_prediction), rejected)
    assert n_out == 1 and dict(rejected) == {"no_ephemeris": 0, "no_accuracy_prediction": 1}
    assert out.n == raw.n - 1 and not ((out.system == target[0]) & (out.prn == target[1])).any()
    sol, ref = (solve_position(e, cfg, klobuchar=KLOBUCHAR) for e in (out, given.select(~key)))
    full = solve_position(given, cfg, klobuchar=KLOBUCHAR)
    assert sol.ok and ref.ok and full.ok and int(sol.used.sum()) == int(full.used.sum()) - 1
    np.testing.assert_allclose(sol.p_ecef_m, ref.p_ecef_m, rtol=0, atol=1e-9)
    assert np.linalg.norm(sol.p_ecef_m - RX_ECEF) < 1.0  # still the receiver (a clean sky)


def test_the_selected_set_decides_no_fallback_to_another():
    """The satellite's set at T0 says NAPA, its set an hour earlier (still within its age) gave 3.12 m:
    at T0 (the NAPA set the nearest) the satellite is not used, not even with the older set; 40 min
    earlier, nearer the old set, it is."""
    eph = next(e for e in KEP if (e.system, e.prn) == GAL)
    old = dataclasses.replace(eph, toe_gps_s=eph.toe_gps_s - 3600.0, toc_gps_s=eph.toc_gps_s - 3600.0,
                              toe_sow_s=eph.toe_sow_s - 3600.0, accuracy_m=sisa_m(107))
    store = EphemerisStore([old, dataclasses.replace(eph, accuracy_m=math.inf)])
    sysv, prn = np.array([GAL[0]] * 2), np.array([GAL[1]] * 2)
    t = np.array([T0, T0 - 2400.0])
    assert store.states(sysv, prn, t).valid.tolist() == [False, True]
    assert store.no_prediction(sysv, prn, t).tolist() == [True, False]
    assert store.no_prediction(sysv, prn, np.array([T0 + 1e6, T0])).tolist() == [False, True]  # none: no


def _fly(store: EphemerisStore) -> TightNavigator:
    """The tight navigator at rest for 3 s (50 Hz IMU, raw epochs every 0.2 s)."""
    nav = TightNavigator(TightConfig(), "second-order", ephemerides=store)
    hold_at_rest(nav, _sky((0, 0), 0.0), 150)
    return nav


def test_no_prediction_is_left_out_of_the_tight_filter_and_counted():
    """NAPA on one Galileo satellite: the tight filter runs exactly as on a sky without that
    satellite's ephemeris (the same estimate, to 1e-9), counting each left-out observation as
    ``sat_rejected_no_accuracy_prediction``; with SISA 3.12 m it is used (a different estimate) and
    nothing is counted."""
    napa = _fly(_sky(GAL, math.inf))
    without = _fly(EphemerisStore([e for e in _sky(GAL, math.inf).kepler if (e.system, e.prn) != GAL],
                                  GLO, KLOBUCHAR))
    given = _fly(_sky(GAL, sisa_m(107)))
    c = napa.counters()
    # every epoch's observation of it counted; the first epoch starts the filter, the others are fused
    assert c["sat_rejected_no_accuracy_prediction"] == 15 and c["gnss_fused"] == 14
    assert "sat_rejected_no_accuracy_prediction" not in without.counters()
    assert "sat_rejected_no_accuracy_prediction" not in given.counters()
    a, b, g = (n.estimate() for n in (napa, without, given))
    assert a is not None and b is not None and g is not None
    np.testing.assert_allclose(np.r_[a.p_ned_m, a.v_ned_m_s], np.r_[b.p_ned_m, b.v_ned_m_s],
                               rtol=0, atol=1e-9)
    assert np.abs(np.asarray(a.p_ned_m) - np.asarray(g.p_ned_m)).max() > 1e-6


def test_the_simulated_sky_broadcasts_a_healthy_accuracy():
    """The simulator's constellation: GPS URA index 0 (2.4 m), Galileo SISA 3.12 m, BeiDou URAI 0
    (2.4 m) on every Keplerian ephemeris, so its UBX and RINEX output look like a real sky."""
    kep, _ = constellation(1.4e9, 1.4e9 + 7200.0, (System.GPS, System.GALILEO, System.BEIDOU))
    got = {(System(e.system), e.accuracy_m) for e in kep}
    assert got == {(System.GPS, 2.4), (System.GALILEO, 3.12), (System.BEIDOU, 2.4)}
    expected = {System.GPS: ura_m(0), System.GALILEO: sisa_m(107), System.BEIDOU: ura_m(0)}
    assert expected == BROADCAST_ACCURACY_M


def test_a_broadcast_cannot_say_not_given():
    """Every broadcast states an index: encoding NaN ("not given") is an error, inf is URA 15 / NAPA."""
    from companion.gnss.inav import sisa_index
    from companion.gnss.lnav import ura_index

    for index in (ura_index, sisa_index):
        with pytest.raises(ValueError, match="not given"):
            index(math.nan)
    assert (ura_index(math.inf), sisa_index(math.inf)) == (15, SISA_NAPA)
