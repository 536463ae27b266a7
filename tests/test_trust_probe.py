"""The trust probe's per-flight statistics on known records, and its command-line errors."""

import dataclasses
import math

import numpy as np
import pytest

from companion.estimator.belief import InnovationTerms, s_of_beta
from companion.estimator.config import EstimatorConfig
from gcs_tools.evaluate.trust_probe import main, probe_stats


def test_stats_of_records_consistent_with_a_known_trust():
    """Innovations exactly consistent with β₀ = 0.3 (y_i² = S_i(β₀)) under the Gaussian loss, the
    rule holding β₀, a bias estimate of 0.6 m north: each statistic has a closed form."""
    cfg = dataclasses.replace(EstimatorConfig(), loss="gaussian")
    records = []
    for k in range(20):
        t = InnovationTerms((0.0, 0.0, 0.0), (0.01 + 0.001 * k,) * 3, 0.03, (0.0064,) * 3, (0.01,) * 3)
        S, _ = s_of_beta(0.3, t, cfg)
        records.append((t._replace(y=tuple(math.sqrt(s) for s in S)), 0.3, (0.6, 0.0, 0.1)))
    s = probe_stats(records, cfg)
    assert s["fixes"] == 20 and s["beta_mean"] == pytest.approx(0.3)
    assert s["nis_per_axis"] == pytest.approx(1.0)
    assert s["beta_hindsight"] == pytest.approx(0.3)
    ys = np.array([r[0].y[:2] for r in records])
    assert s["innovation_h_rms_m"] == pytest.approx(math.sqrt(np.mean(np.sum(ys**2, axis=1))))
    assert s["bias_h_m"] == pytest.approx(0.6)
    sigma = cfg.sigma_bias_m(0.3)
    assert s["bias_over_sigma"] == pytest.approx(math.sqrt(0.36 / sigma**2 / 2))


def test_unknown_row_is_a_one_line_error(tmp_path, capsys):
    rows = tmp_path / "rows.yaml"
    rows.write_text("rows:\n  a:\n    method: naive\n", encoding="utf-8")
    assert main(["--rows", str(rows), "--row", "b", "--profiles", "1"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("trust_probe: error: --row 'b'") and err.count("\n") == 1
