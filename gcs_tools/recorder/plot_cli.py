"""``beliefnav plot FILE``: redraw a run's figures from a recording."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from gcs_tools.recorder.recording import read_recording, series


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", help="recording made by `beliefnav record`")
    parser.add_argument("--out", help="output folder (default: next to the recording)")
    parser.add_argument("--vehicle", help="only this vehicle (default: all)")


def overview_figure(s: dict[str, np.ndarray], buildings_ne_m: np.ndarray, title: str):  # -> Figure
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    fig, ax = plt.subplots(2, 2, figsize=(12, 9))
    m = ax[0, 0]
    for n0, e0, n1, e1 in buildings_ne_m:
        m.add_patch(Rectangle((e0, n0), e1 - e0, n1 - n0, color="0.6"))
    m.plot(s["p_ref_ned_m"][:, 1], s["p_ref_ned_m"][:, 0], "k--", lw=1, label="reference")
    m.plot(s["p_true_ned_m"][:, 1], s["p_true_ned_m"][:, 0], "C0", label="true")
    m.plot(s["p_est_ned_m"][:, 1], s["p_est_ned_m"][:, 0], "C1", lw=0.8, label="estimated")
    m.set(xlabel="east [m]", ylabel="north [m]", aspect="equal", title="track")
    m.legend(loc="best")
    t = s["t_s"]
    ax[0, 1].plot(t, s["beta"], "C2")
    ax[0, 1].set(ylabel="β", ylim=(-0.05, 1.05), title="GNSS trust and NIS")
    nis = ax[0, 1].twinx()
    nis.plot(t, s["nis"], "C3", lw=0.6, alpha=0.7)
    nis.set_ylabel("NIS")
    ax[1, 0].plot(t, s["est_error_m"], "C1", label="estimation ‖p̂ − p‖")
    ax[1, 0].plot(t, s["track_error_m"], "C0", label="tracking ‖p − p_ref‖")
    ax[1, 0].set(xlabel="time [s]", ylabel="error [m]", title="errors")
    ax[1, 0].legend(loc="best")
    ax[1, 1].plot(t, s["latency_s"] * 1e3, "C4")
    ax[1, 1].set(xlabel="time [s]", ylabel="latency [ms]", title="GNSS latency")
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def run(args: argparse.Namespace) -> int:
    rec = read_recording(args.file)
    out = Path(args.out) if args.out else Path(args.file).with_suffix("")
    out.mkdir(parents=True, exist_ok=True)
    vehicles = [args.vehicle] if args.vehicle else rec.vehicles
    for v in vehicles:
        s = series(rec, v)
        routes = rec.messages[v].get("route", [])
        buildings = routes[-1].buildings_ne_m if routes else np.zeros((0, 4))
        fig = overview_figure(s, buildings, f"{Path(args.file).name}: {v}")
        path = out / f"{v}_overview.png"
        fig.savefig(path, dpi=110)
        print(f"{path}: {len(s['t_s'])} estimates, median error {np.nanmedian(s['est_error_m']):.2f} m")
    if rec.malformed:
        print(f"{rec.malformed} malformed lines skipped", file=sys.stderr)
    return 0
