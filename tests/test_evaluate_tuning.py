"""Parameter overrides and tuning sweeps: parsing, application to every flight's config, table."""

import pytest

from companion.errors import UserError
from companion.mission import ConfigError
from companion.wiring import mission_estimator_config
from gcs_tools.cli import main
from gcs_tools.evaluate import campaign, tune, tuning


def test_override_parsing_reads_yaml_scalars_and_rejects_bad_keys():
    assert tuning.parse_override("estimator.r_inflation_max=100") == ("estimator.r_inflation_max", 100)
    assert tuning.parse_override("estimator.eta = 0.3") == ("estimator.eta", 0.3)
    assert tuning.parse_override("gnss.report_accuracy=false") == ("gnss.report_accuracy", False)
    for bad in ("estimator.eta", "eta=0.3", "planner.w_tra=1", "estimator.eta=[1, 2]", "estimator.=1"):
        with pytest.raises(UserError):
            tuning.parse_override(bad)


def test_overrides_reach_the_flight_config_and_leave_the_mission_untouched():
    plain = tuning.load("test")
    o = (("estimator.sigma_acc_m_s2", 0.02), ("estimator.eta", 0.3), ("estimator.eta", 0.4))
    tuned = tuning.load("test", o)
    cfg, base = mission_estimator_config(tuned), mission_estimator_config(plain)
    assert (cfg.sigma_acc_m_s2, cfg.eta) == (0.02, 0.4)  # the later override wins
    assert cfg.r_inflation_max == base.r_inflation_max
    assert plain.section("estimator") == tuning.load("test").section("estimator")
    assert campaign.mission("test", o).section("estimator")["eta"] == 0.4
    jobs = campaign.grid("test", [0], ["naive", "second-order"], [0], overrides=o)
    assert len(jobs) == 2 and all(j.overrides == o for j in jobs)
    with pytest.raises(ConfigError, match="no_such_field"):
        tuning.check(tuning.load("test", (("estimator.no_such_field", 1),)))
    with pytest.raises(ConfigError, match="eta"):
        tuning.check(tuning.load("test", (("estimator.eta", -1.0),)))


def test_sweep_points_are_the_cartesian_product_then_the_fixed_overrides():
    pts = tune.points(["estimator.eta=0.1,0.2", "estimator.alpha_fast=0.3,0.4,0.5"], ["estimator.theta0=1"])
    assert len(pts) == 6
    assert pts[0] == (("estimator.eta", 0.1), ("estimator.alpha_fast", 0.3), ("estimator.theta0", 1))
    assert pts[-1][:2] == (("estimator.eta", 0.2), ("estimator.alpha_fast", 0.5))
    assert tune.points([], []) == [()]


def test_sweep_table_on_known_records():
    methods = {"naive": {"estimation_error_m": 2.0, "tracking_error_m": 1.0},
               "second-order": {"estimation_error_m": 0.5, "tracking_error_m": 0.8}}
    rec = {"estimator_section": {"sigma_acc_m_s2": 0.02}, "profiles": [0, 1, 2, 3], "seeds": [1000, 1001],
           "methods": tune.record_reductions(methods)}
    row = tune.table([rec]).splitlines()[-1]
    assert row == ("| 0 | sigma_acc_m_s2=0.02 | 0–3 | 1000–1001 | 2.000 / 1.000 | 0.500 / 0.800 "
                   "| -75% / -20% |")


def test_evaluate_and_tune_reject_bad_overrides_in_one_line(tmp_path, capsys):
    code = main(["evaluate", "--mission", "test", "--out", str(tmp_path), "--set", "estimator.bogus=1"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.startswith("beliefnav: error:") and "bogus" in err and "\n" not in err
    assert tune.main(["--seeds", "0-1", "--out", str(tmp_path)]) == 2
    assert tune.main(["--vary", "estimator.eta=0.1,-1", "--out", str(tmp_path)]) == 2
    assert "tuning seeds" in capsys.readouterr().err and not (tmp_path / tune.RECORDS).exists()
