"""The simulated receiver's UBX output: frames byte-equal to pyubx2's, LNAV parity on a real satellite's
subframes, and the round trip simulated epoch -> UBX -> pyubx2 -> companion.gnss.ubx -> the same epoch,
ephemerides and Klobuchar parameters; the TCP server."""

import dataclasses
import io
import math
import socket
import time

import numpy as np
import pytest
from gnss_helpers_lnav import SUBFRAMES_PRN21
from pyubx2 import GET, UBXMessage, UBXReader

from companion.errors import UserError
from companion.gnss.ephemeris import GlonassEphemeris, KeplerEphemeris
from companion.gnss.lnav import LnavDecoder
from companion.gnss.observations import GnssEpoch
from companion.gnss.systems import System
from companion.gnss.timescale import gps_minus_utc_s, week_tow
from companion.gnss.ubx import ReceiverPvt, UbxDecoder
from companion.mission import load_mission
from simvehicle import SimVehicle
from simvehicle.receiver import prstd_index
from simvehicle.ubx import UbxEncoder, lnav_parity, lnav_subframe, navpvt, navsat, rawx, sfrbx
from simvehicle.ubx_server import UbxServer


@pytest.fixture(scope="module")
def flight():
    """40 s of the canyon scenario (hovering at profile 4's start; a GPS frame of five 6 s subframes
    completes within 36 s of acquisition): raw epochs and frames."""
    sim = SimVehicle(load_mission("default", "canyon"), 4, 0)
    enc = UbxEncoder(sim.gnss.store)
    raws, frames = [], []
    while sim.t_us < 40e6:
        for raw in sim.advance(None, None).gnss_raw:
            raws.append(raw)
            frames.append(enc.epoch_frames(raw))
    return sim, raws, frames


def _pyubx2_rawx(ep: GnssEpoch, channel, lock, reset) -> bytes:
    week, tow = week_tow(ep.t_gps_s)
    kw = {
        "rcvTow": tow,
        "week": week,
        "leapS": round(gps_minus_utc_s(ep.t_gps_s)),
        "numMeas": ep.n,
        "leapSec": 1,
        "clkReset": int(reset),
    }
    lam = np.where(
        ep.system == System.GLONASS, 299792458.0 / (1602e6 + channel * 0.5625e6), 299792458.0 / 1575.42e6
    )
    for i in range(ep.n):
        s = f"_{i + 1:02d}"
        kw.update(
            {
                f"prMes{s}": float(ep.pseudorange_m[i]),
                f"cpMes{s}": 0.0,
                f"doMes{s}": float(-ep.pseudorange_rate_m_s[i] / lam[i]),
                f"gnssId{s}": int(ep.system[i]),
                f"svId{s}": int(ep.prn[i]),
                f"sigId{s}": 0,
                f"freqId{s}": int(channel[i]) + 7 if ep.system[i] == System.GLONASS else 0,
                f"locktime{s}": int(min(lock[i], 64500)),
                f"cno{s}": int(ep.cn0_dbhz[i]),
                f"prStd{s}": int(prstd_index(np.sqrt(ep.pseudorange_var_m2[i : i + 1]))[0]),
                f"cpStd{s}": 15,
                f"doStd{s}": 8,
                f"prValid{s}": 1,
            }
        )
    return UBXMessage("RXM", "RXM-RAWX", GET, **kw).serialize()


def test_frames_are_byte_equal_to_pyubx2(flight):
    sim, raws, _ = flight
    raw = next(r for r in raws if r.solution is not None and r.epoch.n > 8 and (r.epoch.system == 6).any())
    ep, sol = raw.epoch, raw.solution
    channel = np.where(ep.system == System.GLONASS, sim.gnss.store.glonass_channel(ep.prn), 0)
    assert rawx(ep, channel, raw.lock_ms, True) == _pyubx2_rawx(ep, channel, raw.lock_ms, True)
    # residuals on a 0.5 m grid: pyubx2 truncates scaled fields (int(x / 0.1)), ours rounds; equal there
    sol = dataclasses.replace(sol, residuals_m=np.round(np.nan_to_num(sol.residuals_m) * 2.0) / 2.0)
    kw = {"iTOW": 123456, "version": 1, "numSvs": ep.n}
    for i in range(ep.n):
        s = f"_{i + 1:02d}"
        used = bool(sol.used[i])
        kw.update(
            {
                f"gnssId{s}": int(ep.system[i]),
                f"svId{s}": int(ep.prn[i]),
                f"cno{s}": int(ep.cn0_dbhz[i]),
                f"elev{s}": int(ep.elevation_deg[i]),
                f"azim{s}": int(ep.azimuth_deg[i]),
                f"prRes{s}": float(sol.residuals_m[i]),
                f"qualityInd{s}": 7 if used else 4,
                f"svUsed{s}": int(used),
                f"orbitSource{s}": 1,
                f"ephAvail{s}": 1,
            }
        )
    assert navsat(ep, 123456, sol) == UBXMessage("NAV", "NAV-SAT", GET, **kw).serialize()
    v = np.array([1.234, -0.5, 0.25])
    t = raw.t_gps_s
    got = navpvt(sol, 52.1234567, 13.7654321, 123.456, v, 7.5, 12.25, t)
    msg = UBXReader.parse(got)
    assert (msg.lat, msg.lon, msg.height, msg.hAcc, msg.vAcc, msg.velN, msg.velE, msg.velD) == (
        52.1234567,
        13.7654321,
        123456,
        7500,
        12250,
        1234,
        -500,
        250,
    )
    assert msg.numSV == sol.n_used and msg.fixType == 3 and msg.gnssFixOk == 1 and msg.validDate == 1
    assert msg.iTOW == round(week_tow(t)[1] * 1000) and msg.pDOP == pytest.approx(sol.dops.pdop, abs=0.005)
    words = list(range(1, 11))
    assert (
        sfrbx(0, 7, words)
        == UBXMessage(
            "RXM",
            "RXM-SFRBX",
            GET,
            gnssId=0,
            svId=7,
            numWords=10,
            version=2,
            **{f"dwrd_{i + 1:02d}": w for i, w in enumerate(words)},
        ).serialize()
    )


def test_lnav_parity_of_a_real_satellite_and_the_ephemeris_round_trip(flight):
    """IS-GPS-200 parity reproduces the parity bits of PRN 21's real subframes (u-blox words: the
    previous word's D29/D30 in bits 31-30); an ephemeris written to subframes 1-3 decodes to itself."""
    for sf in SUBFRAMES_PRN21:
        for w in sf:
            assert lnav_parity((w >> 6) & 0xFFFFFF, (w >> 31) & 1, (w >> 30) & 1) == w & 0x3F
    sim, _, _ = flight
    store = sim.gnss.store
    eph = store.kepler[5]
    week, tow = week_tow(eph.toe_gps_s + 60.0)
    dec = LnavDecoder()
    got = None
    for k in (1, 2, 3):
        words = lnav_subframe(eph, k, tow + 6.0 * k, week)
        assert words is not None and all(
            w & 0x3 == 0 for w in (words[1] & 0x3F, words[9] & 0x3F)
        )  # D29 = D30 = 0
        got = dec.add(eph.prn, words, eph.toe_gps_s + 60.0) or got
    assert got == eph
    dec.add(eph.prn, lnav_subframe(eph, 4, tow + 24.0, week, store.klobuchar), eph.toe_gps_s)
    for a, b in zip(dec.klobuchar, store.klobuchar, strict=True):
        np.testing.assert_array_equal(a, b)


def test_round_trip_through_pyubx2_and_the_project_decoder(flight):
    sim, raws, frames = flight
    data = b"".join(f for fs in frames for f in fs)
    dec = UbxDecoder()
    epochs, pvts, ephs, glo = [], [], [], []
    for _, msg in UBXReader(io.BytesIO(data), protfilter=2):
        item = dec.feed(msg)
        if isinstance(item, GnssEpoch):
            epochs.append(item)
        elif isinstance(item, ReceiverPvt):
            pvts.append(item)
        elif isinstance(item, KeplerEphemeris):
            ephs.append(item)
        elif isinstance(item, GlonassEphemeris):
            glo.append(item)
    assert len(epochs) == len(raws) > 100 and len(pvts) == sum(r.solution is not None for r in raws)
    for raw, ep in zip(raws, epochs, strict=True):
        a = raw.epoch
        assert ep.t_gps_s == a.t_gps_s
        np.testing.assert_array_equal(ep.system, a.system)
        np.testing.assert_array_equal(ep.prn, a.prn)
        np.testing.assert_array_equal(ep.pseudorange_m, a.pseudorange_m)  # R8
        for name in ("cn0_dbhz", "elevation_deg", "azimuth_deg", "pseudorange_var_m2"):  # whole units / prStd
            np.testing.assert_array_equal(getattr(ep, name), getattr(a, name))
        np.testing.assert_allclose(ep.pseudorange_rate_m_s, a.pseudorange_rate_m_s, atol=2e-4)  # float32 Hz
    # NAV-PVT: the solution to the field resolution (1e-7 deg, 1 mm)
    sols = [r.solution for r in raws if r.solution is not None]
    from companion.gnss.geometry import ecef_to_geodetic

    for sol, pvt in zip(sols, pvts, strict=True):
        lat, lon, h = (float(x) for x in ecef_to_geodetic(sol.p_ecef_m))
        assert pvt.lat_deg == pytest.approx(math.degrees(lat), abs=6e-8)
        assert pvt.lon_deg == pytest.approx(math.degrees(lon), abs=6e-8)
        assert pvt.height_ellipsoid_m == pytest.approx(h, abs=6e-4)
        assert (pvt.h_acc_m, pvt.v_acc_m) == pytest.approx((sol.h_acc_m, sol.v_acc_m), abs=6e-4)
        assert pvt.num_sv == sol.n_used and pvt.fix_type == 3
    # the GPS satellites tracked through whole subframes: their broadcast ephemerides, exactly
    assert ephs and all(e in sim.gnss.store.kepler for e in ephs)
    assert dec.counters["lnav_klobuchar"] > 0
    # and the GLONASS satellites tracked through strings 1-4 (8 s of each 30 s frame): theirs, exactly
    tracked = {int(p) for r in raws for s_, p in zip(r.epoch.system, r.epoch.prn, strict=True)
               if s_ == System.GLONASS}
    assert len({g.prn for g in glo}) >= len(tracked) // 2 > 0
    assert all(g in sim.gnss.store.glonass for g in glo) and dec.counters["glonass_bad_hamming"] == 0


def test_glonass_strings_round_trip_to_the_same_satellite_position(flight):
    """Each simulated GLONASS ephemeris through strings 1-4 (ICD layout, Hamming code) and back:
    the same fields, the same satellite 15 min after t_b (to 1 cm); a flipped bit is refused."""
    from companion.gnss.ephemeris import EphemerisStore
    from companion.gnss.glonav import GlonassDecoder, hamming_ok, string_from_words, words_from_string
    from simvehicle.ubx import glonass_string

    sim = flight[0]
    store = sim.gnss.store
    dec = GlonassDecoder()
    out = []
    for k, eph in enumerate(store.glonass):
        t_frame = eph.toe_gps_s - 60.0 + 30.0 * (k % 3)
        strings = [glonass_string(eph, m, t_frame, t_frame + 2.0 * (m - 1)) for m in (1, 2, 3, 4)]
        assert all(hamming_ok(s_) and string_from_words(words_from_string(s_, 1, 2)) == s_ for s_ in strings)
        got = [dec.add(eph.prn, eph.channel, words_from_string(s_, 7, k % 5 + 1), t_frame + 40.0)
               for s_ in strings]
        assert got[:3] == [None] * 3 and got[3] == eph
        out.append(got[3])
    assert len(out) == len(store.glonass) > 20
    t = np.array([e.toe_gps_s + 900.0 for e in store.glonass])
    prn = np.array([e.prn for e in store.glonass])
    sysv = np.full(len(t), int(System.GLONASS))
    a = EphemerisStore([], list(store.glonass)).states(sysv, prn, t)
    b = EphemerisStore([], out).states(sysv, prn, t)
    assert np.isfinite(a.pos_ecef_m).all() and np.abs(a.pos_ecef_m - b.pos_ecef_m).max() < 0.01
    bad = words_from_string(glonass_string(store.glonass[0], 1, 0.0, 0.0) ^ (1 << 40), 0, 1)
    assert GlonassDecoder().add(1, 0, bad, 0.0) is None
    with pytest.raises(ValueError, match="out of range"):
        glonass_string(dataclasses.replace(store.glonass[0], clock_bias_s=0.01), 4, 0.0, 0.0)


def test_glonass_decoder_takes_hostile_words_and_counts_every_one():
    """Random words, random words made Hamming-valid, wrong lengths, extreme slots, channels and
    times: nothing raises, each kind of refusal is counted, and anything decoded is finite."""
    from companion.gnss.glonav import GlonassDecoder, hamming, string_from_words, words_from_string

    rng = np.random.default_rng(7)
    dec = GlonassDecoder()
    decoded, calls = [], 0
    for i in range(3000):
        n = 4 if i % 10 else int(rng.integers(0, 9))
        words = [int(w) for w in rng.integers(0, 2**32, n, dtype=np.uint64)]
        if n == 4 and i % 2:  # a valid Hamming code over random content, strings 1-4 mostly
            s = string_from_words(words) & ~((1 << 8) - 1) & ((1 << 85) - 1)
            s = (s & ~(0xF << 80)) | (int(rng.integers(1, 6)) << 80)
            s = hamming(s)
            words = words_from_string(s, int(rng.integers(0, 2**16)), int(rng.integers(0, 2**16)))
        t = float(rng.choice([0.0, 1.4e9, 1e12, -1e9]))
        eph = dec.add(int(rng.integers(0, 256)), int(rng.integers(-100, 300)), words, t)
        calls += 1
        if eph is not None:
            decoded.append(eph)
    assert calls == 3000 and all(dec.counters.get(k, 0) > 0 for k in (
        "glonass_bad_length", "glonass_bad_hamming", "glonass_other_string"))
    assert all(np.isfinite([*e.pos_ecef_m, *e.vel_ecef_m_s, e.toe_gps_s, e.clock_bias_s]).all()
               for e in decoded)


def test_ubx_server_streams_to_clients_and_refuses_a_busy_port(tmp_path):
    server = UbxServer(0, tmp_path / "r.ubx")
    try:
        with pytest.raises(UserError, match="UBX TCP port"):
            UbxServer(server.port)
        a = socket.create_connection(("127.0.0.1", server.port))
        b = socket.create_connection(("127.0.0.1", server.port))
        time.sleep(0.05)
        server.send([b"\xb5\x62one", b"two"])
        b.close()
        server.send([b"three"])
        got = b""
        a.settimeout(2.0)
        while len(got) < 13:
            got += a.recv(100)
        assert got == b"\xb5\x62onetwothree"
        assert server.counters["clients"] == 2 and server.counters["frames"] == 3
    finally:
        server.close()
    assert (tmp_path / "r.ubx").read_bytes() == b"\xb5\x62onetwothree"
