"""One entry point for raw GNSS inputs: smartLoc, RINEX 2-4 observation + navigation (compressed or not), UBX.

``load_input`` returns epochs ready for the solver (RINEX/UBX: satellite states attached from the
broadcast ephemerides at transmission time; observations without an ephemeris counted in
``rejected['no_ephemeris']``, those whose ephemeris broadcasts "no accuracy prediction" (URA 15,
Galileo NAPA) in ``rejected['no_accuracy_prediction']``), the Klobuchar parameters, and the truth
when one is given.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from companion.errors import UserError
from companion.gnss.ephemeris import EphemerisStore, attach_broadcast
from companion.gnss.observations import GnssEpoch
from gcs_tools.gnss import rinex, smartloc


@dataclass
class GnssInput:
    path: Path
    format: str  # smartloc | rinex | ubx
    epochs: list[GnssEpoch]
    klobuchar: tuple[np.ndarray, np.ndarray] | None = None
    rejected: Counter[str] = field(default_factory=Counter)
    truth: smartloc.Truth | None = None
    truth_ecef_m: np.ndarray | None = None  # a static receiver
    truth_note: str = ""
    store: EphemerisStore | None = None

    def truth_at(self, t_s: np.ndarray) -> np.ndarray | None:
        """Truth (k, 3) at the epochs' times, NaN where unknown; None without truth."""
        if self.truth is not None:
            return self.truth.at(t_s)
        if self.truth_ecef_m is not None:
            return np.tile(self.truth_ecef_m, (len(t_s), 1))
        return None


def detect(path: Path) -> str:
    with open(path, "rb") as f:
        head = f.read(128)
    if head.startswith(b"\xb5\x62"):
        return "ubx"
    if smartloc.is_smartloc(path):
        return "smartloc"
    if b"RINEX VERSION / TYPE" in head[:90] or rinex.is_compressed(head):
        return "rinex"
    if path.suffix.lower() == ".ubx":
        return "ubx"
    raise UserError(f"{path}: not a smartLoc, RINEX observation or UBX file")


def parse_ecef(text: str, option: str = "--truth-ecef") -> np.ndarray:
    try:
        v = np.array([float(x) for x in text.split(",")])
    except ValueError:
        v = np.zeros(0)
    if v.shape != (3,) or not np.isfinite(v).all() or not 6.0e6 < np.linalg.norm(v) < 7.0e6:
        raise UserError(f"{option} {text!r}: expected X,Y,Z in metres on the Earth's surface")
    return v


def load_input(
    path: Path, navs: Sequence[Path] = (), truth: Path | None = None, truth_ecef: str | None = None
) -> GnssInput:
    if truth is not None and truth_ecef is not None:
        raise UserError("--truth and --truth-ecef: two truths; give one")
    fmt = detect(path)
    if fmt == "smartloc":
        data = smartloc.read_input(path)
        out = GnssInput(path, fmt, data.epochs, rejected=data.rejected)
        if truth_ecef is None:  # the *_GT.txt beside it, unless a static truth is asked for
            truth = truth or smartloc.default_truth_path(path)
    elif fmt == "rinex":
        if not navs:
            raise UserError(f"{path}: a RINEX observation file needs --nav (broadcast ephemerides)")
        out = rinex_input(path, navs)
    else:
        from gcs_tools.gnss.ubx_source import read_ubx_file

        out = read_ubx_file(path)
    if truth is not None:
        from gcs_tools.gnss import truth as truth_formats

        out.truth = truth_formats.read(truth)
        truth_formats.check_covers(out.truth, np.array([e.t_gps_s for e in out.epochs]), truth)
        out.truth_note = f"{out.truth.source} of {truth.name}, interpolated at the epochs"
    elif truth_ecef is not None:
        out.truth_ecef_m = parse_ecef(truth_ecef)
        out.truth_note = "a static position (--truth-ecef)"
    return out


def rinex_input(obs_path: Path, nav_paths: Sequence[Path]) -> GnssInput:
    from gcs_tools.gnss import rinex

    for p in (obs_path, *nav_paths):
        if not Path(p).is_file():
            raise UserError(f"{p}: no such file")
    obs = rinex.read_obs(obs_path)
    nav = rinex.read_nav(nav_paths)
    store = EphemerisStore(nav.kepler, nav.glonass, nav.klobuchar)
    rejected = Counter({f"obs_{k}": v for k, v in obs.rejected.items()})
    rejected.update({f"nav_{k}": v for k, v in nav.rejected.items()})
    if store.dropped_unhealthy:
        rejected["nav_unhealthy"] += store.dropped_unhealthy
    epochs = []
    for e in obs.epochs:
        e = rinex.fix_glonass_rates(e, store.glonass_channel(e.prn))
        e, _ = attach_broadcast(e, store, rejected)
        if e.n:
            epochs.append(e)
    if not epochs:
        raise UserError(
            f"{obs_path}: no observation has a broadcast ephemeris in "
            f"{', '.join(str(p) for p in nav_paths)} (times or satellites do not match)"
        )
    return GnssInput(obs_path, "rinex", epochs, nav.klobuchar, rejected, store=store)
