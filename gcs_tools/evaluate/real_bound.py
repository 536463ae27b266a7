"""What the GNSS errors alone allow: a bound on the real-flight campaign's urban medians.

    python -m gcs_tools.evaluate.real_bound --corpus ansfl/ --flights tuning \\
        --errors smartloc_berlin_spp_errors.csv --seeds 0-4

The campaign (:mod:`gcs_tools.evaluate.real`) gives every estimator a flight's truth plus a GNSS error
series, with a Doppler velocity of 0.2 m/s noise. An estimator with a PERFECT velocity knows the
path up to one constant offset; all it can do with the fixes is estimate that offset from their errors
``e_k`` (fix minus truth) as they arrive. Its horizontal error at each arrival is then the error of
that estimate, whatever the IMU. This module takes the campaign's exact windows (the same
``GnssErrorOptions`` and seeds, so the same series start per flight and seed) and scores:

* ``raw``: the fixes themselves (the mean over windows of the per-window median |e|);
* ``window_median``: a clairvoyant constant, the median of the whole window's errors (non-causal:
  it knows the future; no filter can use it);
* ``best_filter``: the best, in hindsight, of a grid of causal Kalman filters per horizontal axis on
  ``e_k = c + b_k + w_k`` (``c`` the constant, ``b`` a Gauss-Markov bias of std ``sigma_b_m`` and
  correlation time ``tau_s``, ``w`` white of std ``sigma_w_m`` or ``c_hacc`` × the fix's reported
  accuracy), each with an innovation gate of ``gate_sigma`` (0: none) on the two axes jointly,
  chosen on the very windows it is scored on (so optimistic for that class);
* ``best_huber_filter``: the same filters without a gate, their update robust instead (Huber: a fix whose
  normalised innovation ``m = √(NIS/2)`` exceeds ``huber_c`` is fused with its R × (m / ``huber_c``), so
  its pull is bounded, not cut), the best of its grid in hindsight as well;
* ``best_step_filter``: the gated filters with each fix's white variance raised by ``step_c`` × the
  largest squared step (per axis) of the errors over its last three fixes, ``(e_k − e_(k−1))²/2``: what
  a receiver velocity tells of a fix, its jump against the motion (with a perfect velocity the jump of
  the fix IS the jump of its error), used as an accuracy the receiver does not report.

A filter with a perfect velocity and its parameters tuned on the windows it is scored on does at
least as well as the same filter with a real velocity tuned elsewhere: when even ``best_filter``
stays above a goal, no filter of that class meets it on these windows.
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from companion.errors import UserError
from gcs_tools.choices import seeds as parse_seeds

FIX_PERIOD_S = 0.2  # the campaign's 5 Hz
SIGMA_W_M = (2.0, 3.5, 5.0, 8.0)  # white noise std (accuracy "none")
C_HACC = (0.5, 0.75, 1.0, 1.5)  # white noise std / reported accuracy (accuracy "reported")
SIGMA_B_M = (1.0, 3.0, 6.0, 10.0, 20.0)
TAU_S = (2.0, 5.0, 10.0, 30.0, 100.0)
GATE_SIGMA = (0.0, 2.0, 3.0, 4.0)
HUBER_C = (0.5, 1.0, 1.5, 2.0)  # Huber's threshold on the normalised innovation (1.345: 95 % efficiency)
STEP_C = (0.25, 0.5, 1.0, 2.0)  # the white variance added per squared step of the errors
KINDS = ("gate", "huber", "step")
PRIOR_M2 = 1e6  # the constant's prior variance (unknown)


def windows(corpus: Path | None, flights: str, errors: str, seeds: Sequence[int]
            ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per flight and seed: the horizontal errors (n, 2) of the campaign's fixes in arrival order and
    their reported accuracy (n,)."""
    from gcs_tools.evaluate.real import flight_dirs
    from gcs_tools.replay.logs import open_log
    from gcs_tools.replay.synthetic_gnss import GnssErrorOptions, replace_gnss

    out = []
    for flight in flight_dirs(corpus, flights)[1]:
        for seed in seeds:
            opts = GnssErrorOptions(errors, rate_hz=1.0 / FIX_PERIOD_S, accuracy="reported", seed=seed)
            opts.check()
            fixes = replace_gnss(open_log(flight), open_log(flight), opts, None)[0].synthetic
            order = np.argsort(fixes.t_arrival_us, kind="stable")
            out.append((fixes.err_ned_m[order, :2], fixes.h_acc_m[order]))
    return out


def filter_medians(err: np.ndarray, r_m2: np.ndarray, sigma_b_m: np.ndarray, tau_s: np.ndarray,
                   gate_sigma: np.ndarray, huber_c: np.ndarray | None = None) -> np.ndarray:
    """The per-window median horizontal error of G filters at once (every argument but ``err`` (n, 2)
    has a leading axis G; ``r_m2`` (G, n) the white variance per fix): per axis the 2-state Kalman
    filter on e = c + b + w, both axes gated jointly on their normalised innovation; with ``huber_c``
    (G,) the update is Huber's (the module doc) where it is > 0."""
    a = np.exp(-FIX_PERIOD_S / tau_s)
    q = (1.0 - a * a) * sigma_b_m**2
    g2 = np.where(gate_sigma > 0.0, gate_sigma**2, np.inf)
    n, G = len(err), len(a)
    x = np.zeros((2, 2, G))  # axis, (c, b), filter
    P = np.zeros((2, 3, G))  # axis, (P_cc, P_cb, P_bb)
    P[:, 0] = PRIOR_M2
    P[:, 2] = sigma_b_m**2
    est = np.empty((n, 2, G))
    for k in range(n):
        x[:, 1] *= a
        P[:, 1] *= a
        P[:, 2] = a * a * P[:, 2] + q
        s = P[:, 0] + 2.0 * P[:, 1] + P[:, 2] + r_m2[:, k]  # (2, G)
        y = err[k][:, None] - x[:, 0] - x[:, 1]
        nis = (y * y / s).sum(axis=0)
        use = (k == 0) | (nis <= 2.0 * g2)  # the joint NIS (2 dof) against 2·gate²
        if huber_c is not None and k > 0:
            m = np.sqrt(nis / 2.0)
            w = np.where((huber_c > 0.0) & (m > huber_c), m / np.where(huber_c > 0.0, huber_c, 1.0), 1.0)
            s = s + (w - 1.0) * r_m2[:, k]  # R × w
        k_c, k_b = (P[:, 0] + P[:, 1]) / s, (P[:, 1] + P[:, 2]) / s
        pc, pb = P[:, 0] + P[:, 1], P[:, 1] + P[:, 2]
        P[:, 0] = np.where(use, P[:, 0] - k_c * pc, P[:, 0])
        P[:, 1] = np.where(use, P[:, 1] - k_c * pb, P[:, 1])
        P[:, 2] = np.where(use, P[:, 2] - k_b * pb, P[:, 2])
        x[:, 0] += np.where(use, k_c * y, 0.0)
        x[:, 1] += np.where(use, k_b * y, 0.0)
        est[k] = x[:, 0]
    return np.median(np.hypot(est[:, 0], est[:, 1]), axis=0)


def grid(accuracy: str, kind: str = "gate") -> list[dict[str, float]]:
    """The grid of the gated filters (``gate``), of the Huber filters (``huber``: no gate) or of the
    gated filters with the step term (``step``)."""
    white = [("sigma_w_m", w) for w in SIGMA_W_M] if accuracy == "none" else [("c_hacc", c) for c in C_HACC]
    extra = [("huber_c", c) for c in HUBER_C] if kind == "huber" else \
        [("step_c", c) for c in STEP_C] if kind == "step" else [("step_c", 0.0)]
    last = [("gate_sigma", 0.0)] if kind == "huber" else [("gate_sigma", g) for g in GATE_SIGMA]
    out = []
    for (white_key, w), b, t, (ek, ev), (lk, lv) in itertools.product(white, SIGMA_B_M, TAU_S, extra, last):
        cfg = {white_key: w, "sigma_b_m": b, "tau_s": t, ek: ev, lk: lv}
        out.append({k: v for k, v in cfg.items() if not (k == "step_c" and kind == "gate")})
    return out


def step_var_m2(err: np.ndarray) -> np.ndarray:
    """(n,) the largest of ``|e_j − e_(j−1)|² / 2`` over fixes j = k−2..k (0 before the first step)."""
    d = np.zeros(len(err))
    d[1:] = ((err[1:] - err[:-1]) ** 2).sum(axis=1) / 2.0
    return np.maximum.reduce([d, np.r_[0.0, d[:-1]], np.r_[0.0, 0.0, d[:-2]]])


def _best(wins: list[tuple[np.ndarray, np.ndarray]], accuracy: str, kind: str
          ) -> tuple[float, dict[str, float]]:
    """(mean per-window median, parameters) of the best filter of ``grid(accuracy, kind)``."""
    cfgs = grid(accuracy, kind)
    arr = {k: np.array([c.get(k, 0.0) for c in cfgs]) for k in ("sigma_w_m", "c_hacc", "sigma_b_m", "tau_s",
                                                                 "gate_sigma", "huber_c", "step_c")}
    medians = np.zeros(len(cfgs))
    for err, h_acc in wins:
        if accuracy == "none":
            r = np.repeat(arr["sigma_w_m"][:, None] ** 2, len(err), axis=1)
        else:
            if not np.isfinite(h_acc).all():
                raise UserError("--accuracy reported: the error series has fixes without h_acc_m")
            r = (arr["c_hacc"][:, None] * h_acc[None, :]) ** 2
        r = r + arr["step_c"][:, None] * step_var_m2(err)[None, :]
        medians += filter_medians(err, r, arr["sigma_b_m"], arr["tau_s"], arr["gate_sigma"],
                                  arr["huber_c"] if kind == "huber" else None)
    medians /= len(wins)
    best = int(np.argmin(medians))
    return float(medians[best]), cfgs[best]


def bound(wins: list[tuple[np.ndarray, np.ndarray]], accuracy: str) -> dict[str, Any]:
    """``raw``, ``window_median`` and the best filter of each kind of ``grid`` (``best_filter``: the
    gated ones; ``best_huber_filter``, ``best_step_filter``; the module doc)."""
    out: dict[str, Any] = {
        "accuracy": accuracy, "windows": len(wins), "filters": len(grid(accuracy)),
        "raw_median_m": float(np.mean([np.median(np.hypot(e[:, 0], e[:, 1])) for e, _ in wins])),
        "window_median_m": float(np.mean([np.hypot(*np.median(e, axis=0)) for e, _ in wins])),
    }
    for kind in KINDS:
        name = "best_filter" if kind == "gate" else f"best_{kind}_filter"
        out[f"{name}_median_m"], out[name] = _best(wins, accuracy, kind)
    return out


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(allow_abbrev=False, prog="python -m gcs_tools.evaluate.real_bound",
                                description=__doc__.split("\n")[0])
    p.add_argument("--corpus", type=Path, default=None, help="the ANSFL directory (path_1, path_2, ...)")
    p.add_argument("--flights", default="tuning", help="tuning, reporting, all, or flight names/paths")
    p.add_argument("--errors", required=True, help="an error series CSV (the campaign's --errors)")
    p.add_argument("--accuracy", default="reported,none", help="comma-separated of reported, none")
    p.add_argument("--seeds", default="0-4")
    args = p.parse_args(argv)
    try:
        accuracies = [a.strip() for a in args.accuracy.split(",") if a.strip()]
        for a in accuracies:
            if a not in ("reported", "none"):
                raise UserError(f"--accuracy {a!r}: not one of reported, none")
        if args.errors in ("model", "none"):
            raise UserError("--errors: give an error series CSV (the model's errors are drawn per replay)")
        wins = windows(args.corpus, args.flights, args.errors, parse_seeds(args.seeds))
        out = [bound(wins, a) for a in accuracies]
    except UserError as exc:
        print(f"real_bound: error: {exc}", file=sys.stderr)
        return 2
    for b in out:  # one JSON object per accuracy
        print(json.dumps(b))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
