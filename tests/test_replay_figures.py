"""``beliefnav replay``'s figures: track.png and errors.png from real logs, --no-figures, and the pure
plotting functions on small synthetic arrays (with and without truth, with NaNs)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread

from gcs_tools.cli import main
from gcs_tools.replay import core, figures

DATA = Path(__file__).parent / "data"
QUAD106 = DATA / "quad106.tlog"  # real 668 s flight: fixes, no autopilot position, no truth
SITL_BIN = DATA / "arducopter_sitl_hover.bin"  # SITL: fixes, the autopilot's estimate (POS), truth (SIM)
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _assert_png(path: Path, min_px: int = 300) -> None:
    assert path.read_bytes()[:8] == PNG_MAGIC, path
    assert 20_000 < path.stat().st_size < 2_000_000, (path, path.stat().st_size)
    img = imread(path)
    assert img.shape[0] >= min_px and img.shape[1] >= min_px, img.shape
    assert float(np.std(img[..., :3])) > 0.05  # not a blank canvas


def test_real_tlog_writes_both_figures_and_prints_them(quad106_replayed: tuple[Path, str]) -> None:
    out, printed = quad106_replayed  # `beliefnav replay QUAD106 --out OUT --no-progress`, exit 0
    for name in ("track.png", "errors.png"):
        _assert_png(out / name)
    assert f"wrote {out}/: estimates.csv, gnss_fixes.csv, summary.json, track.png, errors.png" in printed
    # the figure's estimate-to-fix distance is the summary's (same rows, same interpolation, all fixes)
    t_s, table = figures.read_estimates(out / "estimates.csv")
    summary = json.loads((out / "summary.json").read_text())
    result = core.replay(QUAD106, "second-order")
    d = figures.horizontal_distance(t_s, table[:, :2], result.tracks["gnss"])
    gnss = summary["errors"]["gnss"]
    assert np.isfinite(d).sum() == gnss["n"]
    assert np.nanmedian(d) == pytest.approx(gnss["error_horizontal_m"]["median"], abs=1e-5)
    assert np.nanmax(d) == pytest.approx(gnss["error_horizontal_m"]["max"], abs=1e-5)
    assert set(result.tracks) == {"gnss"}  # this log has no autopilot position and no truth


def test_log_with_truth_and_autopilot_tracks(tmp_path: Path) -> None:
    out = tmp_path / "b"
    assert main(["replay", str(SITL_BIN), "--out", str(out), "--no-progress"]) == 0
    _assert_png(out / "track.png")
    _assert_png(out / "errors.png")
    result = core.replay(SITL_BIN, "second-order", rate_hz=0)
    assert {"gnss", "truth", "autopilot_estimate"} <= set(result.tracks)
    for kind, rows in result.tracks.items():
        assert rows.shape[1] == 5 and len(rows) > 100 and np.isfinite(rows).all(), kind
        assert (rows[:, 4] == 0).all()  # one segment
        assert np.diff(rows[:, 0]).min() >= core.TRACK_PERIOD_US / 1e6 - 1e-9, kind  # bounded: ≤ 10 Hz
        d = figures.horizontal_distance(result.t_us / 1e6, result.table[:, :2], rows)
        # a hover: the estimate within centimetres of every reference, in the same frame
        assert np.nanmax(d) <= result.summary["errors"][kind]["error_horizontal_m"]["max"] + 1e-6, kind


def test_concatenated_log_compares_each_segment_with_its_own_estimates(tmp_path: Path) -> None:
    """Two copies of a log: two segments on the same boot times; the figure's distances, computed per
    segment, are the summary's (which restarts its comparisons at the restart)."""
    log = tmp_path / "twice.bin"
    log.write_bytes(SITL_BIN.read_bytes() * 2)
    result = core.replay(log, "second-order")
    assert result.summary["log_restarts"] == 1
    seg = result.table[:, core.CSV_COLUMNS.index("segment") - 1]
    for kind in ("gnss", "truth"):
        rows = result.tracks[kind]
        assert set(rows[:, 4]) == {0.0, 1.0}, kind
        d = figures.horizontal_distance(result.t_us / 1e6, result.table[:, :2], rows, seg)
        h = result.summary["errors"][kind]["error_horizontal_m"]
        assert np.nanmax(d) <= h["max"] + 1e-6, kind
    d = figures.horizontal_distance(result.t_us / 1e6, result.table[:, :2], result.tracks["gnss"], seg)
    gnss = result.summary["errors"]["gnss"]  # every fix kept: the summary's numbers exactly
    assert np.isfinite(d).sum() == gnss["n"]
    assert np.nanmedian(d) == pytest.approx(gnss["error_horizontal_m"]["median"], abs=1e-6)
    g = result.gnss["gnss_fixes.csv"]  # the per-fix record, kept in memory without --out: per segment
    assert set(g["segment"]) == {0.0, 1.0} and (g["reason"] == "start").sum() == 2  # a fresh navigator each
    assert (g["reason"] == "fused").sum() + 2 == result.summary["navigator"]["gnss_fused"]
    figures.save(tmp_path, result.t_us / 1e6, result.table, result.tracks, log.name, "second-order", "loose",
                 result.gnss)
    _assert_png(tmp_path / "track.png")
    _assert_png(tmp_path / "errors.png")
    # segments on the same clock, 10 m apart: each compared with its own estimate, never the other's
    t = np.tile(np.arange(5.0), 2)
    seg2 = np.repeat([0.0, 1.0], 5)
    p = np.column_stack([10 * seg2, np.zeros(10)])
    ref = np.column_stack([t + 0.5, p, np.zeros(10), seg2])[[0, 1, 2, 3, 5, 6, 7, 8]]
    np.testing.assert_allclose(figures.horizontal_distance(t, p, ref, seg2), 0.0, atol=1e-12)
    assert np.nanmax(figures.horizontal_distance(t, p, ref[:, :4])) > 1.0  # what mixing them would give
    x, y = figures.broken(np.array([0, 0, 1, 1, 1, 2]), np.arange(6.0), np.ones((6, 2)))
    assert np.isnan(x[[2, 6]]).all() and len(x) == 8 and np.isnan(y[[2, 6]]).all() and y.shape == (8, 2)


def test_no_figures_writes_none(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "n"
    assert main(["replay", str(SITL_BIN), "--out", str(out), "--no-progress", "--no-figures"]) == 0
    assert f"wrote {out}/: estimates.csv, gnss_fixes.csv, summary.json\n" in capsys.readouterr().out
    assert (out / "estimates.csv").is_file()
    assert not list(out.glob("*.png"))


def test_a_previous_runs_record_in_the_same_out_is_not_taken_for_this_runs(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A tight replay's gnss_epochs.csv left in --out by an earlier run: a loose replay into the same
    directory removes it (it was listed as written and drawn into this run's figures)."""
    out = tmp_path / "same"
    out.mkdir()
    (out / "gnss_epochs.csv").write_text("t_s,segment,n_sats,n_used,n_excluded,n_low_belief,beta_mean,"
                                         "nis,reset,reason\n1.0,0,9,0,9,0,,,0,no_satellite_used\n")
    (out / "track.png").write_bytes(PNG_MAGIC)  # and its figures: not this run's with --no-figures
    assert main(["replay", str(SITL_BIN), "--out", str(out), "--no-progress", "--no-figures"]) == 0
    assert f"wrote {out}/: estimates.csv, gnss_fixes.csv, summary.json\n" in capsys.readouterr().out
    assert not (out / "gnss_epochs.csv").exists() and not (out / "track.png").exists()
    assert (out / "gnss_fixes.csv").is_file()


def test_at_times_interpolates_and_refuses_gaps() -> None:
    t = np.array([0.0, 1.0, 2.0, 5.0, 5.5])
    x = np.column_stack([3 * t + 1, -t])
    got = figures.at_times(t, x, np.array([-0.1, 0.0, 0.25, 1.5, 3.0, 5.25, 6.0, np.nan]))
    expect = np.array([[np.nan] * 2, [1, 0], [1.75, -0.25], [5.5, -1.5], [np.nan] * 2, [16.75, -5.25],
                       [np.nan] * 2, [np.nan] * 2])
    np.testing.assert_allclose(got, expect, atol=1e-12)  # 3.0 lies in a 3 s gap: not compared
    x[1] = np.nan  # a NaN sample is left out: 0.5 interpolates between 0 and 2 (2 s apart: a gap)
    assert np.isnan(figures.at_times(t, x, np.array([0.5]))).all()
    assert figures.at_times(t, x, np.array([0.5]), max_gap_s=2.0)[0, 0] == pytest.approx(2.5)
    assert figures.at_times(t[:1], x[:1], np.array([0.0])).shape == (1, 2)


@pytest.mark.parametrize("with_truth", [True, False])
def test_figure_functions_on_tiny_arrays_with_nans(tmp_path: Path, with_truth: bool) -> None:
    rng = np.random.default_rng(3)
    t = np.linspace(0.0, 4.0, 9)
    p = np.column_stack([t, 2 * t]) + rng.normal(0, 0.1, (9, 2))
    p[3] = np.nan
    sigma = np.full(9, 0.5)
    sigma[5] = np.nan
    ref = np.column_stack([t, t, 2 * t, np.zeros(9)])
    ref[2, 1] = np.nan
    tracks = {"gnss": ref[::2] + [0, 0.3, -0.2, 0], "autopilot_estimate": ref}
    if with_truth:
        tracks["truth"] = ref
    beta = np.linspace(0.5, 1.0, 9)
    beta[0] = np.nan
    figures.track_figure(tmp_path / "t.png", p, tracks, "tiny")
    figures.errors_figure(tmp_path / "e.png", t, p, sigma, tracks, beta, "belief β", "tiny")
    figures.errors_figure(tmp_path / "e1.png", t, p, sigma, {}, None)  # nothing to compare, no belief
    figures.track_figure(tmp_path / "t0.png", np.zeros((0, 2)), {}, "")  # empty
    for name in ("t.png", "e.png", "e1.png", "t0.png"):
        assert (tmp_path / name).read_bytes()[:8] == PNG_MAGIC
    d = figures.horizontal_distance(t, p, tracks["autopilot_estimate"])
    assert np.isnan(d[2])  # a NaN reference is not compared
    assert np.isfinite(d[3])  # a NaN estimate row: its neighbours, 1 s apart (not a gap), are interpolated
    assert np.nanmax(d) < 1.0


def _step_series(path: Path) -> Path:
    """An error series (5 Hz) with two northward GNSS steps on the hover: 30 m for 2 s from series time
    30 s, 40 m for 12 s from 50 s (held as a step for gnss_offset_max_s = 5 s, then reset onto)."""
    t = np.round(np.arange(0.0, 120.0, 0.2), 3)
    north = np.where((t >= 30) & (t < 32), 30.0, 0.0) + np.where((t >= 50) & (t < 62), 40.0, 0.0)
    rows = "".join(f"{a:.3f},{n:.3f},0,0,0.5,1.0\n" for a, n in zip(t, north, strict=True))
    path.write_text("t_s,err_n_m,err_e_m,err_d_m,h_acc_m,v_acc_m\n" + rows)
    return path


def test_glitch_fixes_are_recorded_rejected_and_marked(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """gnss_fixes.csv: one row per fix with the estimator's decision, the same counts as the navigator's
    counters; the stepped fixes rejected or held (not fused), one reset 5 s into the long step, the rest
    fused."""
    from gcs_tools.replay import gnss_record

    out = tmp_path / "g"
    series = _step_series(tmp_path / "steps.csv")
    assert main(["replay", str(SITL_BIN), "--gnss-errors", str(series), "--gnss-series-start-s", "0",
                 "--gnss-latency-ms", "100", "--out", str(out), "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert f"wrote {out}/: estimates.csv, gnss_fixes.csv, summary.json, track.png, errors.png" in printed
    _assert_png(out / "track.png")
    _assert_png(out / "errors.png")
    assert not (out / "gnss_epochs.csv").exists()  # loose coupling: fixes, no raw epochs
    g = gnss_record.read(out / "gnss_fixes.csv")
    nav = json.loads((out / "summary.json").read_text())["navigator"]
    reason, accepted, north, t = g["reason"], g["accepted"], g["p_n_m"], g["t_s"]
    count = {r: int((reason == r).sum()) for r in set(reason)}
    # every fix the navigator was given has its row
    assert len(t) == nav["gnss_fused"] + sum(n for k, n in nav.items() if k.startswith("gnss_rejected_"))
    assert count.get("innovation", 0) == nav["gnss_rejected_innovation"] == 2  # the first fix of each step
    assert count.get("reset", 0) == nav["gnss_resets"] == 1
    assert count.get("return", 0) == nav["gnss_offset_returns"]
    taken = sum(count.get(r, 0) for r in ("start", "fused", "step", "reset", "return"))
    assert taken == nav["gnss_fused"]  # the counters count held (step) fixes as fused
    for r in set(reason) - {"start", "fused", "step", "reset", "return", "innovation"}:
        assert count[r] == nav[f"gnss_rejected_{r}"], r  # refused before the gate: future, too old, ...
    assert ((accepted == 1) == np.isin(reason, ["start", "fused", "reset", "return"])).all()
    short = (north > 20) & (north < 35)  # the 2 s step: not one fix fused
    assert short.sum() >= 9 and (accepted[short] == 0).all()
    assert (reason[short] == "innovation").sum() == 1
    assert set(reason[short]) <= {"innovation", "step", "future"}
    long = north > 35
    t_reset = t[reason == "reset"][0]
    assert 5.0 <= t_reset - t[long][0] < 6.0  # accepted as the GNSS's new track after 5 s held
    assert (accepted[long & (t < t_reset)] == 0).all()
    assert (accepted[long & (t > t_reset) & (reason != "future")] == 1).all()
    clean = north < 1.0  # the hover's own fixes: fused, or refused before the gate, never gated
    assert set(reason[clean]) <= {"start", "fused", "return", "future", "too_old", "fix_type"}
    ratio = g["test_ratio"]
    assert (ratio[reason == "innovation"] > 1.0).all() and np.nanmax(ratio[clean & (reason == "fused")]) < 1.0
