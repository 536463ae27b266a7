"""Statistical consistency of ``naive`` on the filter's own linear model (Monte Carlo NEES/NIS)."""

import numpy as np
from scipy import stats

from companion.estimator import model
from companion.estimator.config import EstimatorConfig
from companion.estimator.engine import FusionEngine
from tests.estimator_streams import consistent_stream

CFG = EstimatorConfig()
RUNS = 30
DURATION_S = 10.0


def test_naive_nees_and_nis_inside_95_percent_chi2_bounds():
    """Per fix time, the average over RUNS independent runs of NEES (12 dof) and NIS (3 dof) must
    lie inside the two-sided 95% bounds χ²(RUNS·n, 0.025/0.975) / RUNS in at least 90% of the
    fix times (95% expected), and the grand averages within ±6% of 9 and 3."""
    rng = np.random.default_rng(2024)
    nees, nis = [], []
    for _ in range(RUNS):
        s, x_hat0, _ = consistent_stream(rng, CFG, DURATION_S, beta=CFG.beta_fixed)
        e = FusionEngine(CFG, "naive")
        run_nees, run_nis = [], []
        k0 = 0
        for j, k in enumerate(s.fix_index.tolist()):
            e.push_acc_batch(s.t_us[k0:k + 1], s.a_ned_m_s2[k0:k + 1])
            k0 = k + 1
            e.push_fix(int(s.t_us[k]), s.z_ned_m[j])
            f = e.fusions[-1]
            if j == 0:
                np.testing.assert_allclose(f.x, x_hat0)
                continue
            err = s.x_true[k] - np.array(f.x)
            run_nees.append(float(err @ np.linalg.solve(model.cov_to_matrix(f.P), err)))
            run_nis.append(f.nis)
        nees.append(run_nees)
        nis.append(run_nis)
    for values, dof in ((np.array(nees), model.N_STATE), (np.array(nis), 3)):
        avg = values.mean(axis=0)
        lo, hi = stats.chi2.ppf([0.025, 0.975], RUNS * dof) / RUNS
        inside = np.mean((avg > lo) & (avg < hi))
        assert inside >= 0.90, (dof, inside, lo, hi)
        assert abs(values.mean() / dof - 1.0) < 0.06, (dof, values.mean())
