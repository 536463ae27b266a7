"""Writes tests/data/synthetic_gnss.obs/.nav: three epochs (1 Hz) of the synthetic constellation of
tests/gnss_helpers.py seen from a receiver in Berlin moving at (5, −3, 1) m/s ECEF, as RINEX 3.04
(GPS time). Run from the repository root: ``python tests/data/make_gnss_rinex.py``."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from gcs_tools.gnss.rinex import write_nav, write_obs  # noqa: E402
from tests.gnss_helpers import KLOBUCHAR, RX_ECEF, T0, constellation, observe, store  # noqa: E402

V_RX = np.array([5.0, -3.0, 1.0])


def epochs():
    st = store()
    return [
        observe(st, T0 + 100.0 + k, RX_ECEF + V_RX * k, v_rx_ecef=V_RX, drift_m_s=0.3)[0] for k in range(3)
    ]


def main(out: Path = Path(__file__).parent) -> None:
    kep, glo = constellation()
    write_nav(out / "synthetic_gnss.nav", kep, glo, KLOBUCHAR)
    write_obs(out / "synthetic_gnss.obs", epochs(), "GPS", RX_ECEF, {g.prn: g.channel for g in glo})


if __name__ == "__main__":
    main()
