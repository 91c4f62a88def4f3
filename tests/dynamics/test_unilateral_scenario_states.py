"""The unilateral solve on the two-gripper scenario's states with a table (7 + 4 rows).

The table's four coplanar rows make the Delassus operator singular (rank 10 of 11), the
situation the benchmark measures. References: active-set enumeration (dense KKT) and
Pinocchio's ADMM contact solver.
"""

from __future__ import annotations

import numpy as np
import pytest

from multiarm_pin.dynamics import solve, solve_unilateral

from .contact_problems import admm_lcp, dense_matrices, oracle, two_gripper_table_states


@pytest.fixture(scope="module")
def states():
    return two_gripper_table_states(4, seed=12)


def test_states_are_redundant_and_mixed(states):
    pushing = separating = 0
    for b in states:
        assert b.n_constraints == 11 and b.nv.tolist() == [6, 6, 0]
        M, h, A, c = dense_matrices(b)
        sv = np.linalg.svd(A, compute_uv=False)
        assert sv[9] > 1e-3 * sv[0] and sv[10] < 1e-12 * sv[0]  # rank 10 by construction
        sol = solve_unilateral(b, b.constraint_mask)
        pushing += int((sol.mu > 0).sum())
        separating += int(sol.separating.sum())
    assert pushing >= 20 and separating >= 1


def test_matches_enumeration_and_admm(states):
    for b in states:
        uni = b.constraint_mask.copy()
        sol = solve_unilateral(b, uni)
        a_o, qdd, mu, _ = oracle(b, uni)
        scale = max(np.abs(a_o).max(), np.abs(qdd).max())
        assert np.abs(sol.a_o - a_o).max() < 1e-10 * scale
        assert np.abs(sol.qdd - qdd).max() < 1e-10 * scale
        assert sol.complementarity < 1e-10
        # Pinocchio ADMM on the dense G (PSD): same motion; the fingertip forces are unique
        # (the null space of Aᵀ lies in the table rows), the table's only through its wrench
        M, h, A, c = dense_matrices(b)
        G = A @ np.linalg.solve(M, A.T)
        lam, ok, _ = admm_lcp(G, A @ np.linalg.solve(M, h) - c)
        assert ok
        v = np.linalg.solve(M, h + A.T @ lam)
        ours = np.concatenate([sol.a_o] + [sol.qdd[i, : b.nv[i]] for i in range(b.n)])
        assert np.abs(v - ours).max() < 1e-10 * np.abs(ours).max()
        mu_flat = b.flatten_mu(sol.mu)
        assert np.abs(mu_flat[:7] - lam[:7]).max() < 1e-9 * np.abs(lam).max()
        Wt = b.W_o[2, :, :4]
        assert np.abs(Wt @ mu_flat[7:] - Wt @ lam[7:]).max() < 1e-9 * np.abs(lam).max()


def test_all_touching_gives_the_bilateral_motion():
    """Where no contact separates, the motion is the bilateral solve's (singular path).

    Twelve states, of which those with no separating row are compared: a state whose
    smallest fingertip force is near zero can change sides with round-off in its blocks
    (one did when the arms' terms moved from Pinocchio to the compiled pass), so the test
    does not rest on one such state.
    """
    compared = 0
    for b in two_gripper_table_states(12, seed=12):
        sol = solve_unilateral(b, b.constraint_mask)
        if sol.separating.any():
            continue
        compared += 1
        ref = solve(b, "auto")
        scale = max(np.abs(ref.a_o).max(), np.abs(ref.qdd).max())
        assert np.abs(sol.a_o - ref.a_o).max() < 1e-11 * scale
        assert np.abs(sol.qdd - ref.qdd).max() < 1e-11 * scale
    assert compared >= 1
