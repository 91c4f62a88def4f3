"""Dense KKT forward dynamics (thesis Eq 4.9, its ``msolve03``): the straightforward reference.

The whole system is assembled as one symmetric matrix of size ``6 + Σ nv_i + Σ N_i`` in the
unknowns ``[a_o; q̈_1 .. q̈_n; λ]`` with ``λ = -μ`` (the thesis's multiplier sign)::

    [ M_o   0    W_o ] [a_o]   [h_o]
    [ 0     M    W   ] [q̈  ] = [h  ]
    [ W_oᵀ  Wᵀ   0   ] [λ  ]   [c  ]

and solved with one LU factorisation. No least-squares fallback: a singular or badly
conditioned KKT matrix (redundant constraints) raises; use the ``"singular"`` solver then.
"""

from __future__ import annotations

import numpy as np

from multiarm_pin.dynamics.blocks import Solution, SystemBlocks
from multiarm_pin.exceptions import DynamicsError

KKT_COND_LIMIT = 1e13
"""A proven lower bound of the KKT condition number above this raises :class:`DynamicsError`."""


def assemble_kkt(blocks: SystemBlocks) -> tuple[np.ndarray, np.ndarray]:
    """Assemble the dense symmetric KKT system of the blocks, without padding.

    Args:
        blocks: the system blocks.

    Returns:
        ``(K, rhs)``: ``K`` of shape (D, D) and ``rhs`` (D,), ``D = 6 + Σ nv_i + Σ N_i``,
        unknowns ordered ``[a_o (6); q̈ arm-major (Σ nv_i); λ = -μ arm-major (Σ N_i)]``.
    """
    b = blocks
    nv_tot = int(b.nv.sum())
    D = 6 + nv_tot + b.n_constraints
    K = np.zeros((D, D))
    rhs = np.empty(D)
    K[:6, :6] = b.M_o
    rhs[:6] = b.h_o
    jq, jc = 6, 6 + nv_tot
    for i in range(b.n):
        k, m = int(b.nv[i]), int(b.N[i])
        K[jq:jq + k, jq:jq + k] = b.M[i, :k, :k]
        K[jq:jq + k, jc:jc + m] = b.W[i, :k, :m]
        K[jc:jc + m, jq:jq + k] = b.W[i, :k, :m].T
        K[:6, jc:jc + m] = b.W_o[i, :, :m]
        K[jc:jc + m, :6] = b.W_o[i, :, :m].T
        rhs[jq:jq + k] = b.h[i, :k]
        rhs[jc:jc + m] = b.c[i, :m]
        jq += k
        jc += m
    return K, rhs


def unpack_kkt(blocks: SystemBlocks, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split a KKT unknown vector (D,) into ``a_o`` (6,), ``qdd`` (n, nv_max), ``mu`` (n, N_max).

    ``mu = -λ`` (positive = pushing); padded entries are zero.
    """
    b = blocks
    nv_tot = int(b.nv.sum())
    qdd = np.zeros((b.n, b.nv_max))
    qdd[b.dof_mask] = x[6:6 + nv_tot]
    mu = np.zeros((b.n, b.N_max))
    mu[b.constraint_mask] = -x[6 + nv_tot:]
    return x[:6].copy(), qdd, mu


def solve_dense_kkt(blocks: SystemBlocks, cond_limit: float = KKT_COND_LIMIT) -> Solution:
    """Forward dynamics by assembling and solving the full KKT system (Eq 4.9).

    Args:
        blocks: the system blocks.
        cond_limit: raise when ``‖x‖∞ ‖K‖∞ / ‖rhs‖∞`` (a lower bound of the condition number
            of ``K``) exceeds this.

    Returns:
        The solution (``solver="dense_kkt"``, ``singular_arms=()``).

    Raises:
        DynamicsError: the KKT matrix is singular or too badly conditioned (redundant or
            conflicting constraints).
        InputError: NaN or infinity in the blocks.
    """
    K, rhs = assemble_kkt(blocks)
    try:
        x = np.linalg.solve(K, rhs)
    except np.linalg.LinAlgError:
        blocks.check_finite()
        raise DynamicsError(
            "the KKT matrix is singular (redundant constraints or singular M_o/M_i); "
            "use solver='singular' or 'auto' for redundant constraints"
        ) from None
    if not np.isfinite(x).all():
        blocks.check_finite()
        raise DynamicsError("the dense KKT solve produced NaN or infinity")
    xn, bn = np.abs(x).max(), np.abs(rhs).max()
    if xn > 0 and xn * np.abs(K).max() > cond_limit * bn:
        raise DynamicsError(
            f"the KKT matrix is singular or badly conditioned (condition number >= "
            f"{xn * np.abs(K).max() / bn:.3g}); use solver='singular' or 'auto' for "
            "redundant constraints"
        )
    a_o, qdd, mu = unpack_kkt(blocks, x)
    return Solution(a_o, qdd, mu, "dense_kkt", (), blocks)
