"""A smartLoc drive's satellites placed on another flight (``gcs_tools.gnss.transplant``) and the campaign's
``smartloc-sats:INPUT`` condition: known answers on the first minute of the real Berlin drive placed on
a synthetic ANSFL flight (the drive skips without the shared data, fails when CI=true)."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from ansfl_helpers import smartloc_drive_slice, write_flight

from companion.gnss.constants import C_M_S, OMEGA_E_RAD_S
from companion.gnss.geometry import ecef_to_geodetic, ecef_to_ned_matrix, sagnac_range_m
from companion.gnss.observations import make_epoch
from companion.gnss.spp import SppConfig
from companion.gnss.systems import System
from gcs_tools.evaluate import real
from gcs_tools.evaluate.tight import TIGHT_ROWS
from gcs_tools.gnss import transplant
from gcs_tools.gnss.baseline import epoch_residuals_at_truth, solve_series
from gcs_tools.replay.synthetic_gnss import GnssErrorOptions, series_times

SLICE_S = 60.0  # the first minute of the drive: 300 epochs


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The drive's first minute (input and truth) in a temporary directory."""
    return smartloc_drive_slice(tmp_path_factory.mktemp("smartloc"), SLICE_S)


@pytest.fixture(scope="module")
def flight(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("ansfl")
    write_flight(root / "f", seconds=20.0, offset_s=0.2, seed=3)
    return root / "f"


def test_residuals_at_truth_recover_the_clock_per_system_by_the_high_satellites_median() -> None:
    """Known residuals: the median over each system's satellites above 40° is its clock, a reflected
    high satellite (+30 m) does not move it; low ones keep their residuals."""
    p = np.array([3785108.1, 899901.5, 5037234.5])  # Berlin
    lat, lon, _ = (float(v) for v in ecef_to_geodetic(p))
    el = np.radians([85, 60, 50, 45, 20, 10, 70, 55, 15])
    az = np.radians([0, 40, 100, 200, 250, 300, 10, 150, 330])
    ned = np.column_stack((np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el)))
    los = ned @ ecef_to_ned_matrix(lat, lon)
    sat = p + 2.2e7 * los
    system = np.array([System.GPS] * 6 + [System.GALILEO] * 3, dtype=np.int8)
    clock = np.where(system == System.GPS, 1234.5, -87.25)
    resid = np.array([0.0, 30.0, 0.0, 0.0, 45.0, -12.0, 0.0, 0.0, 80.0])
    rho, _ = sagnac_range_m(sat, p)
    ep = make_epoch(0.0, system, np.arange(1, 10), rho + clock + resid, sat_pos_ecef_m=sat, corrected=True)
    at = epoch_residuals_at_truth(ep, p)
    assert np.allclose(at.clock_m, clock, atol=1e-6) and np.allclose(at.residual_m, resid, atol=1e-6)
    assert np.allclose(at.elevation_deg, np.degrees(el), atol=1e-6)


def test_the_drive_epochs_align_to_flight_time_as_the_error_series_does(drive: Path) -> None:
    """Each placed epoch's offset from the flight's first epoch maps back, through the series
    condition's own rule (``synthetic_gnss.series_times``), onto exactly that drive epoch; every drive
    epoch of the window is placed once, and a flight longer than the drive reads it again (wrapped)."""
    sky = transplant.drive_sky(drive)
    for start, span in ((12.34, 20.0), (50.0, 25.0), (3.0, 2.5 * sky.span_s)):
        off, idx = transplant.aligned_offsets_s(sky, start, span)
        assert np.all(np.diff(off) > 0) and off[0] >= 0 and off[-1] <= span
        ts = series_times(sky.t_s, sky.span_s, start, off)
        wrapped = np.mod(ts - sky.t_s[idx] + sky.span_s / 2, sky.span_s) - sky.span_s / 2
        assert np.abs(wrapped).max() < 1e-9
        # none skipped: the gaps between placed epochs are the drive's own (one period across the wrap)
        assert np.diff(off).max() <= max(np.diff(sky.t_s).max(), sky.period_s) + 1e-9
        assert off[0] <= sky.period_s * 1.5 and span - off[-1] <= np.diff(sky.t_s).max() + 1e-9
    assert set(np.bincount(idx).tolist()) <= {2, 3}  # 2.5 spans: every drive epoch twice or three times


def test_placed_pseudoranges_reproduce_the_drives_spp_error_series(drive: Path, flight: Path) -> None:
    """Known answer: the single-point solution of the placed pseudoranges minus the flight's truth equals
    the drive's SPP minus its truth (what ``beliefnav gnss spp`` writes to spp_errors.csv) within 5 cm,
    the flight 80-200 m from where the drive was: the lines of sight turn by < 2·10⁻⁵ rad, moving a
    solution whose error is tens of metres by millimetres (times the DOP). The clock cancels: a placed
    pseudorange is the recorded one plus the change of range."""
    from gcs_tools.gnss.cli import evaluate
    from gcs_tools.gnss.sources import load_input

    sky = transplant.drive_sky(drive)
    opts = GnssErrorOptions("none", series_start_s=38.0)
    placed = transplant.sky_on_flight(flight, sky, opts)
    p = placed.placed
    assert len(p.epochs) >= 85 and not p.wrapped
    _, series, err_csv = evaluate(load_input(drive), SppConfig())
    assert err_csv is not None
    t_csv = series.t_s - series.t_s[np.isfinite(err_csv).all(axis=1)][0]  # the CSV's t_s
    rows = {round(float(t), 6): e for t, e in zip(t_csv, err_csv, strict=True)}
    want = np.array([rows[round(float(sky.t_s[k]), 6)] for k in p.drive_index])
    got = placed.fixes.err_ned_m
    assert len(got) == len(want)  # every placed epoch has a solution, as the drive's had
    p_flight = transplant.ned_to_ecef(sky.origin, p.p_truth_ned_m)
    away = np.linalg.norm(p_flight - sky.truth_ecef_m[p.drive_index], axis=1)
    assert 120.0 < away.max() < 400.0
    assert np.abs(got - want).max() < 0.05 and np.median(np.abs(got - want)) < 0.005, np.abs(got - want).max()
    assert np.percentile(np.hypot(want[:, 0], want[:, 1]), 50) > 5.0  # real urban errors, not a zero test
    k, i = 7, int(p.drive_index[7])
    change = sagnac_range_m(sky.epochs[i].sat_pos_ecef_m, p_flight[k])[0] \
        - sagnac_range_m(sky.epochs[i].sat_pos_ecef_m, sky.truth_ecef_m[i])[0]
    assert np.allclose(p.epochs[k].pseudorange_m - sky.epochs[i].pseudorange_m, change, atol=1e-6)


def test_zero_residuals_give_the_flights_truth(drive: Path, flight: Path) -> None:
    sky = transplant.drive_sky(drive)
    _, truth = _truth(flight, sky)
    p = transplant.place(sky, truth, sky.origin, GnssErrorOptions("none", seed=2), residual_scale=0.0)
    sol = solve_series(p.epochs, SppConfig())
    assert sol.ok.all()
    assert np.abs(sol.p_ecef_m - transplant.ned_to_ecef(sky.origin, p.p_truth_ned_m)).max() < 1e-3


def _truth(flight: Path, sky: transplant.DriveSky) -> tuple[object, object]:
    from gcs_tools.replay.logs import open_log
    from gcs_tools.replay.synthetic_gnss import collect_tracks, to_track

    t = collect_tracks(open_log(flight, None, sky.origin))
    return t, to_track(t.truth_t_us, t.truth_p, t.truth_label, t.truth_geodetic, sky.origin)


def test_campaign_condition_loose_and_tight_rows(drive: Path, flight: Path, tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """The condition's rows: the methods on the SPP fixes, every tight row on the epochs (identical
    with and without a reported accuracy: it changes no pseudorange), the raw fixes, and the belief's
    paired comparisons; bad choices are one-line errors."""
    errors = f"{transplant.PREFIX}{drive}"
    res = real.run([flight], [errors], ["reported", "none"], ["naive"], [0, 1])
    tight = [f"tight-{w}" for w in TIGHT_ROWS]
    assert res["campaign"]["runs"] == 2 * 2 * (1 + len(tight))
    by = {(r["accuracy"], r["seed"], r["row"]): r for r in res["runs"]}
    for s in (0, 1):
        for row in tight:
            a, b = by[("reported", s, row)], by[("none", s, row)]
            assert a["median"] == b["median"] and a["gnss_fused"] >= 80  # ~90 epochs in 20 s
        assert by[("reported", s, real.RAW[0])]["median"] == by[("none", s, real.RAW[0])]["median"]
        assert by[("reported", s, real.RAW[0])]["median"] > 3.0  # Berlin's errors, not the model's
    for cond in res["conditions"]:
        assert list(cond["table"]) == ["naive", *tight, *real.RAW]
        refs = [c["reference"] for c in cond["belief_paired"]]
        assert refs == [*real.BELIEF_REFERENCES, "naive"]
        for c in cond["belief_paired"]:
            mine = [by[(cond["accuracy"], s, "tight-second-order")]["median"] for s in (0, 1)]
            other = [by[(cond["accuracy"], s, c["reference"])]["median"] for s in (0, 1)]
            assert c["median_diff_m"]["mean"] == pytest.approx(np.mean(mine) - np.mean(other))
    text = real.markdown(res)
    assert f"satellites {drive.name}" in text and "`tight-second-order` − `tight-fde`" in text
    assert "SYNTHETIC pseudorange rates" in text
    # no velocity for the fixes: none (no Doppler) for the tight rows either, replayed anew (not memoised)
    res_none = real.run([flight], [errors], ["reported"], ["naive"], [0], velocity_std_m_s=None)
    by_none = {r["row"]: r for r in res_none["runs"]}
    assert all(by_none[row]["median"] != by[("reported", 0, row)]["median"] for row in tight)
    assert "no row gets a velocity" in real.markdown(res_none)
    capsys.readouterr()
    for bad, words in (([transplant.PREFIX], "give the smartLoc input"),
                       ([f"{transplant.PREFIX}{tmp_path / 'no.txt'}"], "no such file"),
                       ([f"{transplant.PREFIX}{flight / 'GT.csv'}"], "no *_GT.txt truth")):
        assert real.main(["--flights", str(flight), "--errors", *bad, "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("real: error: ") and words in err and "\n" not in err, err
    assert not math.isnan(res["conditions"][0]["goals"]["best_median_m"])


def _ecef_rotation(sky: transplant.DriveSky) -> np.ndarray:
    f = sky.origin
    return ecef_to_ned_matrix(math.radians(f.home_lat_deg), math.radians(f.home_lon_deg))


def test_synthetic_doppler_is_the_placed_ranges_rate_and_gives_the_flights_velocity(drive: Path,
                                                                                    flight: Path) -> None:
    """Known answers with zero residuals and zero noise: each rate is the finite-difference derivative of
    the placed range (|sat − p| with its Sagnac term, to 1 mm/s) + the drive's drift; the Doppler-only
    least-squares velocity and drift (the exact model's) are the flight's truth velocity and the drive's
    drift to 1 mm/s; the project's single-point solver gets them within 1 cm/s (2.3 mm/s measured: its
    light-time factor is counted twice here, as the drive's satellite velocities, differentiated over
    reception times, already carry it)."""
    from companion.gnss.spp import solve_position

    sky = transplant.drive_sky(drive)
    _, truth = _truth(flight, sky)
    opts = GnssErrorOptions("none", seed=2, velocity_std_m_s=0.0)
    p = transplant.place(sky, truth, sky.origin, opts, residual_scale=0.0)
    rot = _ecef_rotation(sky)
    v_ecef = truth.velocity_at(p.t_validity_us) @ rot
    p_ecef = transplant.ned_to_ecef(sky.origin, p.p_truth_ned_m)
    h = 0.01
    worst_v, worst_d, worst_exact, n = 0.0, 0.0, 0.0, 0
    for k, (ep, i) in enumerate(zip(p.epochs, p.drive_index.tolist(), strict=True)):
        ok = np.isfinite(ep.sat_vel_ecef_m_s).all(axis=1)
        moved = [sagnac_range_m(ep.sat_pos_ecef_m + s * h * ep.sat_vel_ecef_m_s,
                                p_ecef[k] + s * h * v_ecef[k])[0] for s in (1.0, -1.0)]
        fd = (moved[0] - moved[1]) / (2 * h) + sky.drift_m_s[i]
        assert np.abs(ep.pseudorange_rate_m_s[ok] - fd[ok]).max() < 1e-3
        assert np.isnan(ep.pseudorange_rate_m_s[~ok]).all()
        rs, us, pk = ep.sat_pos_ecef_m[ok], ep.sat_vel_ecef_m_s[ok], p_ecef[k]
        _, los = sagnac_range_m(rs, pk)
        w = OMEGA_E_RAD_S / C_M_S
        y = (ep.pseudorange_rate_m_s[ok] - np.einsum("ij,ij->i", los, us)
             - w * (us[:, 0] * pk[1] - us[:, 1] * pk[0]))
        hm = np.column_stack((-los + w * np.column_stack((-rs[:, 1], rs[:, 0], np.zeros(len(rs)))),
                              np.ones(len(rs))))
        x = np.linalg.lstsq(hm, y, rcond=None)[0]
        worst_exact = max(worst_exact, float(np.abs(x[:3] - v_ecef[k]).max()), abs(x[3] - sky.drift_m_s[i]))
        sol = solve_position(ep, SppConfig())
        if np.isfinite(sol.v_ecef_m_s).all():
            n += 1
            worst_v = max(worst_v, float(np.abs(rot @ (sol.v_ecef_m_s - v_ecef[k])).max()))
            worst_d = max(worst_d, abs(sol.clock_drift_m_s - sky.drift_m_s[i]))
    assert n >= 0.9 * len(p.epochs) and np.abs(v_ecef).max() > 1.0  # a moving flight
    assert worst_exact < 1e-3, worst_exact
    assert worst_v < 0.01 and worst_d < 0.01, (worst_v, worst_d)
    # no velocity for the fixes: no rates for the epochs
    none = transplant.place(sky, truth, sky.origin, GnssErrorOptions("none", seed=2, velocity_std_m_s=None))
    assert all(np.isnan(e.pseudorange_rate_m_s).all() for e in none.epochs)
    assert np.isnan(none.rate_sigma_m_s).all()


def test_synthetic_doppler_noise_has_the_fixes_velocity_information(drive: Path, flight: Path) -> None:
    """The rates' noise over its stated σ has a unit sample std (~1400 draws: within 6 %, 3 standard
    errors), is the seed's and not another's, and the σ give a weighted least-squares velocity whose mean
    per-axis variance is the fixes' velocity std² (0.2 m/s), exactly (the same drive epochs: a fixed
    series start)."""
    sky = transplant.drive_sky(drive)
    _, truth = _truth(flight, sky)
    std = 0.2
    clean, noisy, other = (
        transplant.place(sky, truth, sky.origin,
                         GnssErrorOptions("none", seed=seed, velocity_std_m_s=v, series_start_s=10.0))
        for seed, v in ((4, 0.0), (4, std), (5, std)))
    p_ecef = transplant.ned_to_ecef(sky.origin, noisy.p_truth_ned_m)
    z, z_other = [], []
    for k, (a, b, c) in enumerate(zip(clean.epochs, noisy.epochs, other.epochs, strict=True)):
        sigma = transplant.doppler_sigma_m_s(b, p_ecef[k], std)
        ok = np.isfinite(sigma)
        z.append((b.pseudorange_rate_m_s - a.pseudorange_rate_m_s)[ok] / sigma[ok])
        z_other.append((c.pseudorange_rate_m_s - a.pseudorange_rate_m_s)[ok] / sigma[ok])
        _, los = sagnac_range_m(b.sat_pos_ecef_m[ok], p_ecef[k])
        hm = np.column_stack((-los, np.ones(int(ok.sum())))) / sigma[ok, None]
        q = np.linalg.inv(hm.T @ hm)
        assert np.trace(q[:3, :3]) / 3.0 == pytest.approx(std**2, rel=1e-9)
    zz = np.concatenate(z)
    assert len(zz) > 1000 and abs(zz.std() - 1.0) < 0.06 and abs(zz.mean()) < 0.08  # 3 standard errors
    assert abs(np.corrcoef(zz, np.concatenate(z_other))[0, 1]) < 0.08  # another seed, other noise
    ep = noisy.epochs[0]  # the σ follow C/N0 as the simulated receiver's: 20 dB weaker, 10 × larger
    sigma = transplant.doppler_sigma_m_s(ep, p_ecef[0], std)
    assert np.allclose(sigma / sigma[0], 10.0 ** ((ep.cn0_dbhz[0] - ep.cn0_dbhz) / 20.0))


def test_satellite_velocities_and_clock_drift_known_answers() -> None:
    """A circular orbit sampled at the drive's irregular epochs (0.2 / 0.3 s, a gap): the finite
    differences give its velocity within 1 mm/s (ends included); a clock of known drift gives that drift."""
    t = np.r_[np.arange(0.0, 6.0, 0.2), np.arange(6.3, 9.0, 0.3), np.arange(20.0, 24.0, 0.2)]
    n = 2 * math.pi / 43082.0  # a GPS orbit in inertial space
    pos = 26.56e6 * np.column_stack((np.cos(n * t), np.sin(n * t) * 0.5, np.sin(n * t) * math.sqrt(0.75)))
    vel = 26.56e6 * n * np.column_stack((-np.sin(n * t), np.cos(n * t) * 0.5,
                                         np.cos(n * t) * math.sqrt(0.75)))
    drift = -49.7
    clock = 1000.0 + drift * t + 0.3 * np.sin(t)  # a wandering estimate about a steady drift
    epochs = [make_epoch(ti, [System.GPS], [7], [2.2e7], sat_pos_ecef_m=pi[None], corrected=True)
              for ti, pi in zip(t, pos, strict=True)]
    got = transplant.satellite_velocities(t, epochs)
    v = np.array([e.sat_vel_ecef_m_s[0] for e in got])
    assert np.abs(v - vel).max() < 1e-3
    at = [epoch_residuals_at_truth(e, np.zeros(3)) for e in epochs]
    at = [dataclasses.replace(a, clock_m=np.array([c])) for a, c in zip(at, clock, strict=True)]
    d = transplant.clock_drift_m_s(t, epochs, at)
    assert np.abs(d - drift).max() < 0.1 and np.abs(np.median(d) - drift) < 0.02
    short = transplant.satellite_velocities(t[:2], epochs[:2])  # fewer than 3 epochs: no velocity
    assert all(np.isnan(e.sat_vel_ecef_m_s).all() for e in short)


def _replay_json(args: list[str], capsys: pytest.CaptureFixture[str]) -> dict[str, Any]:
    from gcs_tools.cli import main

    capsys.readouterr()
    assert main(["replay", *args, "--json", "--no-progress"]) == 0, capsys.readouterr().err
    return json.loads(capsys.readouterr().out)


def test_replay_cli_places_the_drives_satellites_as_the_campaign_does(
        drive: Path, flight: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    """``beliefnav replay FLIGHT --gnss-errors smartloc-sats:INPUT --seed 3`` is the campaign's run of that
    flight and seed: loose, its raw fixes' errors are the placed SPP fixes' (exact) and its estimate's
    error to the truth the campaign's second-order run's (exact); ``--coupling tight`` the campaign's
    ``tight-second-order`` run's (exact). The campaign's summaries are taken unrounded."""
    from gcs_tools.replay.core import json_safe

    errors = f"{transplant.PREFIX}{drive}"
    seen: dict[str, dict[str, Any]] = {}
    row = real._row
    monkeypatch.setattr(real, "_row", lambda base, name, s: (seen.setdefault(name, s), row(base, name, s))[1])
    monkeypatch.setattr(real, "_TIGHT_DONE", {})
    real.run_job(real.Job(str(flight), errors, "reported", 3, 5.0, None, ("second-order",)))
    common = [str(flight), "--gnss-errors", errors, "--seed", "3", "--rate-hz", "10",
              "--method", "second-order"]
    loose = _replay_json([*common, "--out", str(tmp_path / "loose")], capsys)
    placed = transplant.sky_on_flight(flight, transplant.drive_sky(drive),
                                      GnssErrorOptions("none", accuracy="reported", seed=3))
    raw = loose["errors"]["raw_fixes"]
    assert {k: raw[k] for k in ("at_validity", "at_arrival")} == json_safe(
        {k: placed.raw_errors[k] for k in ("at_validity", "at_arrival")})
    assert raw["at_arrival"]["error_horizontal_m"]["median"] > 3.0  # Berlin's errors
    assert loose["synthetic_gnss"]["seed"] == 3
    assert loose["synthetic_gnss"]["errors"].startswith("smartloc-sats:")
    want = seen["second-order"]["errors"]["truth"]["error_horizontal_m"]
    assert loose["errors"]["truth"]["error_horizontal_m"] == json_safe(want)
    assert loose["clock_alignment"]["offset_s"] == pytest.approx(0.2, abs=0.01)  # the ANSFL log's, kept
    tight = _replay_json([*common, "--coupling", "tight", "--out", str(tmp_path / "tight")], capsys)
    got = tight["errors"]["truth"]["error_horizontal_m"]["median"]
    assert got == pytest.approx(seen["tight-second-order"]["errors"]["truth"]["error_horizontal_m"]["median"],
                                abs=1e-9)
    assert got != loose["errors"]["truth"]["error_horizontal_m"]["median"]  # not the loose filter
    assert tight["raw_gnss"]["coupling"] == "tight" and tight["navigator"]["gnss_fused"] >= 80
    other = _replay_json([*common[:4], "4", *common[5:], "--out", str(tmp_path / "seed4")], capsys)
    assert other["synthetic_gnss"]["series_start_s"] != loose["synthetic_gnss"]["series_start_s"]
    from gcs_tools.cli import main

    for kind in ("loose", "tight"):  # the replay's outputs are a replay's: the table and its export
        assert (tmp_path / kind / "estimates.csv").is_file()
        assert main(["export", str(tmp_path / kind), "--format", "csv",
                     "--out", str(tmp_path / f"{kind}.csv")]) == 0
        assert (tmp_path / f"{kind}.csv").stat().st_size > 1000


def test_replay_cli_satellites_on_a_log_with_geodetic_truth(drive: Path, tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    """A DataFlash SITL log (SIM truth, geodetic, in another city) moved to the drive: its truth keeps its
    shape (NED about its first point = NED about the drive's origin), the placed fixes reproduce the
    drive's SPP errors (within 5 cm), and the moved autopilot estimate (POS, cm from SIM) is compared in
    the same frame as the truth: the estimate's distances to both agree."""
    from companion.domain.geodesy import LocalNedFrame
    from gcs_tools.replay.logs import open_log
    from gcs_tools.replay.synthetic_gnss import collect_tracks, to_track

    log = Path(__file__).parent / "data" / "arducopter_sitl_hover.bin"
    sky = transplant.drive_sky(drive)
    placed = transplant.sky_on_flight(log, sky, GnssErrorOptions("none", seed=1))
    own = collect_tracks(open_log(log))
    want = to_track(own.truth_t_us, own.truth_p, "", True, LocalNedFrame(*own.truth_p[0]))
    assert np.array_equal(placed.truth.t_us, want.t_us)
    assert np.abs(placed.truth.p_ned_m - want.p_ned_m).max() < 1e-6
    assert placed.placed.wrapped and len(placed.fixes) == len(placed.placed.drive_index)  # 94 s on 60 s
    assert np.abs(placed.fixes.err_ned_m - sky.spp_err_ned_m[placed.placed.drive_index]).max() < 0.05
    s = _replay_json([str(log), "--gnss-errors", f"{transplant.PREFIX}{drive}", "--seed", "1",
                      "--out", str(tmp_path / "o")], capsys)
    assert s["errors"]["autopilot_estimate"]["n"] > 100 and s["errors"]["truth"]["n"] > 100
    ap = s["errors"]["autopilot_estimate"]["error_horizontal_m"]["median"]
    tr = s["errors"]["truth"]["error_horizontal_m"]["median"]
    assert abs(ap - tr) < 0.5 and 1.0 < tr < 30.0, (ap, tr)


def test_replay_cli_satellites_one_line_errors(drive: Path, flight: Path, tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    from gcs_tools.cli import main

    errors = f"{transplant.PREFIX}{drive}"
    no_truth = Path(__file__).parent / "data" / "quad106.tlog"  # a real flight: its own fixes, no truth
    for args, words in (
            ([str(flight), "--gnss-errors", f"{transplant.PREFIX}{tmp_path / 'no.txt'}"], "no such file"),
            ([str(flight), "--gnss-errors", f"{transplant.PREFIX}{flight / 'GT.csv'}"], "no *_GT.txt truth"),
            ([str(flight), "--gnss-errors", "model", "--coupling", "tight"], "fixes carry no satellites"),
            ([str(flight), "--gnss-errors", "none", "--coupling", "tight"], "fixes carry no satellites"),
            ([str(no_truth), "--gnss-errors", errors], "no ground truth"),
            ([str(flight), "--gnss-errors", errors, "--gnss-base", "log"], "on the log's truth"),
            ([str(flight), "--gnss-errors", errors, "--home", "52.5,13.4,40"], "moved to the drive"),
            ([str(flight), "--gnss-errors", errors, "--coupling", "tight", "--method", "bogus"], "bogus"),
            ([str(flight), "--gnss-errors", errors, "--ubx", str(drive)], "choose one")):
        capsys.readouterr()
        assert main(["replay", *args, "--out", str(tmp_path / "o")]) == 2, args
        err = capsys.readouterr().err.strip()
        assert err.startswith("beliefnav: error: ") and words in err and "\n" not in err, err
    assert not (tmp_path / "o").exists()
