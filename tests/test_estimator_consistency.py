"""Statistical consistency of ``naive`` on the filter's own linear model (Monte Carlo NEES/NIS)."""

import numpy as np
import pytest
from scipy import stats

from companion.estimator import model
from companion.estimator.config import EstimatorConfig
from companion.estimator.engine import FusionEngine
from tests.estimator_streams import consistent_stream

CFG = EstimatorConfig()
RUNS = 60
DURATION_S = 10.0


@pytest.mark.parametrize("yaw_rate_rad_s", [0.0, 0.8])
def test_naive_nees_and_nis_inside_chi2_bounds(yaw_rate_rad_s):
    """Monte Carlo over RUNS independent runs. Per fix time, the run-average of NIS (3 dof) and of
    the NEES of p, v, b (9 dof) lies inside the two-sided 95% bounds χ²(RUNS·n, 0.025/0.975) / RUNS
    in at least 90% of the fix times (95% expected), grand averages within ±6% of 3 and 9. The
    IMU error states (a, d) drift slowly, so their errors barely change within a run: their
    consistency is tested on the whole-state NEES (15 dof) at each run's last fix, one independent
    sample per run, against the two-sided 99% bounds. With a yawing and rolling body the
    accelerometer bias (body axes) moves in NED: the filter stays consistent."""
    cfg = CFG if yaw_rate_rad_s == 0.0 else EstimatorConfig(sigma_acc_bias_rw_m_s2_sqrt_s=0.05,
                                                                 sigma_acc_ned_rw_m_s2_sqrt_s=0.05)
    rng = np.random.default_rng(2024)
    nees, nis, nees_last = [], [], []
    for _ in range(RUNS):
        s, x_hat0, _ = consistent_stream(rng, cfg, DURATION_S, beta=cfg.beta_fixed,
                                         yaw_rate_rad_s=yaw_rate_rad_s)
        e = FusionEngine(cfg, "naive")
        run_nees, run_nis = [], []
        k0 = 0
        for j, k in enumerate(s.fix_index.tolist()):
            rot = None if s.rot is None else s.rot[k0:k + 1]
            e.push_acc_batch(s.t_us[k0:k + 1], s.a_ned_m_s2[k0:k + 1], rot)
            k0 = k + 1
            e.push_fix(int(s.t_us[k]), s.z_ned_m[j])
            f = e.fusions[-1]
            if j == 0:
                np.testing.assert_allclose(f.x, x_hat0)
                continue
            err = s.x_true[k] - np.array(f.x)
            run_nees.append(float(err[:9] @ np.linalg.solve(f.P[:9, :9], err[:9])))
            run_nis.append(f.nis)
        nees_last.append(float(err @ np.linalg.solve(f.P, err)))
        nees.append(run_nees)
        nis.append(run_nis)
    for values, dof in ((np.array(nees), 9), (np.array(nis), 3)):
        avg = values.mean(axis=0)
        lo, hi = stats.chi2.ppf([0.025, 0.975], RUNS * dof) / RUNS
        inside = np.mean((avg > lo) & (avg < hi))
        assert inside >= 0.90, (dof, inside, lo, hi)
        assert abs(values.mean() / dof - 1.0) < 0.06, (dof, values.mean())
    lo, hi = stats.chi2.ppf([0.005, 0.995], RUNS * model.N_STATE) / RUNS
    assert lo < np.mean(nees_last) < hi, (np.mean(nees_last), lo, hi)
