"""Warm-started force QP (multiarm_pin.dynamics.force_qp) against a cold solve and an
independent one.

The independent solve enumerates every active set of the (small) problems and keeps the one
whose equality-constrained solution satisfies the KKT conditions: the QP is strictly convex,
so that solution is the unique minimiser, found without NNLS, SVD or the active-set
iteration under test.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from multiarm_pin.dynamics.force_distribution import min_norm_forces
from multiarm_pin.dynamics.force_qp import (
    QP_FAILED,
    QP_OK,
    WarmForceDistribution,
    least_norm_forces,
)
from multiarm_pin.exceptions import DynamicsError

TOL = 1e-9


def random_problem(rng, n_arms, feasible=True):
    """Padded (n, 6, m) W_o with random N_i <= m, a unilateral mask, margin and wrench.

    Feasible by construction: the wrench is made by multipliers that keep every unilateral
    one at least 1 N above the margin.
    """
    m = 5
    N = rng.integers(3, m + 1, size=n_arms)
    W = np.zeros((n_arms, 6, m))
    U = np.zeros((n_arms, m), dtype=bool)
    for i in range(n_arms):
        W[i, :, :N[i]] = rng.normal(size=(6, N[i]))
        U[i, :N[i]] = rng.random(N[i]) < 0.7
    margin = float(rng.uniform(0.0, 2.0))
    push = margin + 1.0 + 5.0 * rng.random((n_arms, m))
    mu_star = np.where(U, push, rng.normal(size=(n_arms, m)))
    mu_star[np.arange(m)[None, :] >= N[:, None]] = 0.0
    w = np.einsum("nij,nj->i", W, mu_star)
    if not feasible:
        w = w + 1e3 * rng.normal(size=6)
    return W, N, U, margin, w


def flat(W, N):
    mask = np.arange(W.shape[2])[None, :] < N[:, None]
    return W.transpose(0, 2, 1)[mask].T, mask


def enumerate_kkt(Wf, w, U, margin):
    """The minimiser by trying every active set (independent of both solvers)."""
    K = Wf.shape[1]
    idx = np.flatnonzero(U)
    for r in range(len(idx) + 1):
        for act in itertools.combinations(idx, r):
            act = np.array(act, dtype=int)
            free = np.setdiff1d(np.arange(K), act)
            rhs = w - Wf[:, act] @ np.full(len(act), margin)
            Wfree = Wf[:, free]
            if np.linalg.matrix_rank(Wfree) < 6:
                continue
            lam = np.linalg.solve(Wfree @ Wfree.T, rhs)
            mu = np.full(K, margin)
            mu[free] = Wfree.T @ lam
            nu = margin - Wf[:, act].T @ lam
            scale = max(np.abs(mu).max(), margin, 1.0)
            if np.all(mu[idx] >= margin - 1e-10 * scale) and np.all(nu >= -1e-10 * scale):
                return mu
    raise AssertionError("no active set satisfies the KKT conditions")


def assert_kkt(Wf, w, U, margin, mu):
    scale = max(np.abs(mu).max(), margin, np.abs(w).max())
    assert np.abs(Wf @ mu - w).max() <= TOL * scale
    assert mu[U].min(initial=np.inf) >= margin - TOL * scale
    # stationarity: μ = W_oᵀ λ + ν with ν >= 0 on the multipliers at the margin, 0 elsewhere
    at = U & (mu <= margin + 1e-9 * scale)
    free = ~at
    lam = np.linalg.lstsq(Wf[:, free].T, mu[free], rcond=None)[0]
    assert np.abs(Wf[:, free].T @ lam - mu[free]).max() <= TOL * scale
    assert (mu[at] - Wf[:, at].T @ lam).min(initial=0.0) >= -TOL * scale


@pytest.mark.parametrize("seed", range(12))
def test_warm_qp_equals_cold_and_independent_solves(seed):
    rng = np.random.default_rng(seed)
    W, N, U, margin, w = random_problem(rng, 2 + seed % 2)
    Wf, mask = flat(W, N)
    Uf = U[mask]
    cold = min_norm_forces(Wf, w, Uf, margin)
    brute = enumerate_kkt(Wf, w, Uf, margin)
    dist = WarmForceDistribution(N, U)
    mu = dist.solve(W, w, margin)
    assert dist.cold_solves == 0
    scale = max(np.abs(cold).max(), 1.0)
    assert np.abs(mu[mask] - cold).max() <= TOL * scale
    assert np.abs(mu[mask] - brute).max() <= TOL * scale
    assert np.all(mu[~mask] == 0.0)
    assert_kkt(Wf, w, Uf, margin, mu[mask])


def test_the_comparison_is_not_vacuous():
    """Some of the problems above have multipliers at the margin, some none."""
    counts = []
    for seed in range(12):
        rng = np.random.default_rng(seed)
        W, N, U, margin, w = random_problem(rng, 2 + seed % 2)
        dist = WarmForceDistribution(N, U)
        dist.solve(W, w, margin)
        counts.append(int(dist.active.sum()))
    assert max(counts) >= 2 and min(counts) == 0


def test_warm_start_follows_a_moving_wrench_exactly_and_in_fewer_iterations():
    rng = np.random.default_rng(7)
    W, N, U, margin, w0 = random_problem(rng, 3)
    Wf, mask = flat(W, N)
    direction = rng.normal(size=6)
    warm = WarmForceDistribution(N, U)
    warm_iters, cold_iters, changes = 0, 0, 0
    previous = None
    for step in range(40):
        w = w0 + 0.05 * step * direction
        mu = warm.solve(W, w, margin)
        warm_iters += warm.iterations
        cold = WarmForceDistribution(N, U)  # from an empty active set
        mu_cold = cold.solve(W, w, margin)
        cold_iters += cold.iterations
        ref = min_norm_forces(Wf, w, U[mask], margin)
        scale = max(np.abs(ref).max(), 1.0)
        assert np.abs(mu[mask] - ref).max() <= TOL * scale
        assert np.abs(mu_cold[mask] - ref).max() <= TOL * scale
        if previous is not None and not np.array_equal(previous, warm.active):
            changes += 1
        previous = warm.active.copy()
    assert warm.cold_solves == 0
    assert changes >= 1  # the active set did change along the way
    assert warm_iters < cold_iters


def test_infeasible_margin_falls_back_to_the_cold_solve_and_its_error():
    rng = np.random.default_rng(3)
    W, N, U, margin, w = random_problem(rng, 2)
    U[:] = np.arange(W.shape[2])[None, :] < N[:, None]  # all unilateral
    dist = WarmForceDistribution(N, U)
    Wf, mask = flat(W, N)
    w = -Wf @ np.full(Wf.shape[1], 100.0)  # made by pulls of 100 N: no push reaches 1 N
    assert np.linalg.matrix_rank(Wf) == 6  # infeasibility is the LP's verdict (cold solve)
    with pytest.raises(DynamicsError):
        min_norm_forces(Wf, w, U[mask], 1.0)
    with pytest.raises(DynamicsError):
        dist.solve(W, w, 1.0)
    assert dist.cold_solves == 1


def test_kernel_reports_a_degenerate_free_set():
    """W_o of rank 3 (< 6): W_F W_Fᵀ is singular, the kernel refuses instead of guessing."""
    W = np.zeros((1, 6, 4))
    W[0, :3, :3] = np.eye(3)
    N = np.array([3])
    U = np.zeros((1, 4), dtype=bool)
    active = np.zeros((1, 4), dtype=np.uint8)
    mu = np.empty((1, 4))
    status, _ = least_norm_forces(W, N, U, np.ones(6), 0.0, active, mu, 10)
    assert status == QP_FAILED
    W[0, :, :3] = np.random.default_rng(0).normal(size=(6, 3))
    W[0, :, 3] = 0.0
    full = np.concatenate([W, np.random.default_rng(1).normal(size=(1, 6, 4))], axis=0)
    full[1, :, 3] = 0.0
    status, _ = least_norm_forces(full, np.array([3, 3]), np.zeros((2, 4), dtype=bool),
                                  np.ones(6), 0.0, np.zeros((2, 4), dtype=np.uint8),
                                  np.empty((2, 4)), 10)
    assert status == QP_OK
