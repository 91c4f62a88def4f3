"""Inverse dynamics (Eq 3.7-3.10): forward(inverse(x)) == x, internal-force bases, errors."""

from __future__ import annotations

import numpy as np
import pytest

from multiarm_pin.dynamics import (
    SystemBlocks,
    internal_force_basis,
    inverse_dynamics,
    solve,
)
from multiarm_pin.exceptions import DynamicsError, InputError

from .synthetic import random_system


def random_graspable(rng, n=None):
    """Random system in which every arm can follow the object (nv_i >= N_i) and Σ N_i > 6."""
    n = n or int(rng.integers(2, 5))
    nv = rng.choice([6, 7], n).tolist()
    N = [int(rng.integers(2, 7)) for _ in range(n)]
    if sum(N) <= 6:
        N[0] = 6
    blocks, _, _ = random_system(rng, nv, N)
    return blocks


def in_range(W: np.ndarray, x: np.ndarray) -> bool:
    y, *_ = np.linalg.lstsq(W, x, rcond=None)
    return np.linalg.norm(W @ y - x) <= 1e-9 * max(np.linalg.norm(x), 1e-12)


@pytest.mark.parametrize("seed", range(12))
@pytest.mark.parametrize("method", ["svd", "echelon"])
def test_forward_of_inverse_reproduces_the_motion(seed, method):
    rng = np.random.default_rng(seed)
    blocks = random_graspable(rng)
    a_o = rng.standard_normal(6)
    qdd_des = rng.standard_normal((blocks.n, blocks.nv_max))
    basis = internal_force_basis(blocks.stacked_W_o(), method)
    mu_I = rng.standard_normal(basis.A_o.shape[1])
    res = inverse_dynamics(blocks, a_o, qdd_des, mu_I, basis)
    assert not res.tau[~blocks.dof_mask].any()
    driven = blocks.with_torques(res.tau)
    for solver in ("object_first", "dense_kkt", "singular"):
        sol = solve(driven, solver)
        np.testing.assert_allclose(sol.a_o, a_o, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(sol.qdd, res.qdd, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(sol.mu, res.mu, rtol=1e-9, atol=1e-9)
    # the joint accelerations are the closest to the desired ones: the difference lies in
    # the range of W_i (it has no component along the arm's free motions)
    for i in range(blocks.n):
        k, m = blocks.nv[i], blocks.N[i]
        assert in_range(blocks.W[i, :k, :m], res.qdd[i, :k] - qdd_des[i, :k])


def test_internal_forces_do_not_move_the_object():
    rng = np.random.default_rng(20)
    blocks = random_graspable(rng, n=3)
    a_o = rng.standard_normal(6)
    base = inverse_dynamics(blocks, a_o)
    basis = base.basis
    mu_I = rng.standard_normal(basis.A_o.shape[1])
    loaded = inverse_dynamics(blocks, a_o, mu_I=mu_I)
    dmu = blocks.flatten_mu(loaded.mu - base.mu)
    np.testing.assert_allclose(dmu, basis.A_o @ mu_I, atol=1e-12)
    np.testing.assert_allclose(blocks.stacked_W_o() @ dmu, 0.0, atol=1e-10)
    np.testing.assert_allclose(loaded.qdd, base.qdd, atol=1e-12)
    # the minimum-norm multipliers are orthogonal to every internal force
    np.testing.assert_allclose(basis.A_o.T @ blocks.flatten_mu(base.mu), 0.0, atol=1e-10)


@pytest.mark.parametrize("seed", range(5))
def test_bases_svd_and_echelon(seed):
    rng = np.random.default_rng(seed)
    W = rng.standard_normal((6, 9))
    W[:, 3] = W[:, 1] - 2 * W[:, 0]  # a dependent column: not a pivot of the echelon form
    svd = internal_force_basis(W, "svd")
    ech = internal_force_basis(W, "echelon")
    assert svd.rank == ech.rank == 6
    assert svd.A_o.shape == ech.A_o.shape == (9, 3)
    np.testing.assert_allclose(W @ svd.A_o, 0.0, atol=1e-12)
    np.testing.assert_allclose(W @ ech.A_o, 0.0, atol=1e-12)
    np.testing.assert_allclose(svd.A_o.T @ svd.A_o, np.eye(3), atol=1e-12)
    assert ech.free.tolist() == [3, 7, 8]  # pivots of the row echelon form: 0,1,2,4,5,6
    np.testing.assert_array_equal(ech.A_o[ech.free], np.eye(3))
    np.testing.assert_allclose(svd.W_o_pinv, np.linalg.pinv(W), atol=1e-12)
    # thesis Sec 3.7.3: with the echelon basis, μ_I,j = μ_free(j) - (W_o⁺ f)_free(j)
    w = rng.standard_normal(6)
    mu = np.linalg.pinv(W) @ w + svd.A_o @ rng.standard_normal(3)
    mu_I = ech.coordinates(mu)
    np.testing.assert_allclose(mu_I, (mu - np.linalg.pinv(W) @ w)[ech.free], atol=1e-12)
    np.testing.assert_allclose(ech.W_o_pinv @ w + ech.A_o @ mu_I, mu, atol=1e-12)


def test_rank_deficient_grasp_and_unfollowable_arm_raise():
    rng = np.random.default_rng(30)
    # Only 4 multipliers on the object: W_o has rank 4, most object accelerations unreachable.
    blocks, _, _ = random_system(rng, [6, 6], [2, 2])
    with pytest.raises(DynamicsError, match="rank 4 < 6"):
        inverse_dynamics(blocks, rng.standard_normal(6))
    # Arm 1 has 3 joints for 5 constraints: it cannot follow a general object motion.
    blocks, _, _ = random_system(rng, [7, 3], [4, 5])
    with pytest.raises(DynamicsError, match=r"arm\(s\) \[1\] cannot follow"):
        inverse_dynamics(blocks, rng.standard_normal(6))


def test_bad_arguments():
    blocks = random_graspable(np.random.default_rng(40), n=2)
    with pytest.raises(InputError, match="a_o"):
        inverse_dynamics(blocks, np.zeros(5))
    with pytest.raises(InputError, match="mu_I"):
        inverse_dynamics(blocks, np.zeros(6), mu_I=np.zeros(99))
    with pytest.raises(InputError, match="known: svd, echelon"):
        inverse_dynamics(blocks, np.zeros(6), basis="qr")
    other = internal_force_basis(np.random.default_rng(0).standard_normal((6, 20)))
    with pytest.raises(InputError, match="built for 20 multipliers"):
        inverse_dynamics(blocks, np.zeros(6), basis=other)
    with pytest.raises(InputError, match="qdd_desired"):
        inverse_dynamics(blocks, np.zeros(6), qdd_desired=np.zeros(3))
    with pytest.raises(InputError, match="NaN"):
        inverse_dynamics(blocks, np.array([0, 0, 0, 0, 0, np.nan]))


def test_single_arm_weld_closed_form():
    """One arm welded (W_o = I, W = -I): τ = M q̈ + nle-terms with μ = M_o a_o - h_o."""
    rng = np.random.default_rng(50)
    M = np.diag(rng.uniform(1, 2, 6))
    h = rng.standard_normal(6)
    M_o = np.diag([2.0, 2.0, 2.0, 0.1, 0.2, 0.3])
    h_o = rng.standard_normal(6)
    blocks = SystemBlocks.from_lists([M], [h], [-np.eye(6)], [np.eye(6)], [np.zeros(6)],
                                     M_o, h_o)
    a_o = rng.standard_normal(6)
    res = inverse_dynamics(blocks, a_o)
    mu = M_o @ a_o - h_o
    np.testing.assert_allclose(res.mu[0], mu, atol=1e-12)
    np.testing.assert_allclose(res.qdd[0], a_o, atol=1e-12)  # constraint: a_o - q̈ = 0
    np.testing.assert_allclose(res.tau[0], M @ a_o - h + mu, atol=1e-12)
