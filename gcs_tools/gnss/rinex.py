"""RINEX 2 (2.10, 2.11), 3 and 4 observation and navigation files (GPS, Galileo, BeiDou, GLONASS,
QZSS); a RINEX 3 writer.

Observations -> :class:`companion.gnss.GnssEpoch` per epoch, with one signal per system:
``C1C``/``D1C``/``S1C`` (GPS, QZSS, GLONASS G1, Galileo E1 — ``C1X``/``C1B`` accepted when C1C is
absent) and BeiDou B1I (``C2I``; ``C1I`` as RINEX 3.01 named it). Epochs are read in the file's time
system (``TIME OF FIRST OBS``: GPS, GAL, BDT, GLO = UTC) and converted to GPS time — never shifted
by the leap seconds when the file is already in GPS time (a known pitfall of some readers).

RINEX 2 observation files (one ``# / TYPES OF OBSERV`` list for all systems, 2-digit years, 12
satellites on the epoch line and continuation lines for more, five observations a line, a blank
system letter = GPS) are read as the RINEX 3 file they correspond to: each epoch's satellite lines
are put in RINEX 3's layout and go through the same code, and the codes are named as RINEX 3 names
the signal (C1/D1/S1 -> C1C/D1C/S1C, BeiDou C2/D2/S2 -> C2I/D2I/S2I as RINEX 2.12 numbers B1I; P1/P2
-> C1P/C2P, which the reader never picks, as it picks no C1P/C1W in RINEX 3). RINEX 2 navigation files
are per system — ``N`` GPS (``ION ALPHA``/``ION BETA`` -> Klobuchar), ``G`` GLONASS (2.01 on: the
clock signs of RINEX 3), ``H`` SBAS (counted, as RINEX 3's SBAS records) — and their records (PRN
without a system letter, 2-digit year, ``F5.1`` seconds, three-blank continuation lines) are RINEX 3's
one column to the left. ``DELTA-UTC``/``CORR TO SYSTEM TIME`` are not used (nor is RINEX 3's ``TIME
SYSTEM CORR``). Compressed files (gzip, ``.Z``, bzip2, zip; Compact RINEX 1.0 and 3.0) go through
the ``hatanaka`` package.

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
not RINEX 2, 3 or 4, or holds no usable record, is a one-line ``UserError``. A truncated last record is
counted (``truncated``), the records before it are kept; a RINEX 2 epoch whose satellite list does
not parse (e.g. more satellites announced than listed) is counted (``bad_epoch_line``) and its lines
(``stray_line``) are not read as observations. An observation whose Doppler or C/N0 field holds NaN,
inf or a value no receiver gives is counted (``bad_doppler``, ``bad_cn0``), not used. A lone epoch out
of the file's time order (a damaged stamp: before the epoch kept last, or after the next one while
that one agrees with it) is counted (``lone_epoch_back``, ``lone_epoch_ahead``), not solved at the
wrong time; gaps forward are kept, and a time going back for ``RESTART_EPOCHS`` epochs in a row (two
files joined) is adopted (:func:`_in_time_order`).
"""

from __future__ import annotations

import math
import re
import warnings
import zlib
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from itertools import pairwise
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
# an observation's Doppler (Hz) and C/N0 (dB-Hz) beyond these is damage, counted (bad_doppler, bad_cn0)
MAX_DOPPLER_HZ, MAX_CN0_DBHZ = 1.0e5, 100.0
MIN_SQRT_A = 2500.0  # √m: a semi-major axis inside the Earth (6,250 km) is damage, not a satellite
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


def _header(path: Path, lines: list[str], kind: str) -> tuple[float, str, int]:
    """Check the version line; returns (version, file type, index of the first line after END OF HEADER).
    RINEX 2 navigation files are per system: ``N`` GPS, ``G`` GLONASS, ``H`` SBAS (GEO)."""
    if not lines or "RINEX VERSION / TYPE" not in lines[0]:
        raise UserError(f"{path}: not a RINEX file (no 'RINEX VERSION / TYPE' on the first line)")
    try:
        version = float(lines[0][:9])
    except ValueError:
        raise UserError(f"{path}: unreadable RINEX version {lines[0][:9]!r}") from None
    if not 2.0 <= version < 5.0:
        raise UserError(f"{path}: RINEX version {version:g}; only RINEX 2 (2.10, 2.11), 3 and 4 are read")
    ftype = lines[0][20:21]
    if kind == "N" and version < 3.0 and ftype not in V2_NAV_LETTER:
        raise UserError(
            f"{path}: RINEX 2 navigation type {ftype!r}: N (GPS), G (GLONASS) and H (SBAS) are read"
        )
    if ftype != kind and not (kind == "N" and version < 3.0):
        what = {"O": "observation", "N": "navigation"}[kind]
        raise UserError(f"{path}: a RINEX {what} file was expected, this one has type {ftype!r}")
    for i, line in enumerate(lines):
        if "END OF HEADER" in line[60:]:
            return version, ftype, i + 1
    raise UserError(f"{path}: RINEX header without END OF HEADER (truncated?)")


def read_obs(path: str | Path) -> RinexObs:
    path = Path(path)
    lines = _read_lines(path)
    version, _, body = _header(path, lines, "O")
    header = lines[: body - 1]
    rejected: Counter[str] = Counter()
    if version < 3.0:  # one type list for every system the file holds; RINEX 2's epoch records
        obs_types, n_types = _v2_obs_types(path, header, lines[0][40:41])
        records, when = _v2_records(lines, body, n_types, rejected), _v2_when
    else:
        obs_types = _v3_obs_types(header)
        records, when = _v3_records(lines, body, rejected), _v3_when
    if not obs_types:
        raise UserError(f"{path}: RINEX observation header lists no observation types")
    cols = {s: _columns(t, CODE_PREFERENCE.get(s, ())) for s, t in obs_types.items()}
    time_system = _time_system(path, header, lines[0][40:41])
    epochs = _in_time_order(_collect(records, when, cols, time_system, rejected), rejected)
    if not epochs:
        raise UserError(f"{path}: no usable observation epochs (rejected: {dict(rejected) or 'none'})")
    return RinexObs(path, version, time_system, epochs, _approx_position(header), obs_types, rejected)


def _v3_obs_types(header: list[str]) -> dict[System, list[str]]:
    """``SYS / # / OBS TYPES``: each system's codes, continuation lines included."""
    obs_types: dict[System, list[str]] = {}
    current: System | None = None
    for line in header:
        if line[60:].strip() == "SYS / # / OBS TYPES":
            letter = line[0:1]
            if letter.strip():
                current = FROM_RINEX_LETTER.get(letter)
                if current is not None:
                    obs_types[current] = []
            if current is not None:
                obs_types[current] += line[7:60].split()
    return obs_types


def _time_system(path: Path, header: list[str], file_system: str) -> str:
    """The epochs' time system from ``TIME OF FIRST OBS``."""
    for line in header:
        if line[60:].strip() == "TIME OF FIRST OBS":
            # blank: the file's system's own time (RINEX 3.05 table A2, RINEX 2.11 table A1); mixed
            # files must state it
            own = {"E": "GAL", "C": "BDT", "R": "GLO", "J": "QZS"}.get(file_system, "GPS")
            # A3 in columns 49-51 after F13.7 seconds; read as the word after the seconds, as some
            # writers put both a column late (the hatanaka package's test files: "     0.0000000     GPS")
            words = line[30:60].split()
            ts = words[1] if len(words) > 1 else own
            if ts not in TIME_SYSTEMS:
                raise UserError(f"{path}: unknown time system {ts!r} in TIME OF FIRST OBS")
            return ts
    return "GPS"


def _approx_position(header: list[str]) -> np.ndarray:
    for line in header:
        if line[60:].strip() == "APPROX POSITION XYZ":
            try:
                return np.array([float(line[i : i + 14]) for i in (0, 14, 28)])
            except ValueError:
                return np.zeros(3)
    return np.zeros(3)


EpochRecord = tuple[int, str, list[str]]  # epoch flag, epoch line, satellite lines in RINEX 3 layout


def _v3_records(lines: list[str], start: int, rejected: Counter[str]) -> Iterator[EpochRecord]:
    """RINEX 3/4 epochs: a ``>`` line, then one line per satellite (or per special record)."""
    i, n_lines = start, len(lines)
    while i < n_lines:
        line = lines[i]
        if not line.startswith(">"):
            rejected["stray_line"] += 1
            i += 1
            continue
        try:
            flag = int(line[31:32] or "0")
            nsat = int(line[32:35])
            if nsat < 0:  # read as a count, it stepped back: the reader looped on this line forever
                raise ValueError(nsat)
        except ValueError:
            rejected["bad_epoch_line"] += 1
            i += 1
            continue
        if flag > 1:  # event: nsat special records follow
            yield flag, line, []
            i += 1 + nsat
            continue
        if i + nsat >= n_lines:  # the file ends inside this epoch
            rejected["truncated"] += 1
            return
        yield flag, line, lines[i + 1 : i + 1 + nsat]
        i += 1 + nsat


def _v3_when(line: str) -> tuple[int, int, int, int, int, float]:
    return _date(line, (2, 7, 10, 13, 16, 18, 29))


def _collect(
    records: Iterable[EpochRecord],
    when: Callable[[str], tuple[int, int, int, int, int, float]],
    cols: dict[System, tuple[int, int, int] | None],
    time_system: str,
    rejected: Counter[str],
) -> list[GnssEpoch]:
    """Epochs from the records: events (flag > 1) and unreadable epoch times counted."""
    epochs: list[GnssEpoch] = []
    for flag, line, sat_lines in records:
        if flag > 1:
            rejected[f"event_flag_{flag}"] += 1
            continue
        try:
            t = gps_from_calendar(*when(line), time_system)
        except (ValueError, UserError):
            rejected["bad_epoch_line"] += 1
            continue
        epoch = _epoch(t, sat_lines, cols, rejected, flag)
        if epoch is not None:
            epochs.append(epoch)
    return epochs


# epochs in a row behind the file's time (each after the one before) that make its time go back: two files
# joined, not a damaged stamp (the replay's rule for a restarted log's IMU samples)
RESTART_EPOCHS = 5


def _in_time_order(epochs: list[GnssEpoch], rejected: Counter[str]) -> list[GnssEpoch]:
    """The epochs whose times keep the file's order: a lone epoch out of it (a damaged stamp, which would
    be solved at the wrong time) is counted and dropped. In file order, with the time of the last epoch
    kept as the base, an epoch

    - before the base is ``lone_epoch_back``, unless it and the next ``RESTART_EPOCHS - 1`` epochs are
      each after the one before and all before the base (the file's time went back: adopted);
    - after the base but after the next epoch too, while that one is not before the base (the base and
      the next epoch agree, this one does not), is ``lone_epoch_ahead``; for the first epoch, the next
      two agree.

    Gaps forward (hours in a daily file) are kept, as are equal stamps (the replay counts duplicates) and
    an epoch in order whatever its stamp (a damaged last epoch, or one shifted by less than the interval,
    is not seen)."""
    t = [e.t_gps_s for e in epochs]
    n = len(t)
    kept: list[GnssEpoch] = []
    base: float | None = None
    for i, ti in enumerate(t):
        if base is not None and ti < base:
            run = t[i : i + RESTART_EPOCHS]
            if not (len(run) == RESTART_EPOCHS and all(a < b < base for a, b in pairwise(run))):
                rejected["lone_epoch_back"] += 1
                continue
        elif i + 1 < n and t[i + 1] < ti and (
            t[i + 1] >= base if base is not None else i + 2 < n and t[i + 2] > t[i + 1]
        ):
            rejected["lone_epoch_ahead"] += 1
            continue
        kept.append(epochs[i])
        base = ti
    return kept


# --- RINEX 2 (2.10, 2.11) observations ------------------------------------------------------------

# the satellite systems a RINEX 2 observation file may hold, by its header's system letter
_ALL_V2 = (System.GPS, System.GLONASS, System.GALILEO, System.SBAS, System.BEIDOU, System.QZSS)
V2_FILE_SYSTEMS: dict[str, tuple[System, ...]] = {
    " ": (System.GPS,),
    "G": (System.GPS,),
    "R": (System.GLONASS,),
    "E": (System.GALILEO,),
    "S": (System.SBAS,),
    "M": _ALL_V2,
}
# an epoch line: 2-digit year, month, day, hour, minute (blank for events without a time), F11.7
# seconds, the flag (0-6) and the satellite (or special record) count
V2_EPOCH = re.compile(r" [ \d]{2}(?: [ \d]{2}){4}[ \d.]{11}  [0-6][ \d]{2}\d")
V2_SAT_ID = re.compile(r"[A-Z ][ \d]\d")


def _v2_obs_types(path: Path, header: list[str], file_system: str) -> tuple[dict[System, list[str]], int]:
    """The codes of ``# / TYPES OF OBSERV`` (a count, then nine codes a line, continuation lines
    included) as RINEX 3 names them, for each system the file's system letter allows; their number."""
    systems = V2_FILE_SYSTEMS.get(file_system)
    if systems is None:
        raise UserError(f"{path}: RINEX 2 satellite system {file_system!r}; G, R, E, S and M are read")
    count, types = -1, []
    for line in header:
        if line[60:].strip() == "# / TYPES OF OBSERV":
            if count < 0:
                try:
                    count = int(line[:6])
                except ValueError:
                    raise UserError(f"{path}: unreadable # / TYPES OF OBSERV count {line[:6]!r}") from None
            types += line[6:60].split()
    if count < 0:
        raise UserError(f"{path}: RINEX 2 observation header without # / TYPES OF OBSERV")
    if count != len(types):
        raise UserError(f"{path}: # / TYPES OF OBSERV declares {count} types and lists {len(types)}")
    return {s: [_v3_code(c, s) for c in types] for s in systems}, count


def _v3_code(code: str, system: System) -> str:
    """A RINEX 2 observation code under the RINEX 3 name of the signal the RINEX 3 reader picks: C1/D1/S1
    -> C1C/D1C/S1C (BeiDou C2/D2/S2 -> C2I/D2I/S2I, B1I as RINEX 2.12 numbers it). The others keep
    their band with attribute C (P1/P2: C1P/C2P, the P code) and are never picked, as in RINEX 3; a
    code that is not a RINEX 2 one is kept as it is."""
    if len(code) != 2 or code[0] not in "CLDSP":
        return code
    if code[0] == "P":
        return f"C{code[1]}P"
    return f"{code}{'I' if system == System.BEIDOU else 'C'}"


def _v2_when(line: str) -> tuple[int, int, int, int, int, float]:
    y, mo, d, h, mi, s = _date(line, (0, 3, 6, 9, 12, 15, 26))
    return _full_year(y), mo, d, h, mi, s


def _full_year(y: int) -> int:
    """RINEX 2's 2-digit years: 80-99 -> 1980-1999, 00-79 -> 2000-2079."""
    if y >= 100:
        return y
    return y + (1900 if y >= 80 else 2000)


def _v2_records(lines: list[str], start: int, n_types: int, rejected: Counter[str]) -> Iterator[EpochRecord]:
    """RINEX 2 epochs: an epoch line listing 12 satellites (continuation lines for more), then each
    satellite's observations, five a line; yielded with the satellite lines in RINEX 3's layout. An
    epoch whose satellite list does not parse, or runs into the next epoch line, is counted and the
    reading resumes at the next epoch line; so is an event whose header lines run into one. A new
    ``# / TYPES OF OBSERV`` list in an event ends the reading (counted): the records after it have
    other columns."""
    per_sat = max(1, -(-n_types // 5))
    i, n_lines = start, len(lines)
    while i < n_lines:
        line = lines[i]
        if not V2_EPOCH.match(line):
            rejected["stray_line"] += 1
            i += 1
            continue
        flag, nsat = int(line[28]), int(line[29:32])
        if 2 <= flag <= 5:  # event: nsat header lines follow
            why = _v2_event_problem(lines[i + 1 : i + 1 + nsat])
            if why:
                rejected[why] += 1
                if why == "obs_types_changed":
                    return
                i += 1
                continue
            yield flag, line, []
            i += 1 + nsat
            continue
        n_id = max(1, -(-nsat // 12))
        end = i + n_id + nsat * per_sat
        if end > n_lines:  # the file ends inside this epoch
            rejected["truncated"] += 1
            return
        ids = _v2_sat_ids(lines[i : i + n_id], nsat)
        obs = lines[i + n_id : end]
        if ids is None or any(V2_EPOCH.match(x) for x in obs):
            rejected["bad_epoch_line"] += 1
            i += 1
            continue
        sat_lines = [_v3_sat_line(ids[k], obs[k * per_sat : (k + 1) * per_sat]) for k in range(nsat)]
        yield flag, line, (sat_lines if flag != 6 else [])
        i = end


def _v2_event_problem(special: list[str]) -> str:
    """Why an event's header lines cannot be skipped as such ('' when they can)."""
    if any(V2_EPOCH.match(x) for x in special):
        return "bad_event_record"
    if any(x[60:].strip() == "# / TYPES OF OBSERV" for x in special):
        return "obs_types_changed"
    return ""


def _v2_sat_ids(lines: list[str], nsat: int) -> list[str] | None:
    """The epoch's satellite identifiers (columns 33-68 of the epoch line and of its continuation lines,
    which are blank before); None if they do not read as ``nsat`` identifiers."""
    if any(x[:32].strip() for x in lines[1:]):
        return None
    text = "".join(x[32:68].ljust(36) for x in lines)
    ids = [text[3 * k : 3 * k + 3] for k in range(nsat)]
    return ids if all(V2_SAT_ID.fullmatch(x) for x in ids) else None


def _v3_sat_line(sat_id: str, obs_lines: list[str]) -> str:
    """A RINEX 2 satellite's observation lines as one RINEX 3 line (a blank system letter is GPS)."""
    letter = sat_id[0] if sat_id[0].strip() else "G"
    return letter + sat_id[1:] + "".join(x[:80].ljust(80) for x in obs_lines)


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


def _given(line: str, k: int) -> bool:
    """Observation ``k`` is in the file (a type the header lists, its field not blank)."""
    return k >= 0 and bool(line[3 + 16 * k : 3 + 16 * k + 14].strip())


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
        if _given(line, c[1]) and not abs(d) < MAX_DOPPLER_HZ:
            rejected["bad_doppler"] += 1  # a blank field is no Doppler; NaN, inf or 1e308 is damage
            continue
        if _given(line, c[2]) and not 0.0 <= s < MAX_CN0_DBHZ:
            rejected["bad_cn0"] += 1  # -3552 dB-Hz weighed the satellite to nothing: a singular solve
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
    """One or more RINEX 2, 3 or 4 navigation files (mixed or per system) into one set."""
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
# RINEX 2 navigation file types: the system letter of their records (which carry none)
V2_NAV_LETTER = {"N": "G", "G": "R", "H": "S"}


def _read_nav_file(path: Path, out: RinexNav) -> None:
    lines = _read_lines(path)
    version, ftype, body = _header(path, lines, "N")
    klobuchar = _nav_header(lines[: body - 1], out)
    if version >= 4.0:  # the Klobuchar parameters are in ION records
        _read_v4_records(lines[body:], out)
        return
    if klobuchar is not None:
        out.klobuchar = klobuchar
    if version >= 3.0:
        glo_lines = 5 if version >= 3.05 else 4
        _nav_records(
            lines[body:],
            out,
            lambda line: line[0:1].strip(),
            lambda letter: glo_lines if letter == "R" else NAV_LINES.get(letter, 0),
            _nav_record,
        )
        return
    if ftype == "G" and version < 2.01:
        raise UserError(f"{path}: GLONASS navigation {version:g}: withdrawn clock signs; 2.01 on are read")
    letter = V2_NAV_LETTER[ftype]  # records start with the PRN (I2), continuation lines with 3 blanks
    _nav_records(lines[body:], out, lambda x: letter if x[0:2].strip() else "", NAV_LINES.get, _nav_record_v2)


def _nav_header(header: list[str], out: RinexNav) -> tuple[np.ndarray, np.ndarray] | None:
    """The GPS Klobuchar parameters (RINEX 3 ``IONOSPHERIC CORR`` GPSA/GPSB, RINEX 2 ``ION ALPHA``/``ION
    BETA``; None unless both are there); ``LEAP SECONDS`` into ``out``."""
    ion: dict[str, np.ndarray] = {}
    for line in header:
        label = line[60:].strip()
        where = _klobuchar_field(label, line)
        if where is not None:
            key, first = where
            try:
                ion[key] = np.array([_float(line[first + 12 * j : first + 12 + 12 * j]) for j in range(4)])
            except ValueError:
                out.rejected["bad_klobuchar"] += 1
        elif label == "LEAP SECONDS":
            text = line[:6].strip()
            out.leap_seconds = int(text) if text.lstrip("-").isdigit() else None
    return (ion["A"], ion["B"]) if "A" in ion and "B" in ion else None


def _klobuchar_field(label: str, line: str) -> tuple[str, int] | None:
    """Whether a header line holds GPS Klobuchar α ("A") or β ("B"), and the column of its first value."""
    if label == "IONOSPHERIC CORR" and line[:4] in ("GPSA", "GPSB"):
        return line[3], 5
    if label in ("ION ALPHA", "ION BETA"):
        return label[4], 2
    return None


def _nav_records(
    lines: list[str],
    out: RinexNav,
    letter_of: Callable[[str], str],
    n_lines: Callable[[str], int | None],
    parse: Callable[[str, list[str], RinexNav], None],
) -> None:
    """Records of ``n_lines(letter)`` lines, each starting on a line where ``letter_of`` gives its
    system letter ('' on continuation lines); records of unknown systems, records with lines missing
    (the next record starts inside them) and damaged ones counted."""
    i = 0
    while i < len(lines):
        letter = letter_of(lines[i])
        if not letter:
            out.rejected["stray_line"] += 1
            i += 1
            continue
        n = n_lines(letter) or 0
        if n == 0:
            out.rejected["unknown_system"] += 1
            i += 1
            while i < len(lines) and not letter_of(lines[i]):
                i += 1
            continue
        block = lines[i : i + n]
        cut = next((j for j in range(1, len(block)) if letter_of(block[j])), 0)
        if cut:  # a record with lines missing: the next record starts inside it
            out.rejected["record_cut_short"] += 1
            i += cut
            continue
        i += n
        if len(block) < n:
            out.rejected["truncated"] += 1
            break
        try:
            parse(letter, block, out)
        except (ValueError, IndexError, OverflowError, UserError):
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
            except (ValueError, IndexError, OverflowError, UserError):
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
    """A RINEX 3 record: ``G01 2024 03 07 22 00 00`` and three values, then four values a line."""
    head = block[0]
    _nav_entry(letter, int(head[1:3]), _date(head, (4, 9, 12, 15, 18, 21, 23)), block, out)


def _nav_record_v2(letter: str, block: list[str], out: RinexNav) -> None:
    """A RINEX 2 record: ``I2`` PRN, a 2-digit year, ``F5.1`` seconds and three values, then (three
    columns in) four values a line; read as the RINEX 3 record it is one column to the right of."""
    head = block[0]
    y, mo, d, h, mi, s = _date(head, (2, 5, 8, 11, 14, 17, 22))
    _nav_entry(letter, int(head[0:2]), (_full_year(y), mo, d, h, mi, s), [" " + x for x in block], out)


def _nav_entry(
    letter: str, prn: int, cal: tuple[int, int, int, int, int, float], block: list[str], out: RinexNav
) -> None:
    """One record's ephemeris (``block`` in RINEX 3's columns) into ``out``, or a counted rejection."""
    v = _nav_values(block)
    if not all(math.isfinite(x) for x in v):
        out.rejected["nonfinite"] += 1
        return
    system = FROM_RINEX_LETTER[letter]
    if system == System.SBAS:
        out.rejected["sbas_skipped"] += 1
        return
    if system == System.GLONASS:
        if not (-7 <= v[10] <= 24 and v[10] == int(v[10])):  # frequency number (RINEX 2: 1-24); 1e308 crashed
            raise ValueError(f"GLONASS frequency number {v[10]}")
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
    if not (0.0 <= toe_sow <= 604800.0 and 0.0 <= v[21] < 10000.0):  # a huge week overflowed the toe
        raise ValueError(f"toe {toe_sow} s of week {v[21]}")
    if not (v[10] > MIN_SQRT_A and 0.0 <= v[8] < 1.0):  # an orbit inside the Earth, or not closed
        raise ValueError(f"sqrt(A) {v[10]}, e {v[8]}")
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
