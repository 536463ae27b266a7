"""Per-flight statistics, stratified bootstrap, ablation rows and ``evaluate --scenario --rows``."""

import json

import numpy as np
import pytest

from companion.errors import UserError
from gcs_tools.evaluate import ablation, flights, stats
from gcs_tools.evaluate.campaign import Job, JobResult, Row, grid_rows
from gcs_tools.evaluate.rows import load_rows, select


def test_flight_stats_known_answers():
    n = 5
    p_true = np.zeros((n, 3))
    e = np.array([[3.0, 4.0, 0.0], [0.0, 0.0, 2.0], [1.0, 0.0, 0.0], [np.nan] * 3, [0.0, 1.0, 1.0]])
    var = np.array([[1.0, 4.0, 1.0]] * n)
    series = {"p_est_ned_m": p_true + e, "p_true_ned_m": p_true, "p_var_ned_m2": var,
              "nis": np.array([np.nan, 1.0, 2.0, 3.0, 6.0]), "track_error_m": np.arange(n, dtype=float)}
    s = stats.flight_stats(series)
    # horizontal: 5, 0, 1, 1 → median 1; 3-D: 5, 2, 1, √2 → median (√2 + 2) / 2
    assert s["est_h_median_m"] == pytest.approx(1.0)
    assert s["est_3d_median_m"] == pytest.approx((np.sqrt(2.0) + 2.0) / 2.0)
    # NEES: 9 + 16/4 = 13, 4, 1, 1/4 + 1 = 1.25 → mean 19.25 / 4, one above χ²₀.₉₅(3) = 7.81
    assert s["nees_mean"] == pytest.approx(19.25 / 4.0)
    assert s["nees_out95"] == pytest.approx(0.25)
    assert s["nis_mean"] == pytest.approx(3.0) and s["track_median_m"] == pytest.approx(2.0)


def test_stratified_bootstrap_resamples_within_strata():
    rng = np.random.default_rng(0)
    strata = np.array([0, 0, 0, 1, 1, 5, 5])
    idx = stats.stratified_indices(strata, rng, 500)
    assert idx.shape == (500, 7)
    counts = np.stack([(strata[idx] == s).sum(axis=1) for s in (0, 1, 5)], axis=1)
    assert (counts == [3, 2, 2]).all()  # every resample keeps each profile's number of flights
    # one flight per profile: nothing to resample within a profile, so flights are resampled together
    single = stats.stratified_indices(np.arange(6), rng, 500)
    assert len({tuple(r) for r in single.tolist()}) > 400
    strata = strata[:6]
    # a constant sample has a zero-width interval; a shifted one moves by the shift
    m, lo, hi = stats.mean_ci(np.full(6, 2.0), strata, rng)
    assert (m, lo, hi) == (2.0, 2.0, 2.0)
    v = rng.normal(size=6)
    a = stats.mean_ci(v, strata, np.random.default_rng(1))
    b = stats.mean_ci(v + 1.0, strata, np.random.default_rng(1))
    np.testing.assert_allclose(np.array(b) - np.array(a), 1.0, atol=1e-12)


def _result(profile: int, seed: int, label: str, method: str, h: float) -> JobResult:
    job = Job("test", profile, method, seed, label="" if label == method else label)
    z = np.zeros(1, dtype=np.float32)
    flight = {k: h for k in flights.KEYS}
    return JobResult(job, {}, 0.0, 0.0, 0.0, z, z, z, z, np.zeros((1, 2)), np.zeros((1, 2)), flight)


def test_paired_differences_match_flights_and_flag_significance():
    rng = np.random.default_rng(3)
    res = []
    for p in range(3):
        for s in range(8):
            base = 1.0 + p + 0.1 * rng.normal()
            res.append(_result(p, s, "second-order", "second-order", base))
            res.append(_result(p, s, "fixed-beta-0.5", "fixed-beta", base + 0.2 + 0.01 * rng.normal()))
            res.append(_result(p, s, "same", "naive", base))
    block = flights.build(res, ["second-order", "fixed-beta-0.5", "same"], "second-order", ["fixed-beta-0.5"])
    d = block["paired_reference_minus_row"]["fixed-beta-0.5"]["est_h_median_m"]
    assert d["mean_difference"] == pytest.approx(-0.2, abs=0.01) and d["significant"]
    assert d["ci95"][1] < 0
    same = block["paired_reference_minus_row"]["same"]["est_h_median_m"]
    assert same["mean_difference"] == 0.0 and same["ci95"] == [0.0, 0.0] and not same["significant"]
    assert flights.best_row(block, ["second-order", "fixed-beta-0.5"]) == "second-order"
    # a second reference: the same pairs with the sign flipped; every flight kept for recomputation
    e = block["paired_by_reference"]["fixed-beta-0.5"]["second-order"]["est_h_median_m"]
    assert e["mean_difference"] == pytest.approx(-d["mean_difference"], abs=1e-12)
    assert block["paired_by_reference"]["second-order"] is block["paired_reference_minus_row"]
    assert len(block["per_flight"]["same"]) == 24 and "| `same` | 24 |" in flights.markdown_paired(
        block, "fixed-beta-0.5")
    assert "| `fixed-beta-0.5` | 24 |" in flights.markdown(block)
    # the ratio against the base row for the severity figure, with its paired interval
    r, lo, hi = ablation.ratio_ci(res, "fixed-beta-0.5", "second-order", np.random.default_rng(0), 500)
    assert lo < r < hi and r > 1.0


def test_rows_file_and_grid(tmp_path):
    f = tmp_path / "rows.yaml"
    f.write_text("rows:\n  fb: {method: fixed-beta, set: {estimator.beta_fixed: 0.5}}\n"
                 "  second-order: {method: second-order}\n")
    rows = load_rows(f)
    assert rows == [Row("fb", "fixed-beta", (("estimator.beta_fixed", 0.5),)),
                    Row("second-order", "second-order")]
    jobs = grid_rows("test", [0], rows, [1, 2], overrides=(("estimator.eta", 0.3),), scenario="realistic")
    assert [j.row for j in jobs] == ["fb", "fb", "second-order", "second-order"]
    assert jobs[0].overrides == (("estimator.eta", 0.3), ("estimator.beta_fixed", 0.5))
    assert jobs[0].scenario == "realistic" and jobs[2].label == ""
    assert select(rows, "second-order") == rows[1:]
    with pytest.raises(UserError, match="unknown row 'x'"):
        select(rows, "x")
    f.write_text("rows:\n  a: {method: warp-drive}\n")
    with pytest.raises(UserError, match="unknown method 'warp-drive'"):
        load_rows(f)
    f.write_text("rows: []\n")
    with pytest.raises(UserError, match="non-empty 'rows:'"):
        load_rows(f)


def test_severity_levels_scale_the_unmodelled_gnss():
    assert ablation.severity_overrides(0.0) == ()
    one = dict(ablation.severity_overrides(1.0))
    from companion.mission.scenarios import UNMODELLED_GNSS

    for key, value in UNMODELLED_GNSS.items():  # s = 1 is the mismatch scenario's GNSS
        assert one[f"gnss.{key}"] == value
    assert dict(ablation.severity_overrides(2.0))["gnss.nlos_delay_mean_m"] == 2.0


def test_evaluate_cli_with_scenario_and_rows(tmp_path, capsys):
    from gcs_tools.cli import main

    rows = tmp_path / "rows.yaml"
    rows.write_text("rows:\n  fixed-beta-0.5: {method: fixed-beta, set: {estimator.beta_fixed: 0.5}}\n"
                    "  map-beta: {method: map-beta}\n")
    out = tmp_path / "out"
    args = ["evaluate", "--mission", "test", "--profiles", "1", "--rows", str(rows), "--seeds", "0-1",
            "--max-duration", "4", "--out", str(out), "--no-progress"]
    assert main([*args, "--scenario", "urban"]) == 2
    assert "--scenario 'urban': not one of paper, realistic, mismatch" in capsys.readouterr().err
    assert main([*args, "--scenario", "mismatch", "--reference", "fixed-beta-0.5,nope"]) == 2
    assert "--reference 'nope': not among the rows" in capsys.readouterr().err
    assert main([*args, "--scenario", "mismatch", "--reference", "fixed-beta-0.5,map-beta"]) == 0
    res = json.loads((out / "results.json").read_text())
    assert res["campaign"]["scenario"] == "mismatch" and res["campaign"]["reference"] == "fixed-beta-0.5"
    assert set(res["flights"]["paired_by_reference"]) == {"fixed-beta-0.5", "map-beta"}
    block = res["flights"]
    assert set(block["rows"]) == {"fixed-beta-0.5", "map-beta"} and block["rows"]["map-beta"]["flights"] == 2
    assert block["rows"]["map-beta"]["nees_mean"]["mean"] > 0
    assert "## Per-flight statistics" in (out / "report.md").read_text()
    # the ablation report picks the campaign up (scenario directory layout) with its rows and cost
    abl = tmp_path / "abl"
    (abl / "realistic").mkdir(parents=True)
    (abl / "realistic" / "results.json").write_text((out / "results.json").read_text())
    (abl / "realistic-velocity").mkdir()  # a campaign directory of its own, after the scenario's
    (abl / "realistic-velocity" / "results.json").write_text((out / "results.json").read_text())
    level = {"second-order": {"ratio": 1.0, "lo": 0.8, "hi": 1.1}, "fixed-beta-best": {"mean_m": 1.5}}
    level1 = {**level, "second-order": {"ratio": 0.9, "lo": 0.7, "hi": 1.0}}
    sev = {"base": "fixed-beta-best", "score": "est_h_median_m", "profiles": [0], "seeds": [0],
           "mission": "test", "wall_s": 1.0, "levels": {"0.0": level, "1.0": level1}}
    (abl / "severity").mkdir()
    (abl / "severity" / "severity.json").write_text(json.dumps(sev))
    ablation.figure(sev, abl / "severity" / "fig_where_adaptation_pays.png")
    text = ablation.report(abl)
    assert "## `realistic`" in text and "`map-beta` = `map-beta`: defaults" in text
    assert text.index("## `realistic`") < text.index("## `realistic-velocity`") < text.index("## Where")
    assert "Paired against `map-beta` (`map-beta` − row" in text and "| `fixed-beta-0.5` | 2 |" in text
    assert "| 1.0 | 0.900 [0.700, 1.000] | 1.500 |" in text
    assert (abl / "severity" / "fig_where_adaptation_pays.png").stat().st_size > 1000


def test_tune_only_retunes_some_rows_pairs_the_points_and_inherits(tmp_path, monkeypatch):
    """``tune --only``: the named rows are swept (every point on the same flights, the winner by
    the lowest mean), map-hmm starts from map-beta's winner, the other rows stay as the file has them."""
    shared = (("estimator.sigma_acc_m_s2", 0.4),)
    kept = [Row("fixed-beta-0.5", "fixed-beta", shared + (("estimator.beta_fixed", 0.5),)),
            Row("second-order", "second-order", shared + (("estimator.eta", 0.5),))]
    ablation.write_rows(tmp_path / "rows-mismatch.yaml", kept, "mismatch", [0], [1000])
    flights_flown = []

    def fake_fly(rows, scenario, profiles, seeds, workers, *a, **k):
        out = []
        for row in rows:
            o = dict(row.overrides)
            assert o["estimator.sigma_acc_m_s2"] == 0.4  # the shared value from the rows file
            score = (abs(o.get("belief_plugins.map_beta_canyon", 0.5) - 0.35)
                     + abs(o.get("belief_plugins.mhmm_evidence", 0.3) - 0.3)
                     + 0.01 * o.get("belief_plugins.map_beta_open", 0))
            for p in profiles:
                for s in seeds:  # a flight effect shared by every point: pairing removes it
                    out.append(_result(p, s, row.label, row.method, score + 0.5 * np.sin(7 * p + s)))
                    flights_flown.append((row.label, p, s))
        return out

    monkeypatch.setattr(ablation, "_fly", fake_fly)
    with pytest.raises(UserError, match="--only: no sweep for nope"):
        ablation.tune("mismatch", [1000, 1001], [0, 1], 1, tmp_path, ["nope"])
    rows = {r.label: r for r in ablation.tune("mismatch", [1000, 1001], [0, 1], 1, tmp_path,
                                              ["map-beta", "map-hmm"])}
    assert dict(rows["map-beta"].overrides)["belief_plugins.map_beta_canyon"] == 0.35
    assert dict(rows["map-beta"].overrides)["belief_plugins.map_beta_open"] == 0.9
    hmm = dict(rows["map-hmm"].overrides)
    assert hmm["belief_plugins.map_beta_canyon"] == 0.35 and hmm["belief_plugins.mhmm_evidence"] == 0.3
    assert rows["second-order"] == kept[1] and set(rows) == {"fixed-beta-0.5", "second-order", "map-beta",
                                                             "map-hmm"}
    assert load_rows(tmp_path / "rows-mismatch.yaml") == list(rows.values())
    records = [json.loads(line) for line in (tmp_path / "tuning-mismatch.jsonl").read_text().splitlines()]
    assert len(records) == 6 + 6 and len(flights_flown) == 12 * 4
    for r in records:  # the paired gap is the score difference exactly: the flight effect cancels
        lo_gap = r["paired_gap_to_winner_m"]
        assert lo_gap[0] == pytest.approx(lo_gap[1], abs=1e-4) == pytest.approx(lo_gap[2], abs=1e-4)
        assert lo_gap[0] >= 0.0


@pytest.mark.parametrize(("gain_m", "kept"), [(0.02, True), (0.3, False)])
def test_retune_keeps_a_row_unless_another_point_beats_it_significantly(tmp_path, monkeypatch, gain_m, kept):
    """``tune --only second-order``: η 0.15 has the lower mean. With a gain of 0.02 m against
    flight-to-flight scatter of ±0.2 m (paired interval including zero) the row keeps η 0.5; with
    0.3 m (interval excluding zero) it moves."""
    shared = (("estimator.sigma_acc_m_s2", 0.4),)
    incumbent = shared + (("estimator.eta", 0.5), ("estimator.lambda_bias_level", 0.0))
    ablation.write_rows(tmp_path / "rows-mismatch.yaml",
                        [Row("fixed-beta-0.5", "fixed-beta", shared + (("estimator.beta_fixed", 0.5),)),
                         Row("second-order", "second-order", incumbent)], "mismatch", [0], [1000])

    def fake_fly(rows, scenario, profiles, seeds, workers, *a, **k):
        out = []
        for row in rows:
            o = dict(row.overrides)
            base = 1.0 + 0.1 * o["estimator.lambda_bias_level"]
            for p in profiles:
                for s in seeds:  # η 0.15's gain scatters by ±0.2 m from flight to flight
                    wobble = 0.2 * np.sin(3.0 * p + 5.0 * s) if o["estimator.eta"] == 0.15 else 0.0
                    gain = gain_m if o["estimator.eta"] == 0.15 else 0.0
                    out.append(_result(p, s, row.label, row.method, base - gain + wobble))
        return out

    monkeypatch.setattr(ablation, "_fly", fake_fly)
    rows = {r.label: r for r in ablation.tune("mismatch", [1000, 1001], [0, 1, 2, 3], 1, tmp_path,
                                              ["second-order"])}
    records = [json.loads(line) for line in (tmp_path / "tuning-mismatch.jsonl").read_text().splitlines()]
    means = {r["overrides"]["estimator.eta"]: r["score_est_h_median_m"] for r in records
             if r["overrides"]["estimator.lambda_bias_level"] == 0.0}
    assert means[0.15] < means[0.5]  # the lowest mean is η 0.15 either way
    assert dict(rows["second-order"].overrides)["estimator.eta"] == (0.5 if kept else 0.15)


def test_shared_setting_is_chosen_alike_for_every_row(tmp_path, monkeypatch, capsys):
    """``ablation shared``: each value flies every row on the same flights; the lowest mean of the
    rows' scores wins and every value is recorded."""
    rows = [Row("a", "fixed-beta", (("estimator.beta_fixed", 0.5),)), Row("b", "map-beta")]

    def fake_fly(cands, scenario, profiles, seeds, workers, *a, **k):
        out = []
        for c in cands:
            v = dict(c.overrides)["estimator.gnss_offset_max_s"]
            base = {"a": 1.0, "b": 2.0}[c.label.split("@")[0]]
            h = base + (0.1 if v == 60.0 else 0.0) + (0.05 if v == 5.0 and c.label.startswith("a") else 0.0)
            out += [_result(p, s, c.label, c.method, h) for p in profiles for s in seeds]
        return out

    monkeypatch.setattr(ablation, "_fly", fake_fly)
    best = ablation.shared_sweep("mismatch", rows, "estimator.gnss_offset_max_s", [60.0, 10.0, 5.0],
                                 [1000, 1001], [0, 1], 1, tmp_path)
    assert best == 10.0  # 60: means 1.6; 10: 1.5; 5: 1.525
    recs = [json.loads(line) for line in (tmp_path / "tuning-mismatch.jsonl").read_text().splitlines()]
    assert [r["value"] for r in recs] == [60.0, 10.0, 5.0] and recs[1]["rows"] == {"a": 1.0, "b": 2.0}
    assert recs[2]["score_mean_est_h_median_m"] == pytest.approx(1.525) and recs[0]["flights"] == 8
    assert ablation.main(["shared", "--scenario", "mismatch", "--rows", str(tmp_path / "none.yaml"),
                          "--vary", "estimator.gnss_offset_max_s=5", "--seeds", "0-1"]) == 2
    assert "tuning seeds are 1000" in capsys.readouterr().err


def test_effects_pair_each_effect_switched_off_with_all_on(tmp_path, monkeypatch):
    """``ablation effects``: every variant flies every row on the same flights with the shared
    settings; an effect's cost is the paired difference to all on (the flight effect cancels)."""
    rows = [Row("a", "fixed-beta", (("estimator.beta_fixed", 0.5),)), Row("b", "map-beta")]
    cost = {("a", "gnss.nlos"): 0.4, ("b", "gnss.nlos"): 0.3, ("a", "gnss.heavy_tail_dof"): -0.02}
    flown = []

    def fake_fly(cands, scenario, profiles, seeds, workers, mission, overrides):
        o = dict(overrides)
        assert scenario == "mismatch" and o.pop("estimator.gnss_offset_max_s") == 5.0
        flown.append(tuple(o))
        return [_result(p, s, c.label, c.method,
                        1.5 + np.sin(7 * p + s) - sum(cost.get((c.label, k), 0.0) for k in o))
                for c in cands for p in profiles for s in seeds]

    monkeypatch.setattr(ablation, "_fly", fake_fly)
    table = ablation.effects(rows, [0, 1], [0, 1, 2], 1, tmp_path / "effects",
                             shared=[("estimator.gnss_offset_max_s", 5.0)])
    assert flown == [(), *((k,) for k, _ in (dict(e[2]).popitem() for e in ablation.EFFECTS))]
    eff = table["effects"]
    assert eff["all on"]["rows"]["a"]["minus_all_on"] == [0.0, 0.0, 0.0]
    for row, gap in (("a", -0.4), ("b", -0.3)):
        assert eff["no reflections"]["rows"][row]["minus_all_on"] == pytest.approx([gap] * 3, abs=1e-9)
    assert eff["Gaussian noise"]["rows"]["a"]["minus_all_on"] == pytest.approx([0.02] * 3, abs=1e-9)
    all_on_b = eff["all on"]["rows"]["b"]["mean_m"]
    assert eff["canyon bias 3 s"]["rows"]["b"]["mean_m"] == pytest.approx(all_on_b)
    assert json.loads((tmp_path / "effects" / "effects.json").read_text())["shared"] == {
        "estimator.gnss_offset_max_s": 5.0}
    text = ablation.report(tmp_path)
    assert "## What each unmodelled GNSS effect costs" in text
    assert "| no reflections: a blocked satellite is lost, never tracked by its reflection | " in text
    assert "(-0.400 [-0.400, -0.400])" in text and "every row with `estimator.gnss_offset_max_s=5.0`" in text


def test_severity_flies_every_level_with_the_shared_settings(tmp_path, monkeypatch):
    rows = [Row("fixed-beta-best", "fixed-beta"), Row("map-beta", "map-beta")]

    def fake_fly(cands, scenario, profiles, seeds, workers, mission, overrides):
        o = dict(overrides)
        assert scenario == "realistic" and o["estimator.gnss_offset_max_s"] == 5.0
        s = o.get("gnss.nlos_delay_mean_m", 0.0)  # the severity level
        k = {"map-beta": 0.9, "fixed-beta-best": 1.0}
        return [_result(p, q, c.label, c.method, (1.0 + s) * k[c.label] + 0.1 * p)
                for c in cands for p in profiles for q in seeds]

    monkeypatch.setattr(ablation, "_fly", fake_fly)
    table = ablation.severity(rows, [0.0, 1.0], [0, 1], [0, 1], 1, tmp_path,
                              shared=[("estimator.gnss_offset_max_s", 5.0)])
    assert table["shared"] == {"estimator.gnss_offset_max_s": 5.0}
    assert table["levels"]["0.0"]["fixed-beta-best"]["mean_m"] == pytest.approx(1.05)
    # ratio of means, not mean of ratios: (0.9 + 0.95) / (1.0 + 1.1) at s = 0, the flight effect kept
    assert table["levels"]["0.0"]["map-beta"]["ratio"] == pytest.approx((0.9 + 1.0) / (1.0 + 1.1))
    assert table["levels"]["1.0"]["map-beta"]["ratio"] == pytest.approx((1.8 + 1.9) / (2.0 + 2.1))


@pytest.mark.parametrize("extra, message", [
    (["--set", "estimator"], "--set: expected SECTION.FIELD=VALUE"),
    (["--set", "estimator.no_such_field=1"], "no_such_field"),
    (["--methods", "nope"], "nope"),
    (["--profiles", "0-99"], "--profiles"),
])
def test_effects_and_severity_bad_arguments_are_one_line_errors(tmp_path, extra, message, capsys):
    rows = tmp_path / "rows.yaml"
    rows.write_text("rows:\n  fixed-beta-best: {method: fixed-beta}\n")
    for command in ("effects", "severity"):
        out = tmp_path / command
        assert ablation.main([command, "--rows", str(rows), "--out", str(out), *extra]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1 and not out.exists()  # nothing flown or written


def test_pair_compares_rows_of_two_campaigns_by_flight(tmp_path, capsys):
    """``ablation pair``: rows of one campaign against a reference row of another, matched by
    (profile, seed); a known difference comes back exactly (every pair differs by the same 0.1 m)."""
    def write(d, rows):
        d.mkdir()
        per_flight = {row: {f"{p}/{s}": {"est_h_median_m": v + 0.01 * p + 0.001 * s}
                            for p in (0, 1) for s in (0, 1, 2)} for row, v in rows.items()}
        (d / "results.json").write_text(json.dumps({"flights": {"per_flight": per_flight}}), encoding="utf-8")

    write(tmp_path / "new", {"second-order": 0.6})
    write(tmp_path / "base", {"fixed-beta-0.5": 0.7, "naive": 0.5})
    table = ablation.pair(tmp_path / "new", tmp_path / "base", ["fixed-beta-0.5", "naive"])
    assert table["rows"]["second-order"]["fixed-beta-0.5"] == pytest.approx([-0.1, -0.1, -0.1])
    assert table["rows"]["second-order"]["naive"] == pytest.approx([0.1, 0.1, 0.1])
    assert json.loads((tmp_path / "new" / "paired.json").read_text())["rows"] == table["rows"]
    assert "second-order: − fixed-beta-0.5 -0.100" in capsys.readouterr().out
    # the report's table of it (every interval excludes 0 here: starred)
    lines = ablation._paired_section(tmp_path / "new")
    assert "| `second-order` | -0.100 [-0.100, -0.100] * | +0.100 [+0.100, +0.100] * |" in lines
    assert ablation.main(["pair", str(tmp_path / "new"), str(tmp_path / "base"), "--reference", "nope"]) == 2
    assert "ablation: error: --reference: nope not in" in capsys.readouterr().err
