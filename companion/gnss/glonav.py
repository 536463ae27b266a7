"""GLONASS L1OF navigation strings -> broadcast ephemeris (GLONASS ICD 5.1, 4.4).

A string is 85 bits (bit 85 the idle chip, 84-81 the string number, 8-1 a Hamming code); as a u-blox
RXM-SFRBX reports it: four 32-bit words, the first three holding string bits 85..1 from the most
significant bit on (the last 11 bits of word 3 zero), the fourth the superframe (bits 31-16) and frame
(bits 7-0) numbers. Strings 1-4 of one frame carry the immediate data: the PZ-90 position, velocity and
luni-solar acceleration at t_b (sign-magnitude, 2⁻¹¹ km, 2⁻²⁰ km/s, 2⁻³⁰ km/s²), t_b (15 min of the
Moscow day), the health B_n, γ_n (2⁻⁴⁰) and τ_n (2⁻³⁰ s); the frequency channel is the SFRBX ``freqId``
− 7. ``t_b`` is placed on the Moscow day nearest the receiver's time. Not decoded: the almanac strings
(5-15), τ_c, τ_GPS, N4. The Hamming code is checked as RTKLIB's ``test_glostr`` does (the ICD's eight
check sums); a string that fails is counted, not used.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

from companion.gnss.ephemeris import GlonassEphemeris
from companion.gnss.timescale import GLONASS_MINUS_UTC_S, gps_minus_utc_s

STRING_BITS = 85
DAY_S = 86400.0
# ICD table 4.13 as RTKLIB's masks over the string's 88-bit buffer (bit 85 first, 3 bits padding):
# rows 1-7 each hold one check bit (string bits 1-7) and the data bits it covers; row 8 all bits
_HAMMING_MASKS = tuple(
    int.from_bytes(bytes(row), "big")
    for row in (
        (0x55, 0x55, 0x5A, 0xAA, 0xAA, 0xAA, 0xB5, 0x55, 0x6A, 0xD8, 0x08),
        (0x66, 0x66, 0x6C, 0xCC, 0xCC, 0xCC, 0xD9, 0x99, 0xB3, 0x68, 0x10),
        (0x87, 0x87, 0x8F, 0x0F, 0x0F, 0x0F, 0x1E, 0x1E, 0x3C, 0x70, 0x20),
        (0x07, 0xF8, 0x0F, 0xF0, 0x0F, 0xF0, 0x1F, 0xE0, 0x3F, 0x80, 0x40),
        (0xF8, 0x00, 0x0F, 0xFF, 0xF0, 0x00, 0x1F, 0xFF, 0xC0, 0x00, 0x80),
        (0x00, 0x00, 0x0F, 0xFF, 0xFF, 0xFF, 0xE0, 0x00, 0x00, 0x01, 0x00),
        (0xFF, 0xFF, 0xF0, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x02, 0x00),
        (0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xF8),
    )
)


def _parity(v: int) -> int:
    return bin(v).count("1") & 1


def hamming(string: int) -> int:
    """``string`` (bit k−1 = string bit k) with its check bits 8..1 set (whatever they were)."""
    s = string & ~0xFF
    for i in range(7):  # β1..β7: string bits 1..7, each the parity of its data bits
        if _parity((s << 3) & _HAMMING_MASKS[i]):
            s |= 1 << i
    if _parity(s):  # β8 (string bit 8): the whole string's parity even
        s |= 1 << 7
    return s


def hamming_ok(string: int) -> bool:
    """The ICD's check: every sum zero (RTKLIB also accepts the pattern of one corrected error; we
    take only clean strings)."""
    return not any(_parity((string << 3) & m) for m in _HAMMING_MASKS)


def string_from_words(words: Sequence[int]) -> int:
    """The 85-bit string of a u-blox SFRBX's first three words."""
    w = [int(x) & 0xFFFFFFFF for x in words[:3]]
    v = (w[0] << 64) | (w[1] << 32) | w[2]
    return v >> (96 - STRING_BITS)


def words_from_string(string: int, superframe: int, frame: int) -> list[int]:
    """The four SFRBX words of a string (the inverse of ``string_from_words``)."""
    v = string << (96 - STRING_BITS)
    return [(v >> 64) & 0xFFFFFFFF, (v >> 32) & 0xFFFFFFFF, v & 0xFFFFFFFF,
            ((superframe & 0xFFFF) << 16) | (frame & 0xFF)]


def field_u(string: int, hi: int, n: int) -> int:
    """Unsigned field of n bits whose most significant bit is string bit ``hi``."""
    return (string >> (hi - n)) & ((1 << n) - 1)


def field_sm(string: int, hi: int, n: int) -> int:
    """Sign-magnitude field (the ICD's: the first bit is the sign)."""
    v = field_u(string, hi, n)
    mag = v & ((1 << (n - 1)) - 1)
    return -mag if v >> (n - 1) else mag


def moscow_day_start_gps_s(t_gps_s: float) -> float:
    """GPS time of the start of the Moscow day containing ``t_gps_s``."""
    shift = GLONASS_MINUS_UTC_S - gps_minus_utc_s(t_gps_s)  # Moscow − GPS
    return math.floor((t_gps_s + shift) / DAY_S) * DAY_S - shift


@dataclass
class GlonassDecoder:
    """Collects strings 1-4 per slot; ``add`` returns an ephemeris once the four of one frame are in."""

    strings: dict[int, dict[int, int]] = field(default_factory=dict)
    frame_id: dict[int, int] = field(default_factory=dict)
    counters: dict[str, int] = field(default_factory=dict)

    def _count(self, name: str) -> None:
        self.counters[name] = self.counters.get(name, 0) + 1

    def add(self, slot: int, channel: int, words: Sequence[int],
            t_ref_gps_s: float) -> GlonassEphemeris | None:
        if len(words) != 4:
            self._count("glonass_bad_length")
            return None
        s = string_from_words(words)
        if not hamming_ok(s):
            self._count("glonass_bad_hamming")
            return None
        m = field_u(s, 84, 4)
        if m not in (1, 2, 3, 4):
            self._count("glonass_other_string")  # almanac and time strings 5-15: not needed here
            return None
        fid = int(words[3])
        if self.frame_id.get(slot) != fid:  # a new frame: the older strings are of another t_b
            self.frame_id[slot] = fid
            self.strings[slot] = {}
        got = self.strings.setdefault(slot, {})
        got[m] = s
        if len(got) < 4:
            return None
        self.strings[slot] = {}
        eph = decode_ephemeris(slot, channel, got[1], got[2], got[3], got[4], t_ref_gps_s)
        self._count("glonass_ephemerides" if eph is not None else "glonass_slot_mismatch")
        return eph


def decode_ephemeris(slot: int, channel: int, s1: int, s2: int, s3: int, s4: int,
                     t_ref_gps_s: float) -> GlonassEphemeris | None:
    """Strings 1-4 -> ephemeris; None when string 4's slot number is not ``slot``."""
    if field_u(s4, 15, 5) != slot:
        return None
    km = 1e3
    pos = tuple(field_sm(s, 35, 27) * 2.0**-11 * km for s in (s1, s2, s3))
    vel = tuple(field_sm(s, 64, 24) * 2.0**-20 * km for s in (s1, s2, s3))
    acc = tuple(field_sm(s, 40, 5) * 2.0**-30 * km for s in (s1, s2, s3))
    tb_s = field_u(s2, 76, 7) * 900.0
    toe = moscow_day_start_gps_s(t_ref_gps_s) + tb_s
    toe += DAY_S * round((t_ref_gps_s - toe) / DAY_S)  # the t_b nearest the receiver's time
    return GlonassEphemeris(
        prn=int(slot), channel=int(channel), toe_gps_s=toe,
        pos_ecef_m=(pos[0], pos[1], pos[2]), vel_ecef_m_s=(vel[0], vel[1], vel[2]),
        acc_ecef_m_s2=(acc[0], acc[1], acc[2]),
        clock_bias_s=-field_sm(s4, 80, 22) * 2.0**-30, gamma_n=field_sm(s3, 79, 11) * 2.0**-40,
        health=field_u(s2, 80, 1))
