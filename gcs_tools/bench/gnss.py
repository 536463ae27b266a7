"""``beliefnav bench gnss``: per-epoch cost of the raw-GNSS core on the synthetic constellation.

Satellite states (selection + Kepler/GLONASS, vectorised) for 20 satellites, one transmission-time
pass (two state evaluations), a single-point solution with and without RAIM, with Doppler velocity.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np

from companion.gnss import SppConfig, attach_broadcast, solve_position, transmission_states
from gcs_tools.gnss.synthetic import RX_ECEF, T0, observe, store


def _per_call_us(fn: Callable[[], object], seconds: float) -> float:
    fn()
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        fn()
        n += 1
    return (time.perf_counter() - t0) / n * 1e6


def measure(args: argparse.Namespace) -> dict[str, object]:
    seconds = 0.2 if getattr(args, "quick", False) else 1.0
    st = store()
    ep, _ = observe(st, T0 + 100.0, RX_ECEF, v_rx_ecef=np.array([5.0, -3.0, 1.0]), mask_deg=-90.0)
    idx = np.argsort(-ep.cn0_dbhz)[:20]  # 20 satellites (some below the horizon: the cost is the same)
    ep20 = ep.select(idx)
    prepared, _ = attach_broadcast(ep20, st)
    above, _ = observe(st, T0 + 100.0, RX_ECEF, v_rx_ecef=np.array([5.0, -3.0, 1.0]))
    visible, _ = attach_broadcast(above, st)
    t20 = np.full(20, T0 + 100.0)
    return {
        "satellites": 20,
        "states_us": _per_call_us(lambda: st.states(ep20.system, ep20.prn, t20), seconds),
        "transmission_states_us": _per_call_us(lambda: transmission_states(st, ep20), seconds),
        "spp_satellites": visible.n,
        "spp_us": _per_call_us(lambda: solve_position(visible, SppConfig(), klobuchar=st.klobuchar), seconds),
        "spp_raim_us": _per_call_us(
            lambda: solve_position(visible, SppConfig(raim=True), klobuchar=st.klobuchar), seconds),
        "prepared_satellites": prepared.n,
    }
