"""Dense KKT forward dynamics (thesis Eq 4.9, its ``msolve03``): the straightforward reference.

The whole system is assembled as one symmetric matrix of size ``6 + Σ nv_i + Σ N_i`` in the
unknowns ``[a_o; q̈_1 .. q̈_n; λ]`` with ``λ = -μ`` (the thesis's multiplier sign)::

    [ M_o   0    W_o ] [a_o]   [h_o]
    [ 0     M    W   ] [q̈  ] = [h  ]
    [ W_oᵀ  Wᵀ   0   ] [λ  ]   [c  ]

and solved with one LU factorisation. No least-squares fallback: a singular KKT matrix
(redundant constraints) raises; use the ``"singular"`` solver then.

Singularity is decided **structurally**, before the LU, not from what the LU's rounding
produced: with ``M_o`` and every ``M_i`` positive definite (``M_o`` is checked when the blocks
are built, ``M_i`` by its Cholesky factorisation here), ``K`` is nonsingular exactly when the
constraint Jacobian ``A = [W_oᵀ  Wᵀ]`` (``Σ N_i`` rows, ``6 + Σ nv_i`` columns) has full row
rank. Its rank is read off the singular values of ``A`` with each row scaled to unit length
(a constraint's row scale is arbitrary, so the verdict must not depend on it), counting those
above ``KKT_RANK_RTOL`` times the largest. Redundant constraints give singular values at the
level of round-off (~1e-16 relative) on any CPU and BLAS kernel; independent ones of the
systems we build stay many orders of magnitude above the cut-off.
"""

from __future__ import annotations

import numpy as np

from multiarm_pin.dynamics.blocks import Solution, SystemBlocks
from multiarm_pin.exceptions import DynamicsError

KKT_RANK_RTOL = 1e-10
"""Singular values of the row-normalised constraint Jacobian below this times the largest count
as zero (a rank-deficient Jacobian, i.e. redundant constraints, raises)."""

KKT_COND_LIMIT = 1e13
"""A proven lower bound of the KKT condition number above this raises :class:`DynamicsError`
(a full-rank but numerically hopeless system: the answer would carry no correct digit)."""


def constraint_jacobian(blocks: SystemBlocks) -> tuple[np.ndarray, np.ndarray]:
    """The stacked constraint Jacobian ``A = [W_oᵀ  Wᵀ]`` of the blocks, without padding.

    Args:
        blocks: the system blocks.

    Returns:
        ``(A, arm)``: ``A`` of shape (Σ N_i, 6 + Σ nv_i), columns ordered like the KKT
        unknowns ``[a_o; q̈ arm-major]``, rows arm-major; ``arm`` (Σ N_i,) int, the arm of
        each row.
    """
    b = blocks
    nv_tot = int(b.nv.sum())
    A = np.zeros((b.n_constraints, 6 + nv_tot))
    arm = np.repeat(np.arange(b.n), b.N)
    jq, r = 6, 0
    for i in range(b.n):
        k, m = int(b.nv[i]), int(b.N[i])
        A[r:r + m, :6] = b.W_o[i, :, :m].T
        A[r:r + m, jq:jq + k] = b.W[i, :k, :m].T
        jq += k
        r += m
    return A, arm


def redundant_constraints(
    blocks: SystemBlocks, rtol: float = KKT_RANK_RTOL
) -> tuple[int, tuple[int, ...]]:
    """Rank of the constraint Jacobian and the arms whose constraints are linearly dependent.

    The rows of ``A`` (:func:`constraint_jacobian`) are scaled to unit length; the rank is the
    number of singular values above ``rtol`` times the largest (a zero row counts as
    dependent). The arms reported are those with a row that takes part in some dependency:
    a nonzero entry (above ``sqrt(rtol)``) in a left null vector of the scaled ``A``.

    Args:
        blocks: the system blocks.
        rtol: relative singular-value cut-off.

    Returns:
        ``(rank, arms)``: the rank of ``A`` and the sorted arm indices of the dependent rows
        (empty when ``A`` has full row rank, i.e. ``rank == Σ N_i``).
    """
    A, arm = constraint_jacobian(blocks)
    m = A.shape[0]
    if m == 0:
        return 0, ()
    norms = np.linalg.norm(A, axis=1)
    zero = norms == 0.0
    A = A / np.where(zero, 1.0, norms)[:, None]
    U, s, _ = np.linalg.svd(A, full_matrices=True)
    s_full = np.zeros(m)
    s_full[:s.size] = s
    keep = s_full > rtol * s_full[0] if s_full[0] > 0 else np.zeros(m, dtype=bool)
    rank = int(keep.sum())
    if rank == m:
        return rank, ()
    null = U[:, ~keep]  # left null space of the scaled A (its columns y: yᵀA ≈ 0)
    involved = (np.abs(null).max(axis=1) > np.sqrt(rtol)) | zero
    return rank, tuple(sorted({int(a) for a in arm[involved]}))


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


def solve_dense_kkt(
    blocks: SystemBlocks, cond_limit: float = KKT_COND_LIMIT, *, check_rank: bool = True
) -> Solution:
    """Forward dynamics by assembling and solving the full KKT system (Eq 4.9).

    Args:
        blocks: the system blocks.
        cond_limit: raise when ``‖x‖∞ ‖K‖∞ / ‖rhs‖∞`` (a lower bound of the condition number
            of ``K``) exceeds this.
        check_rank: decide singularity structurally first (see the module docstring). Only
            the benchmark turns this off, to time the bare assembly and LU of the thesis's
            ``msolve03``; without it a singular ``K`` may go undetected.

    Returns:
        The solution (``solver="dense_kkt"``, ``singular_arms=()``).

    Raises:
        DynamicsError: the KKT matrix is singular (redundant constraints, named by arm; a
            singular ``M_i``) or too badly conditioned.
        InputError: NaN or infinity in the blocks.
    """
    if check_rank:
        blocks.check_finite()
        _check_mass_matrices(blocks)
        rank, arms = redundant_constraints(blocks)
        if arms:
            raise DynamicsError(
                f"the KKT matrix is singular: the constraint Jacobian [W_oᵀ Wᵀ] has rank "
                f"{rank} < {blocks.n_constraints} rows, the constraints of arm(s) "
                f"{list(arms)} are redundant (linearly dependent); use solver='singular' or "
                "'auto' for redundant constraints"
            )
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


def _check_mass_matrices(blocks: SystemBlocks) -> None:
    """Raise :class:`DynamicsError` naming the arms whose ``M_i`` is not positive definite."""
    bad = []
    for i in range(blocks.n):
        k = int(blocks.nv[i])
        try:
            np.linalg.cholesky(blocks.M[i, :k, :k])
        except np.linalg.LinAlgError:
            bad.append(i)
    if bad:
        raise DynamicsError(
            f"the KKT matrix is singular: M_i of arm(s) {bad} is not positive definite"
        )
