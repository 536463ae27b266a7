"""The belief's within-epoch reference (``companion.tight.snapshot``): the leave-one-out residuals equal
the residuals against the solution without that satellite, to 1e-9; a reflected satellite shows its whole
delay; out-of-sequence epochs with it equal in order."""

from __future__ import annotations

import numpy as np
import pytest

from companion.tight import TightConfig, snapshot
from tests.test_tight import _feed, _synthetic_epochs


def _geometry(rng: np.random.Generator, m: int, systems: int) -> np.ndarray:
    """G: unit lines of sight (position columns, −u) and one clock column per system."""
    u = rng.normal(size=(m, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    slot = np.arange(m) % systems
    return np.column_stack([-u, *(slot == j for j in range(systems))]).astype(float)


@pytest.mark.parametrize(("sigma_m", "clocks_free"), [(np.inf, True), (10.0, True), (3.0, False),
                                                      (np.inf, False), (0.0, False)])
def test_leave_one_out_is_the_residual_against_the_others_solution(sigma_m, clocks_free):
    rng = np.random.default_rng(11)
    m, k = 12, 2
    G = _geometry(rng, m, k)
    y = rng.normal(0.0, 3.0, m)
    r = rng.uniform(1.0, 9.0, m)
    P = np.diag(rng.uniform(1.0, 9.0, 3 + k))
    lam = snapshot.position_prior(P, sigma_m, clocks_free)
    y_loo, s_loo = snapshot.leave_one_out(G, y, r, np.zeros(m), lam)
    for i in range(m):  # the solution of the others, solved directly
        o = np.arange(m) != i
        A = G[o].T @ (G[o] / r[o, None]) + lam
        dx = np.linalg.solve(A, G[o].T @ (y[o] / r[o]))
        assert y_loo[i] == pytest.approx(y[i] - G[i] @ dx, abs=1e-9)
        assert s_loo[i] == pytest.approx(G[i] @ np.linalg.solve(A, G[i]), abs=1e-9)


def test_position_prior_known_answers():
    P = np.diag([4.0, 9.0, 16.0, 25.0])
    np.testing.assert_allclose(snapshot.position_prior(P, np.inf, True), 0.0)
    np.testing.assert_allclose(snapshot.position_prior(P, 0.0, True), np.diag([1 / 4, 1 / 9, 1 / 16, 0.0]))
    np.testing.assert_allclose(snapshot.position_prior(P, 3.0, False),
                               np.diag([1 / 13, 1 / 18, 1 / 25, 1 / 25]))
    np.testing.assert_allclose(snapshot.position_prior(P, np.inf, False), np.diag([0.0, 0.0, 0.0, 1 / 25]))


def test_a_reflected_satellite_shows_its_whole_delay_and_a_lone_one_keeps_its_innovation():
    """Noise-free clean satellites and one 30 m late: against the others' solution (free position and
    clock) it is exactly 30 m late, whatever the prediction's error (shared: it leaves no trace); a
    satellite alone on its system's clock has no others to be judged by: its pre-fit innovation stays."""
    rng = np.random.default_rng(2)
    m = 10
    G = _geometry(rng, m, 1)
    G = np.column_stack([G, np.r_[np.zeros(m - 1), 1.0]])  # the last satellite alone on a second clock
    G[m - 1, 3] = 0.0
    err = np.zeros(m)
    err[0] = 30.0
    shared = G[:, 0:4] @ np.array([7.0, -4.0, 2.0, 12.0])  # the prediction's position and clock error
    y = err + shared
    r = np.full(m, 4.0)
    s0 = np.arange(m, dtype=float)
    lam = snapshot.position_prior(np.eye(5), np.inf, True)
    y_loo, s_loo = snapshot.leave_one_out(G, y, r, s0, lam, iterations=3, nu=2.0, early_factor=0.5)
    assert y_loo[0] == pytest.approx(30.0, abs=1e-9)
    assert y_loo[m - 1] == y[m - 1] and s_loo[m - 1] == s0[m - 1]
    assert np.all(np.abs(y_loo[1 : m - 1]) < np.abs(y[1 : m - 1]))  # the shared error is gone from the clean


def test_out_of_sequence_epochs_with_the_snapshot_equal_in_order():
    cfg = TightConfig.for_ground_vehicle(belief_innovation="snapshot", belief_snapshot_sigma_m=1.0,
                                         belief_snapshot_clocks_free=False)
    rng = np.random.default_rng(3)
    epochs, _ = _synthetic_epochs(rng, cfg, 30, bias={0: (30.0, 10)})
    t_us = [1_000_000 + 200_000 * k for k in range(len(epochs))]
    a = _feed(cfg, "second-order", epochs, t_us, list(range(len(epochs))))
    order = list(range(len(epochs)))
    for k in range(2, len(order) - 3, 5):
        order[k], order[k + 3] = order[k + 3], order[k]
    b = _feed(cfg, "second-order", epochs, t_us, order)
    assert b.counts["gnss_out_of_order"] > 0
    for ea, eb in zip(a.entries, b.entries, strict=True):
        np.testing.assert_allclose(eb.x, ea.x, rtol=0, atol=1e-9)
        np.testing.assert_allclose(eb.P, ea.P, rtol=0, atol=1e-9)


@pytest.mark.parametrize("bad", [dict(belief_snapshot_sigma_m=-1.0), dict(belief_snapshot_iterations=-1),
                                 dict(belief_snapshot_blend=1.5), dict(belief_innovation="epoch")])
def test_bad_snapshot_settings_are_refused(bad):
    with pytest.raises(ValueError, match="belief_"):
        TightConfig(**bad).validate()
