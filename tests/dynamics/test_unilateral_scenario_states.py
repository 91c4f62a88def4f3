"""The unilateral solve on the two-gripper scenario's states with a table (7 + 4 rows).

The table's four coplanar rows make the Delassus operator singular (rank 10 of 11), the
situation the benchmark measures. References: active-set enumeration (dense KKT) and
Pinocchio's ADMM contact solver.
"""

from __future__ import annotations

import numpy as np
import pytest

from multiarm_pin.dynamics import solve, solve_unilateral

from .contact_problems import (
    admm_lcp,
    dense_matrices,
    oracle,
    two_gripper_table_pushing_states,
    two_gripper_table_states,
)


@pytest.fixture(scope="module")
def states():
    return two_gripper_table_states(4, seed=12)


def test_states_are_redundant_and_mixed(states):
    """Rank 10 of 11, and the fingertip rows both push and separate, each by a clear margin.

    Only the fingertip rows are classified (their forces are unique); which of the table's
    redundant rows carries the load is not, so the table is not counted.
    """
    pushing = separating = 0
    for b in states:
        assert b.n_constraints == 11 and b.nv.tolist() == [6, 6, 0]
        M, h, A, c = dense_matrices(b)
        sv = np.linalg.svd(A, compute_uv=False)
        assert sv[9] > 1e-3 * sv[0] and sv[10] < 1e-12 * sv[0]  # rank 10 by construction
        sol = solve_unilateral(b, b.constraint_mask)
        v = np.concatenate([sol.a_o] + [sol.qdd[i, : b.nv[i]] for i in range(b.n)])
        mu, phi = b.flatten_mu(sol.mu)[:7], (A @ v - c)[:7]
        push, sep = mu > 1.0, phi > 0.5  # [N], [m/s²]: far from round-off
        assert (push ^ sep).all()  # every fingertip row decided with a margin
        pushing += int(push.sum())
        separating += int(sep.sum())
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
        # 1e-12: met within about 100 of the 10000 iterations on every CPU tried (1e-14 on
        # this singular G is met or not by round-off: see admm_lcp)
        lam, ok, iterations = admm_lcp(G, A @ np.linalg.solve(M, h) - c, tol=1e-12)
        assert ok and iterations < 1000
        v = np.linalg.solve(M, h + A.T @ lam)
        ours = np.concatenate([sol.a_o] + [sol.qdd[i, : b.nv[i]] for i in range(b.n)])
        assert np.abs(v - ours).max() < 1e-10 * np.abs(ours).max()
        mu_flat = b.flatten_mu(sol.mu)
        assert np.abs(mu_flat[:7] - lam[:7]).max() < 1e-9 * np.abs(lam).max()
        Wt = b.W_o[2, :, :4]
        assert np.abs(Wt @ mu_flat[7:] - Wt @ lam[7:]).max() < 1e-9 * np.abs(lam).max()


def test_all_pushing_gives_the_bilateral_motion():
    """Where every row pushes, the motion is the bilateral solve's (singular path).

    The states are built with every multiplier at least 2 N
    (:func:`two_gripper_table_pushing_states`), so the verdict does not rest on round-off.
    Compared: the motion (unique) with the constructed one and the bilateral solve's, the
    fingertip forces (unique: the null space of ``Aᵀ`` lies in the table rows) with the
    constructed ones, and the table's resultant wrench, never which of its redundant rows
    carries the load.
    """
    states = two_gripper_table_pushing_states(6, seed=12)
    assert len(states) == 6
    for b, motion in states:
        sol = solve_unilateral(b, b.constraint_mask)
        ref = solve(b, "auto")
        ours = np.concatenate([sol.a_o] + [sol.qdd[i, : b.nv[i]] for i in range(b.n)])
        bil = np.concatenate([ref.a_o] + [ref.qdd[i, : b.nv[i]] for i in range(b.n)])
        scale = np.abs(motion).max()
        assert np.abs(bil - motion).max() < 1e-9 * scale
        assert np.abs(ours - motion).max() < 1e-9 * scale
        assert np.abs(ours - bil).max() < 1e-11 * scale
        # the constructed forces: fingertips row by row, the table by its resultant wrench
        M, h, A, c = dense_matrices(b)
        lam = np.linalg.lstsq(A.T, M @ motion - h, rcond=None)[0]  # Aᵀλ = M v̇ - h
        mu = b.flatten_mu(sol.mu)
        assert (mu[:7] > 1.0).all()
        assert np.abs(mu[:7] - lam[:7]).max() < 1e-8 * np.abs(lam).max()
        Wt = b.W_o[2, :, :4]
        assert np.abs(Wt @ mu[7:] - Wt @ lam[7:]).max() < 1e-8 * np.abs(lam).max()
        assert (mu[7:] >= 0.0).all()
