"""A short real campaign (test city, real in-process flights): files, pool vs Dask equality."""

import json

import numpy as np
import pytest

pytest.importorskip("simvehicle.harness.fly")

from gcs_tools.cli import main  # noqa: E402
from gcs_tools.evaluate import campaign, plots  # noqa: E402

MAX_DURATION_S = 6.0
JOBS = campaign.grid("test", [0, 1], ["naive", "second-order"], [0], MAX_DURATION_S)


@pytest.fixture(scope="module")
def pool_results():
    return campaign.run(JOBS, workers=2, progress=False)


def assert_identical(a, b):
    assert [r.job for r in a] == [r.job for r in b] == JOBS
    for x, y in zip(a, b, strict=True):
        assert x.summary == y.summary
        for name in ("settling_time_s", "oscillation_rms"):
            np.testing.assert_array_equal(getattr(x, name), getattr(y, name), err_msg=name)
        for name in ("est_error_m", "track_error_m", "t_fig_s", "beta_fig", "p_true_ne_m", "p_ref_ne_m"):
            np.testing.assert_array_equal(getattr(x, name), getattr(y, name), err_msg=name)


@pytest.mark.timeout(120)
def test_pool_results_are_real_flights_in_grid_order(pool_results):
    assert len(pool_results) == len(JOBS)
    for r in pool_results:
        assert r.est_error_m.dtype == np.float32 and r.est_error_m.size > 20 * MAX_DURATION_S * 0.5
        assert np.nanmedian(r.est_error_m) > 0.0
        assert r.p_true_ne_m.shape == (r.t_fig_s.size, 2)
        assert r.summary["duration_s"] <= MAX_DURATION_S + 0.1
    # Methods differ (the estimator really ran per method), the same seed repeats exactly.
    assert not np.array_equal(pool_results[0].est_error_m, pool_results[1].est_error_m)
    assert_identical(pool_results, campaign.run(JOBS, workers=1, progress=False))


@pytest.mark.timeout(120)
def test_dask_local_cluster_gives_identical_results(pool_results):
    from distributed import LocalCluster

    with LocalCluster(n_workers=2, processes=True, threads_per_worker=1, host="127.0.0.1",
                      dashboard_address=None) as cluster:
        dask_results = campaign.run(JOBS, scheduler=cluster.scheduler_address, progress=False)
    assert_identical(pool_results, dask_results)


@pytest.mark.timeout(120)
def test_cli_campaign_writes_every_file(tmp_path, capsys):
    out = tmp_path / "eval"
    code = main(["evaluate", "--mission", "test", "--profiles", "2", "--methods", "naive,second-order",
                 "--seeds", "0-1", "--workers", "2", "--max-duration-s", str(MAX_DURATION_S),
                 "--out", str(out), "--no-progress"])
    assert code == 0
    res = json.loads((out / "results.json").read_text())
    report = (out / "report.md").read_text()
    assert len(plots.FIGURES) == 4
    for name in plots.FIGURES.values():
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert f"]({name})" in report
    assert res["campaign"]["seeds"] == [0, 1] and res["campaign"]["profiles"] == [0, 1]
    assert set(res["methods"]) == {"naive", "second-order"}
    for entry in res["methods"].values():
        for err in ("estimation_error_m", "tracking_error_m"):
            s = entry[err]
            assert 0 < s["median"] <= s["p95"] and s["iqr"] >= 0
            assert s["seed_median_ci95"][0] <= s["seed_median_ci95"][1]
        assert 0.0 <= entry["goal_reached_rate"] <= 1.0
        assert {"belief_settling_time_s", "belief_oscillation_rms", "collisions"} <= set(entry)
    assert res["methods"]["naive"]["estimation_error_m"]["reduction_vs_naive"] == 0.0
    assert "| `second-order` |" in report and "seeds 0–1" in report
    assert "| `naive` |" in capsys.readouterr().out


def test_cli_rejects_bad_arguments_in_one_line(tmp_path, capsys):
    for args in (["--seeds", "5-2"], ["--profiles", "99"], ["--methods", "naive,bogus"]):
        code = main(["evaluate", "--mission", "test", "--out", str(tmp_path), *args])
        err = capsys.readouterr().err.strip()
        assert code == 2 and err.startswith("beliefnav: error: --") and "\n" not in err


def test_old_option_spellings_still_work_with_one_note(tmp_path, capsys):
    code = main(["evaluate", "--mission", "test", "--out", str(tmp_path), "--missions", "99"])
    lines = capsys.readouterr().err.strip().split("\n")
    assert code == 2 and len(lines) == 2
    assert lines[0].endswith("note: --missions is now --profiles")
    assert lines[1].startswith("beliefnav: error: --profiles: the mission has")
