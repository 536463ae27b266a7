"""The real-flight campaign (``python -m gcs_tools.evaluate.real``) on synthetic ANSFL flights:
pairing, the raw fixes' rows, the statistics' exact relations, the report and bad arguments."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from ansfl_helpers import write_flight

from gcs_tools.evaluate import real


@pytest.fixture(scope="module")
def flights(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    root = tmp_path_factory.mktemp("ansfl")
    write_flight(root / "a", seconds=25.0, offset_s=0.2, seed=1)
    write_flight(root / "b", seconds=25.0, offset_s=0.4, heading_error_deg=3.0, seed=2)
    series = root / "series.csv"
    t = np.arange(0.0, 200.0, 0.2)
    err = np.column_stack((8 * np.sin(t / 7), 5 * np.cos(t / 11), 3 * np.sin(t / 5)))
    rows = "\n".join(f"{a:.3f},{e[0]:.4f},{e[1]:.4f},{e[2]:.4f},6.0,9.0" for a, e in zip(t, err, strict=True))
    series.write_text("t_s,err_n_m,err_e_m,err_d_m,h_acc_m,v_acc_m\n" + rows + "\n")
    return [root / "a", root / "b", series]


def test_campaign_tables_pairing_and_goals(flights: list[Path]) -> None:
    a, b, series = flights
    res = real.run([a, b], ["model", str(series)], ["reported", "none"], ["naive", "second-order"], [0, 1])
    assert len(res["conditions"]) == 4 and res["campaign"]["runs"] == 2 * 2 * 2 * 2 * 2
    runs = res["runs"]
    for cond in res["conditions"]:
        mine = [r for r in runs if r["errors"] == cond["errors"] and r["accuracy"] == cond["accuracy"]]
        t = cond["table"]
        assert set(t) == {"naive", "second-order", *real.RAW} and all(t[k]["runs"] == 4 for k in t)
        for row, e in t.items():  # the pooled mean is the mean over runs of the per-run statistic
            per_run = [r["median"] for r in mine if r["row"] == row]
            assert e["median"]["mean"] == pytest.approx(np.mean(per_run))
            lo, hi = e["median"]["ci95"]
            assert lo <= e["median"]["mean"] <= hi
        # the mean of paired differences is the difference of the means (every pair complete)
        diff = t["second-order"]["minus_raw_at_arrival_median"]["mean"]
        assert diff == pytest.approx(t["second-order"]["median"]["mean"] - t[real.RAW[0]]["median"]["mean"])
        assert t["naive"]["vs_naive_median"]["value"] == 0.0
        ratio = t["second-order"]["median"]["mean"] / t["naive"]["median"]["mean"] - 1
        assert t["second-order"]["vs_naive_median"]["value"] == pytest.approx(ratio)
        g = cond["goals"]
        best = g["best_method"]
        below = t[best]["median"]["mean"] < t[real.RAW[0]]["median"]["mean"]
        assert g["best_below_raw_at_arrival"] == below
    # the same seed gives every method the same fixes: the raw rows come once per (flight, seed)
    raw = [r for r in runs if r["row"] == real.RAW[1] and r["errors"] == "model" and r["accuracy"] == "none"]
    assert len(raw) == 4 and len({(r["flight"], r["seed"]) for r in raw}) == 4
    reported = {(r["flight"], r["seed"]): r["median"] for r in runs
                if r["row"] == real.RAW[1] and r["errors"] == "model" and r["accuracy"] == "reported"}
    assert all(reported[(r["flight"], r["seed"])] == r["median"] for r in raw)  # accuracy changes no fix
    text = real.markdown(res)
    assert "## errors: model, accuracy: none" in text and f"series {series.name}" in text
    assert "`raw fixes (at arrival)`" in text


def test_exact_fixes_with_fixed_latency(flights: list[Path]) -> None:
    res = real.run(flights[:1], ["none"], ["reported"], ["naive"], [0], latency_ms=100.0)
    t = res["conditions"][0]["table"]
    assert t[real.RAW[1]]["max"]["mean"] == 0.0 and t[real.RAW[0]]["median"]["mean"] > 0.2  # ~3 m/s × 0.1 s
    assert t["naive"]["median"]["mean"] < 0.1


def test_cli_writes_json_and_report_and_refuses_bad_arguments(flights: list[Path], tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    a, _, _ = flights
    out = tmp_path / "o"
    assert real.main(["--flights", str(a), "--errors", "model", "--accuracy", "eph",
                      "--methods", "second-order", "--seeds", "0", "--out", str(out)]) == 0
    res = json.loads((out / "results.json").read_text())
    assert res["campaign"]["methods"] == ["naive", "second-order"] and (out / "report.md").is_file()
    assert len(res["runs"]) == 4 and {r["row"] for r in res["runs"]} == {"naive", "second-order", *real.RAW}
    capsys.readouterr()
    for bad, words in ((["--flights", "nowhere"], "not an ANSFL flight directory"),
                       (["--corpus", str(tmp_path / "none"), "--flights", "reporting"], "no such directory"),
                       # named by this tool's options (they were replay's: --gnss-errors, ...)
                       (["--flights", str(a), "--errors", "cloudy"], "error: --errors 'cloudy'"),
                       (["--flights", str(a), "--accuracy", "some"], "error: --accuracy 'some'"),
                       (["--flights", str(a), "--rate-hz", "0"], "error: --rate-hz 0.0: expected > 0"),
                       (["--flights", str(a), "--methods", "secnd-order"], "did you mean"),
                       (["--flights", str(a), "--seeds", "x"], "--seeds"),
                       (["--flights", str(a), "--gnss-velocity", "fast"], "--gnss-velocity 'fast'"),
                       (["--flights", str(a), "--gnss-velocity", "-1"], "--gnss-velocity -1"),
                       (["--flights", str(a), "--methods", "map-beta"], "needs a mission's map"),
                       (["--flights", str(a), "--set", "gnss.rate_hz=1"], "only estimator.FIELD"),
                       (["--flights", str(a), "--set", "estimator.sigma_bias_max_m=-1"], "must be"),
                       (["--flights", str(a), "--set", "estimator.no_such_field=1"], "unknown key")):
        assert real.main([*bad, "--out", str(tmp_path / "bad")]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("real: error: ") and words in err and "\n" not in err, err
        assert not (tmp_path / "bad").exists()


def test_an_estimator_override_changes_only_what_it_is_about(flights: list[Path]) -> None:
    """``--set estimator.sigma_gnss_unreported_bias_m=1.2`` changes the fixes without an accuracy only:
    the runs with a reported accuracy are identical to the defaults', those without differ."""
    args = (flights[:1], ["model"], ["reported", "none"], ["naive", "second-order"], [0])
    runs = {}
    for fields in ((), (("sigma_gnss_unreported_bias_m", 1.2),)):
        res = real.run(*args, estimator=fields)
        assert res["campaign"]["estimator"] == dict(fields)
        assert ("`sigma_gnss_unreported_bias_m` = 1.2" in real.markdown(res)) == bool(fields)
        runs[fields] = {(r["accuracy"], r["row"]): r["median"] for r in res["runs"]}
    default, changed = runs.values()
    assert all(changed[k] == default[k] for k in default if k[0] == "reported")
    assert changed[("none", "second-order")] != default[("none", "second-order")]
