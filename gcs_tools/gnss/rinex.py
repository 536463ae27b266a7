"""RINEX 3 and 4 observation and navigation files (GPS, Galileo, BeiDou, GLONASS, QZSS); a RINEX 3 writer.

Observations -> :class:`companion.gnss.GnssEpoch` per epoch, with one signal per system:
``C1C``/``D1C``/``S1C`` (GPS, QZSS, GLONASS G1, Galileo E1 — ``C1X``/``C1B`` accepted when C1C is
absent) and BeiDou B1I (``C2I``; ``C1I`` as RINEX 3.01 named it). Epochs are read in the file's time
system (``TIME OF FIRST OBS``: GPS, GAL, BDT, GLO = UTC) and converted to GPS time — never shifted
by the leap seconds when the file is already in GPS time (a known pitfall of some readers).

Navigation -> :class:`KeplerEphemeris` (GPS, QZSS, Galileo I/NAV, BeiDou D1/D2) and
:class:`GlonassEphemeris`, plus the GPS Klobuchar parameters (``IONOSPHERIC CORR`` GPSA/GPSB).
Group delay for the single-frequency signal: GPS/QZSS TGD, Galileo BGD E5b/E1, BeiDou TGD1.
Broadcast accuracy -> ``accuracy_m`` exactly as the UBX decoders give it from the same broadcast:
the metres RINEX writes (GPS/QZSS/BeiDou "SV accuracy", Galileo SISA) go back to the broadcast index
(``lnav.ura_index`` / ``inav.sisa_index``) and out through its table (``lnav.ura_m`` / ``inav.sisa_m``),
so the nominal value RINEX prescribes (2.0 m for URA index 0, as the real files and RTKLIB's writer
put) and the interval's upper bound (2.4 m) both read as 2.4 m; URA index 15 (above 6144 m), a
Galileo SISA below zero (−1: "NAPA", no accuracy prediction available) or above the table read as
inf ("no prediction", as the UBX decoders give index 15 and NAPA); a blank field reads as NaN ("not
given"), and the writer writes NaN as a blank field.

Galileo records (``data sources``, RINEX 3.05 table A8): bit 0 I/NAV E1-B, bit 1 F/NAV E5a-I, bit 2
I/NAV E5b-I; bit 8 the clock (af0-af2, toc, SISA) is the E5a,E1 pair's, bit 9 the E5b,E1 pair's.
The pseudoranges read here are E1, so only I/NAV records with the E5b,E1 clock (bit 9, or neither
clock bit as I/NAV carries no other pair) are kept, with BGD E5b/E1; F/NAV records and any record
with the E5a,E1 clock are counted (``galileo_fnav_skipped``), not mixed in: the two clocks of one
issue of data differ by the difference of the two group delays (nanoseconds: metres of range).
A record with both clock bits, or no source bit, is counted (``galileo_bad_data_source``).

Rejections are counted (``RinexObs.rejected`` / ``RinexNav.rejected``, by reason); a file that is
not RINEX 3 or 4, or holds no usable record, is a one-line ``UserError``. A truncated last record is
counted (``truncated``), the records before it are kept.
"""

from __future__ import annotations

import math
import warnings
import zlib
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from companion.errors import UserError
from companion.gnss.constants import C_M_S, DFREQ_G1_HZ, FREQ_B1I_HZ, FREQ_G1_HZ, FREQ_L1_HZ
from companion.gnss.ephemeris import GlonassEphemeris, KeplerEphemeris
from companion.gnss.inav import sisa_index, sisa_m
from companion.gnss.lnav import ura_index, ura_m
from companion.gnss.observations import GnssEpoch, make_epoch
from companion.gnss.systems import FROM_RINEX_LETTER, RINEX_LETTER, System
from companion.gnss.timescale import (
    GPS_MINUS_BDT_S,
    bdt_to_gps_s,
    gps_from_calendar,
    gps_minus_utc_s,
    week_tow,
)

# preferred code observation per system (first present wins); Doppler/C/N0 share the code's suffix
CODE_PREFERENCE: dict[System, tuple[str, ...]] = {
    System.GPS: ("C1C",),
    System.QZSS: ("C1C",),
    System.GLONASS: ("C1C",),
    System.GALILEO: ("C1C", "C1X", "C1B"),
    System.BEIDOU: ("C2I", "C1I"),
}
TIME_SYSTEMS = {"GPS": "GPS", "GAL": "GAL", "BDT": "BDT", "GLO": "GLO", "QZS": "QZS", "UTC": "UTC"}


@dataclass
class RinexObs:
    path: Path
    version: float
    time_system: str
    epochs: list[GnssEpoch]
    approx_position_ecef_m: np.ndarray  # (3,) from the header (zeros when absent)
    obs_types: dict[System, list[str]]
    rejected: Counter[str] = field(default_factory=Counter)


@dataclass
class RinexNav:
    kepler: list[KeplerEphemeris]
    glonass: list[GlonassEphemeris]
    klobuchar: tuple[np.ndarray, np.ndarray] | None
    leap_seconds: int | None
    rejected: Counter[str] = field(default_factory=Counter)


def _float(text: str) -> float:
    t = text.strip().replace("D", "E").replace("d", "e")
    return float(t) if t else 0.0


# the first bytes of gzip, LZW (.Z), bzip2 and zip files
COMPRESSED_MAGIC = (b"\x1f\x8b", b"\x1f\x9d", b"BZh", b"PK\x03\x04")
COMPACT_RINEX_LABEL = b"CRINEX VERS   / TYPE"  # the first line of a Hatanaka-compressed file


def is_compressed(head: bytes) -> bool:
    """Whether a file starting with ``head`` (its first 80 bytes or more) is compressed RINEX, or may be."""
    return head.startswith(COMPRESSED_MAGIC) or COMPACT_RINEX_LABEL in head[:80]


def _read_lines(path: Path) -> list[str]:
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise UserError(f"{path}: cannot read: {exc.strerror or exc}") from None
    if is_compressed(data):
        data = _decompressed(path, data)
    return data.decode("ascii", errors="replace").splitlines()


def _decompressed(path: Path, data: bytes) -> bytes:
    """A compressed RINEX file (gzip, .Z, bzip2, zip, Hatanaka's Compact RINEX, or Compact RINEX inside
    one of those: the forms RINEX archives publish) as plain RINEX, through the ``hatanaka`` package."""
    import hatanaka  # noqa: PLC0415 - only compressed files need it (and its crx2rnx subprocess)

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # crx2rnx's notes on skipped lines; the reader counts its own
            return bytes(hatanaka.decompress(data))
    except (hatanaka.HatanakaException, ValueError, OSError, EOFError, zlib.error) as exc:
        detail = " ".join(str(exc).split())[:200] or type(exc).__name__
        raise UserError(f"{path}: cannot decompress: {detail}") from None


def _header(path: Path, lines: list[str], kind: str) -> tuple[float, int]:
    """Check the version line; returns (version, index of the first line after END OF HEADER)."""
    if not lines or "RINEX VERSION / TYPE" not in lines[0]:
        raise UserError(f"{path}: not a RINEX file (no 'RINEX VERSION / TYPE' on the first line)")
    try:
        version = float(lines[0][:9])
    except ValueError:
        raise UserError(f"{path}: unreadable RINEX version {lines[0][:9]!r}") from None
    if not 3.0 <= version < 5.0:
        raise UserError(f"{path}: RINEX version {version:g}; only RINEX 3 and 4 are read")
    ftype = lines[0][20:21]
    if ftype != kind:
        what = {"O": "observation", "N": "navigation"}[kind]
        raise UserError(f"{path}: a RINEX {what} file was expected, this one has type {ftype!r}")
    for i, line in enumerate(lines):
        if "END OF HEADER" in line[60:]:
            return version, i + 1
    raise UserError(f"{path}: RINEX header without END OF HEADER (truncated?)")


def read_obs(path: str | Path) -> RinexObs:
    path = Path(path)
    lines = _read_lines(path)
    version, body = _header(path, lines, "O")
    obs_types: dict[System, list[str]] = {}
    time_system = "GPS"
    approx = np.zeros(3)
    current: System | None = None
    for line in lines[: body - 1]:
        label = line[60:].strip()
        if label == "SYS / # / OBS TYPES":
            letter = line[0:1]
            if letter.strip():
                current = FROM_RINEX_LETTER.get(letter)
                if current is not None:
                    obs_types[current] = []
            if current is not None:
                obs_types[current] += line[7:60].split()
        elif label == "TIME OF FIRST OBS":
            # blank: the file's system's own time (RINEX 3.05 table A2); mixed files must state it
            own = {"E": "GAL", "C": "BDT", "R": "GLO", "J": "QZS"}.get(lines[0][40:41], "GPS")
            # A3 in columns 49-51 after F13.7 seconds; read as the word after the seconds, as some
            # writers put both a column late (the hatanaka package's test files: "     0.0000000     GPS")
            words = line[30:60].split()
            ts = words[1] if len(words) > 1 else own
            if ts not in TIME_SYSTEMS:
                raise UserError(f"{path}: unknown time system {ts!r} in TIME OF FIRST OBS")
            time_system = ts
        elif label == "APPROX POSITION XYZ":
            try:
                approx = np.array([float(line[i : i + 14]) for i in (0, 14, 28)])
            except ValueError:
                approx = np.zeros(3)
    if not obs_types:
        raise UserError(f"{path}: RINEX observation header lists no SYS / # / OBS TYPES")
    cols = {s: _columns(t, CODE_PREFERENCE.get(s, ())) for s, t in obs_types.items()}
    rejected: Counter[str] = Counter()
    epochs: list[GnssEpoch] = []
    i = body
    n_lines = len(lines)
    while i < n_lines:
        line = lines[i]
        if not line.startswith(">"):
            rejected["stray_line"] += 1
            i += 1
            continue
        try:
            flag = int(line[31:32] or "0")
            nsat = int(line[32:35])
        except ValueError:
            rejected["bad_epoch_line"] += 1
            i += 1
            continue
        if flag > 1:  # event: nsat special records follow
            rejected[f"event_flag_{flag}"] += 1
            i += 1 + nsat
            continue
        if i + nsat >= n_lines:  # the file ends inside this epoch
            rejected["truncated"] += 1
            break
        try:
            t = gps_from_calendar(*_date(line, (2, 7, 10, 13, 16, 18, 29)), time_system)
        except (ValueError, UserError):
            rejected["bad_epoch_line"] += 1
            i += 1 + nsat
            continue
        epoch = _epoch(t, lines[i + 1 : i + 1 + nsat], cols, rejected, flag)
        if epoch is not None:
            epochs.append(epoch)
        i += 1 + nsat
    if not epochs:
        raise UserError(f"{path}: no usable observation epochs (rejected: {dict(rejected) or 'none'})")
    return RinexObs(path, version, time_system, epochs, approx, obs_types, rejected)


def _columns(types: list[str], preference: Sequence[str]) -> tuple[int, int, int] | None:
    """Indices of (code, Doppler, C/N0) of the preferred signal; None if none is observed."""
    for code in preference:
        if code in types:
            sig = code[1:]
            d = f"D{sig}"
            s = f"S{sig}"
            return (
                types.index(code),
                types.index(d) if d in types else -1,
                types.index(s) if s in types else -1,
            )
    return None


def _obs_value(line: str, k: int) -> float:
    v = line[3 + 16 * k : 3 + 16 * k + 14].strip()
    return float(v) if v else math.nan


def _epoch(
    t: float,
    sat_lines: list[str],
    cols: dict[System, tuple[int, int, int] | None],
    rejected: Counter[str],
    flag: int,
) -> GnssEpoch | None:
    sysv, prnv, prv, dv, snr = [], [], [], [], []
    for line in sat_lines:
        system = FROM_RINEX_LETTER.get(line[0:1])
        if system is None or system not in cols:
            rejected["unknown_system"] += 1
            continue
        c = cols[system]
        if c is None:
            rejected[f"no_signal_{RINEX_LETTER[system]}"] += 1
            continue
        try:
            prn = int(line[1:3])
            pr = _obs_value(line, c[0])
            d = _obs_value(line, c[1]) if c[1] >= 0 else math.nan
            s = _obs_value(line, c[2]) if c[2] >= 0 else math.nan
        except ValueError:
            rejected["bad_observation"] += 1
            continue
        if not math.isfinite(pr) or not (1.0e7 < pr < 5.0e7):
            rejected["no_pseudorange"] += 1
            continue
        sysv.append(system)
        prnv.append(prn)
        prv.append(pr)
        dv.append(d)
        snr.append(s)
    if flag == 1:
        rejected["power_failure_epoch"] += 1
    if not sysv:
        return None
    sys_arr = np.array(sysv, dtype=np.int8)
    # Doppler (Hz) -> pseudorange rate (m/s), −λ·D; GLONASS: the channel is applied by the caller
    # (glonass_rates) once the navigation data give it, here the G1 centre frequency
    freq = np.where(
        sys_arr == System.BEIDOU, FREQ_B1I_HZ, np.where(sys_arr == System.GLONASS, FREQ_G1_HZ, FREQ_L1_HZ)
    )
    return make_epoch(t, sys_arr, prnv, prv, pseudorange_rate_m_s=-np.array(dv) * C_M_S / freq, cn0_dbhz=snr)


def fix_glonass_rates(epoch: GnssEpoch, channel: np.ndarray) -> GnssEpoch:
    """Rescale GLONASS pseudorange rates read at the G1 centre frequency to each slot's channel."""
    glo = epoch.system == System.GLONASS
    if not glo.any():
        return epoch
    scale = np.where(glo, FREQ_G1_HZ / (FREQ_G1_HZ + channel * DFREQ_G1_HZ), 1.0)
    return epoch.replace(pseudorange_rate_m_s=epoch.pseudorange_rate_m_s * scale)


def read_nav(paths: str | Path | Iterable[str | Path]) -> RinexNav:
    """One or more RINEX 3 or 4 navigation files (mixed or per system) into one set."""
    if isinstance(paths, (str, Path)):
        paths = [paths]
    out = RinexNav([], [], None, None)
    for p in paths:
        _read_nav_file(Path(p), out)
    if not out.kepler and not out.glonass:
        raise UserError(
            f"{', '.join(str(p) for p in paths)}: no usable ephemeris "
            f"(rejected: {dict(out.rejected) or 'none'})"
        )
    return out


NAV_LINES = {"G": 8, "J": 8, "E": 8, "C": 8, "R": 4, "S": 4, "I": 8}


def _read_nav_file(path: Path, out: RinexNav) -> None:
    lines = _read_lines(path)
    version, body = _header(path, lines, "N")
    alpha = beta = None
    for line in lines[: body - 1]:
        label = line[60:].strip()
        if label == "IONOSPHERIC CORR":
            vals = [_float(line[5 + 12 * j : 17 + 12 * j]) for j in range(4)]
            if line.startswith("GPSA"):
                alpha = np.array(vals)
            elif line.startswith("GPSB"):
                beta = np.array(vals)
        elif label == "LEAP SECONDS":
            text = line[:6].strip()
            out.leap_seconds = int(text) if text.lstrip("-").isdigit() else None
    if version >= 4.0:
        _read_v4_records(lines[body:], out)
        return
    if alpha is not None and beta is not None:
        out.klobuchar = (alpha, beta)
    glo_lines = 5 if version >= 3.05 else 4
    i = body
    while i < len(lines):
        line = lines[i]
        letter = line[0:1]
        if not letter.strip():
            out.rejected["stray_line"] += 1
            i += 1
            continue
        n = glo_lines if letter == "R" else NAV_LINES.get(letter, 0)
        if n == 0:
            out.rejected["unknown_system"] += 1
            i += 1
            while i < len(lines) and not lines[i][0:1].strip():
                i += 1
            continue
        block = lines[i : i + n]
        i += n
        if len(block) < n:
            out.rejected["truncated"] += 1
            break
        try:
            _nav_record(letter, block, out)
        except (ValueError, IndexError, UserError):
            out.rejected["bad_record"] += 1


# RINEX 4 ephemeris messages whose records are RINEX 3's (the rest, e.g. CNAV, CNV1-3, are counted)
V4_LEGACY_EPH: dict[str, tuple[str, ...]] = {
    "G": ("LNAV",),
    "J": ("LNAV",),
    "I": ("LNAV",),
    "E": ("INAV", "FNAV"),
    "C": ("D1", "D2"),
    "R": ("FDMA",),
    "S": ("SBAS",),
}


def _read_v4_records(lines: list[str], out: RinexNav) -> None:
    """RINEX 4 navigation: records framed by ``> EPH G01 LNAV`` / ``> ION G   LNAV`` / ``> STO`` / ``> EOP``
    lines, each running to the next frame line. Ephemerides of the messages RINEX 3 carried are read
    as RINEX 3 records; the GPS Klobuchar parameters come from the ``ION`` LNAV record (no longer
    from the header); everything else is counted (``v4_<kind>_skipped``)."""
    frames: list[tuple[list[str], list[str]]] = []
    for line in lines:
        if line.startswith(">"):
            frames.append((line[1:].split(), []))
        elif frames:
            frames[-1][1].append(line)
        elif line.strip():
            out.rejected["stray_line"] += 1
    for words, block in frames:
        kind, sat, msg = (words + ["", "", ""])[:3]
        letter = sat[:1]
        if kind == "EPH" and msg in V4_LEGACY_EPH.get(letter, ()) and block:
            try:
                _nav_record(letter, block, out)
            except (ValueError, IndexError, UserError):
                out.rejected["bad_record"] += 1
        elif kind == "ION" and letter == "G" and msg == "LNAV" and block:
            try:
                v = _nav_values(block)
            except ValueError:
                out.rejected["bad_record"] += 1
                continue
            if len(v) >= 8 and all(math.isfinite(x) for x in v[:8]):
                out.klobuchar = (np.array(v[0:4]), np.array(v[4:8]))
            else:
                out.rejected["bad_record"] += 1
        else:
            out.rejected[f"v4_{(kind or 'empty').lower()}_skipped"] += 1


def _nav_values(block: list[str]) -> list[float]:
    """The record's numbers: three on the first line, four on each following line."""
    vals = [_float(block[0][23 + 19 * j : 42 + 19 * j]) for j in range(3)]
    for line in block[1:]:
        vals += [_float(line[4 + 19 * j : 23 + 19 * j]) for j in range(4)]
    return vals


def _date(line: str, cols: tuple[int, ...]) -> tuple[int, int, int, int, int, float]:
    """Year, month, day, hour, minute (integers) and seconds from fixed columns (field starts, end)."""
    y, mo, d, h, mi = (int(line[a:b]) for a, b in zip(cols[:5], cols[1:6], strict=True))
    return y, mo, d, h, mi, float(line[cols[5] : cols[6]])


def _nav_record(letter: str, block: list[str], out: RinexNav) -> None:
    head = block[0]
    prn = int(head[1:3])
    cal = _date(head, (4, 9, 12, 15, 18, 21, 23))
    v = _nav_values(block)
    if not all(math.isfinite(x) for x in v):
        out.rejected["nonfinite"] += 1
        return
    system = FROM_RINEX_LETTER[letter]
    if system == System.SBAS:
        out.rejected["sbas_skipped"] += 1
        return
    if system == System.GLONASS:
        toe = gps_from_calendar(*cal, "UTC")
        out.glonass.append(
            GlonassEphemeris(
                prn=prn,
                channel=int(v[10]),
                toe_gps_s=toe,
                pos_ecef_m=(v[3] * 1e3, v[7] * 1e3, v[11] * 1e3),
                vel_ecef_m_s=(v[4] * 1e3, v[8] * 1e3, v[12] * 1e3),
                acc_ecef_m_s2=(v[5] * 1e3, v[9] * 1e3, v[13] * 1e3),
                clock_bias_s=v[0],
                gamma_n=v[1],
                health=int(v[6]),
            )
        )
        return
    scale = "BDT" if system == System.BEIDOU else "GPS"
    toc = gps_from_calendar(*cal, scale)
    toe_sow = v[11]
    week = int(v[21])
    toe = bdt_to_gps_s(week * 604800.0 + toe_sow) if system == System.BEIDOU else week * 604800.0 + toe_sow
    toe += 604800.0 * round((toc - toe) / 604800.0)  # a week number off by one at a crossover
    tgd = v[25]
    health = int(v[24])
    if system == System.GALILEO:
        why = galileo_skip_reason(int(v[20]))
        if why:
            out.rejected[why] += 1
            return
        tgd = v[26]  # BGD E5b/E1
    out.kepler.append(
        KeplerEphemeris(
            system=int(system),
            prn=prn,
            toe_gps_s=toe,
            toc_gps_s=toc,
            toe_sow_s=toe_sow,
            sqrt_a_m05=v[10],
            e=v[8],
            i0_rad=v[15],
            omega0_rad=v[13],
            omega_rad=v[17],
            m0_rad=v[6],
            delta_n_rad_s=v[5],
            omega_dot_rad_s=v[18],
            idot_rad_s=v[19],
            cuc_rad=v[7],
            cus_rad=v[9],
            crc_m=v[16],
            crs_m=v[4],
            cic_rad=v[12],
            cis_rad=v[14],
            af0_s=v[0],
            af1_s_s=v[1],
            af2_s_s2=v[2],
            tgd_s=tgd,
            iode=int(v[3]),
            health=health,
            accuracy_m=broadcast_accuracy_m(system, v[23]) if block[6][4:23].strip() else math.nan,
        )
    )


GAL_INAV_E1B, GAL_FNAV_E5A, GAL_INAV_E5B = 1 << 0, 1 << 1, 1 << 2
GAL_CLOCK_E5A_E1, GAL_CLOCK_E5B_E1 = 1 << 8, 1 << 9


def galileo_skip_reason(sources: int) -> str:
    """Why a Galileo record with this ``data sources`` value is not used for E1 ('' if it is)."""
    e5a_clock, e5b_clock = sources & GAL_CLOCK_E5A_E1, sources & GAL_CLOCK_E5B_E1
    inav = sources & (GAL_INAV_E1B | GAL_INAV_E5B)
    if sources < 0 or (e5a_clock and e5b_clock) or not (inav or sources & GAL_FNAV_E5A):
        return "galileo_bad_data_source"
    if e5a_clock or not inav:  # F/NAV, or a clock for the E5a,E1 pair
        return "galileo_fnav_skipped"
    return ""


def broadcast_accuracy_m(system: System, value_m: float) -> float:
    """A navigation record's accuracy field (metres) -> ``accuracy_m`` as the broadcast index gives it
    (inf: no prediction). A blank field is not a value: the reader makes it NaN before this."""
    if not value_m >= 0.0:  # Galileo's −1 (NAPA); never a URA
        return math.inf
    if system == System.GALILEO:
        return sisa_m(sisa_index(value_m))
    return ura_m(ura_index(value_m))


# --- writer (tests and tools: synthetic scenarios) ---------------------------------------------


def _d(x: float) -> str:
    """D19.12 as RINEX writes it; NaN (a value not given) as a blank field."""
    if math.isnan(x):
        return " " * 19
    s = f"{x:19.12E}"
    return s.replace("E", "D")


def _calendar(t_gps_s: float, scale: str) -> tuple[int, int, int, int, int, float]:
    import datetime as dt

    t = t_gps_s
    if scale == "BDT":
        t -= GPS_MINUS_BDT_S
    elif scale in ("UTC", "GLO"):
        t -= gps_minus_utc_s(t_gps_s)
    whole = math.floor(t)
    d = dt.datetime(1980, 1, 6) + dt.timedelta(seconds=whole)
    return d.year, d.month, d.day, d.hour, d.minute, d.second + (t - whole)


def _accuracy_field(system: System, accuracy_m: float) -> float:
    """``accuracy_m`` as a navigation record writes it: Galileo SISA in metres (inf -> NAPA, −1); URA as
    RINEX 3.05's nominal value of its index, 2^(1+N/2) to 0.1 m for N ≤ 6, else 2^(N−2) (inf: 8192 m);
    NaN (not given) stays NaN, which ``_d`` writes as a blank field."""
    if math.isnan(accuracy_m):
        return accuracy_m
    if system == System.GALILEO:
        return accuracy_m if math.isfinite(accuracy_m) else -1.0
    n = ura_index(accuracy_m)
    return round(2.0 ** (1.0 + n / 2.0), 1) if n <= 6 else 2.0 ** (n - 2)


def write_nav(
    path: Path,
    kepler: Sequence[KeplerEphemeris],
    glonass: Sequence[GlonassEphemeris] = (),
    klobuchar: tuple[Sequence[float], Sequence[float]] | None = None,
    leap_seconds: int = 18,
) -> None:
    """A RINEX 3.04 mixed navigation file."""
    out = [f"{3.04:9.2f}{'':11s}{'N: GNSS NAV DATA':20s}{'M: MIXED':20s}RINEX VERSION / TYPE"]
    if klobuchar is not None:
        for name, vals in (("GPSA", klobuchar[0]), ("GPSB", klobuchar[1])):
            out.append(
                f"{name} "
                + "".join(f"{v:12.4E}".replace("E", "D") for v in vals)
                + f"{'':7s}"
                + "IONOSPHERIC CORR"
            )
    out.append(f"{leap_seconds:6d}{'':54s}LEAP SECONDS")
    out.append(f"{'':60s}END OF HEADER")
    for e in kepler:
        s = System(e.system)
        scale = "BDT" if s == System.BEIDOU else "GPS"
        y, mo, d, h, mi, sec = _calendar(e.toc_gps_s, scale)
        week = week_tow(e.toe_gps_s - (GPS_MINUS_BDT_S + 1356 * 604800.0 if s == System.BEIDOU else 0.0))[0]
        sources = 517.0 if s == System.GALILEO else 0.0
        rows = [
            [e.af0_s, e.af1_s_s, e.af2_s_s2],
            [e.iode, e.crs_m, e.delta_n_rad_s, e.m0_rad],
            [e.cuc_rad, e.e, e.cus_rad, e.sqrt_a_m05],
            [e.toe_sow_s, e.cic_rad, e.omega0_rad, e.cis_rad],
            [e.i0_rad, e.crc_m, e.omega_rad, e.omega_dot_rad_s],
            [e.idot_rad_s, sources, week, 0.0],
            [
                _accuracy_field(s, e.accuracy_m),
                e.health,
                e.tgd_s if s != System.GALILEO else 0.0,
                e.tgd_s if s == System.GALILEO else e.iode,
            ],
            [e.toe_sow_s, 4.0 if s != System.GALILEO else 0.0, 0.0, 0.0],
        ]
        out.append(
            f"{RINEX_LETTER[s]}{e.prn:02d} {y:4d} {mo:02d} {d:02d} {h:02d} {mi:02d} {int(sec):02d}"
            + "".join(_d(x) for x in rows[0])
        )
        out += ["    " + "".join(_d(x) for x in r) for r in rows[1:]]
    for g in glonass:
        y, mo, d, h, mi, sec = _calendar(g.toe_gps_s, "UTC")
        rows = [
            [g.clock_bias_s, g.gamma_n, week_tow(g.toe_gps_s)[1] % 86400.0],
            [g.pos_ecef_m[0] / 1e3, g.vel_ecef_m_s[0] / 1e3, g.acc_ecef_m_s2[0] / 1e3, g.health],
            [g.pos_ecef_m[1] / 1e3, g.vel_ecef_m_s[1] / 1e3, g.acc_ecef_m_s2[1] / 1e3, g.channel],
            [g.pos_ecef_m[2] / 1e3, g.vel_ecef_m_s[2] / 1e3, g.acc_ecef_m_s2[2] / 1e3, 0.0],
        ]
        out.append(
            f"R{g.prn:02d} {y:4d} {mo:02d} {d:02d} {h:02d} {mi:02d} {int(sec):02d}"
            + "".join(_d(x) for x in rows[0])
        )
        out += ["    " + "".join(_d(x) for x in r) for r in rows[1:]]
    path.write_text("\n".join(out) + "\n", encoding="ascii")


def write_obs(
    path: Path,
    epochs: Sequence[GnssEpoch],
    time_system: str = "GPS",
    approx_position_ecef_m: Sequence[float] = (0.0, 0.0, 0.0),
    glonass_channels: dict[int, int] | None = None,
) -> None:
    """A RINEX 3.04 mixed observation file with one code, Doppler and C/N0 per system (the
    signals :data:`CODE_PREFERENCE` reads first). Epoch times are written in ``time_system``;
    GLONASS Dopplers on each slot's channel frequency (``glonass_channels``: slot -> k, default 0)."""
    signals = {
        System.GPS: "1C",
        System.QZSS: "1C",
        System.GLONASS: "1C",
        System.GALILEO: "1C",
        System.BEIDOU: "2I",
    }
    freq = {
        System.GPS: FREQ_L1_HZ,
        System.QZSS: FREQ_L1_HZ,
        System.GLONASS: FREQ_G1_HZ,
        System.GALILEO: FREQ_L1_HZ,
        System.BEIDOU: FREQ_B1I_HZ,
    }
    present = sorted({System(int(s)) for e in epochs for s in e.system})
    out = [f"{3.04:9.2f}{'':11s}{'O: OBSERVATION DATA':20s}{'M: MIXED':20s}RINEX VERSION / TYPE"]
    x, y, z = approx_position_ecef_m
    out.append(f"{x:14.4f}{y:14.4f}{z:14.4f}{'':18s}APPROX POSITION XYZ")
    for s in present:
        sig = signals[s]
        types = f"C{sig} D{sig} S{sig}"
        out.append(f"{RINEX_LETTER[s]}  {3:3d} {types:53s}SYS / # / OBS TYPES")
    t0 = _calendar(epochs[0].t_gps_s, time_system)
    out.append(
        f"{t0[0]:6d}{t0[1]:6d}{t0[2]:6d}{t0[3]:6d}{t0[4]:6d}{t0[5]:13.7f}     {time_system:3s}"
        f"{'':9s}TIME OF FIRST OBS"
    )
    out.append(f"{'':60s}END OF HEADER")
    for e in epochs:
        y_, mo, d, h, mi, sec = _calendar(e.t_gps_s, time_system)
        out.append(f"> {y_:4d} {mo:02d} {d:02d} {h:02d} {mi:02d}{sec:11.7f}  0{e.n:3d}")
        for i in range(e.n):
            s = System(int(e.system[i]))
            f = freq[s]
            if s == System.GLONASS:
                f += (glonass_channels or {}).get(int(e.prn[i]), 0) * DFREQ_G1_HZ
            dop = -e.pseudorange_rate_m_s[i] * f / C_M_S
            cells = [e.pseudorange_m[i], dop, e.cn0_dbhz[i]]
            out.append(
                f"{RINEX_LETTER[s]}{int(e.prn[i]):02d}"
                + "".join(f"{c:14.3f}  " if math.isfinite(c) else " " * 16 for c in cells).rstrip()
            )
    path.write_text("\n".join(out) + "\n", encoding="ascii")
