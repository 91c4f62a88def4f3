"""Singular-arm variant of the object-first solver (thesis Sec 4.2, generalised McMillan).

When some ``S_i = W_iᵀ M_i⁻¹ W_i`` are singular (an arm at a kinematic singularity, an arm
with fewer joints than constraints, a fixed gripper with no joints), their multipliers cannot
be eliminated arm by arm. The regular arms ``R`` are eliminated into the object as in the
object-first solver::

    M̃_o = M_o + Σ_{i∈R} W_o,i S_i⁻¹ W_o,iᵀ,   h̃_o = h_o + Σ_{i∈R} W_o,i S_i⁻¹ r_i,
    M̃_o a_o = h̃_o + Σ_{j∈Sg} W_o,j μ_j                               (thesis 4.11, 2nd)

and substituting ``a_o`` into the constraint rows of the singular arms ``Sg`` gives the coupled
system (thesis 4.12, 2nd, in our sign convention)::

    F μ_Sg = d,   F_ij = W_o,iᵀ M̃_o⁻¹ W_o,j + δ_ij S_i,   d_i = r_i - W_o,iᵀ M̃_o⁻¹ h̃_o

``F`` is symmetric positive semi-definite. It is solved in the least-squares, minimum-norm
sense; when the system is consistent every solution gives the same motion. An inconsistent
system (the constraints cannot all hold) raises :class:`DynamicsError`.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from multiarm_pin.dynamics.blocks import Solution, SystemBlocks
from multiarm_pin.dynamics.object_first import (
    DEFAULT_RCOND_TOL,
    ArmReduction,
    _check_tol,
    reduce_arms,
    solve_object_system,
)
from multiarm_pin.exceptions import DynamicsError, InputError

LSTSQ_RCOND = 1e-12
"""Relative singular-value cut-off for the least-squares solve of ``F μ = d``."""

CONSISTENCY_TOL = 1e-8
"""Largest accepted ``‖F μ - d‖ / (‖F‖ ‖μ‖ + ‖d‖)`` before the system is called inconsistent."""


def solve_singular(
    blocks: SystemBlocks,
    rcond_tol: float = DEFAULT_RCOND_TOL,
    singular_arms: Iterable[int] | None = None,
) -> Solution:
    """Forward dynamics with the singular-arm variant of the object-first solver.

    Args:
        blocks: the system blocks.
        rcond_tol: arms whose estimated reciprocal condition number of ``S_i`` is below this
            are treated as singular.
        singular_arms: extra arm indices to treat as singular even if their ``S_i`` is
            well conditioned (any partition gives the same motion; useful for checks).

    Returns:
        The solution, ``solver="singular"``; ``singular_arms`` lists the arms treated as
        singular (detected ones and those asked for).

    Raises:
        DynamicsError: the constraints are inconsistent (no solution), or ``M_i`` singular.
        InputError: bad ``singular_arms`` index, NaN or infinity in the blocks.
    """
    _check_tol(rcond_tol)
    red = reduce_arms(blocks)
    mask = red.rcond < rcond_tol
    if singular_arms is not None:
        for i in singular_arms:
            if not (isinstance(i, int | np.integer) and 0 <= i < blocks.n):
                raise InputError(
                    f"singular_arms: expected arm indices in [0, {blocks.n}), got {i!r}"
                )
            mask[i] = True
    return finish_singular(blocks, red, mask)


def finish_singular(blocks: SystemBlocks, red: ArmReduction, mask: np.ndarray) -> Solution:
    """Solve the system given the per-arm reduction and the (n,) mask of singular arms."""
    b = blocks
    m = b.N_max
    X, S, r = red.X, red.S, red.r
    reg = ~mask
    sg = np.flatnonzero(mask)
    mu = np.zeros((b.n, m))
    # Regular arms: eliminate into the object.
    M_t = b.M_o.copy()
    h_t = b.h_o.copy()
    Z = None
    if reg.any():
        Z = red.Z[reg]  # S_i⁻¹ [W_o,iᵀ r_i] of the regular arms
        AB = b.W_o[reg].transpose(1, 0, 2).reshape(6, -1) @ Z.reshape(-1, 7)
        M_t += AB[:, :6]
        h_t += AB[:, 6]
    # Singular arms: coupled system F μ = d on their real (unpadded) multipliers.
    cm_s = b.constraint_mask[sg]  # (s, m)
    W_flat = b.W_o[sg].transpose(1, 0, 2).reshape(6, -1)[:, cm_s.ravel()]  # (6, p)
    p = W_flat.shape[1]
    Y = solve_object_system(b, M_t, np.concatenate((W_flat, h_t[:, None]), axis=1))
    F = W_flat.T @ Y[:, :p]
    offsets = np.concatenate(([0], np.cumsum(b.N[sg])))
    for j, i in enumerate(sg):  # loop over singular arms only (the rare path)
        lo, hi = offsets[j], offsets[j + 1]
        F[lo:hi, lo:hi] += S[i, : b.N[i], : b.N[i]]
    d = r[sg][cm_s] - W_flat.T @ Y[:, p]
    if not (np.isfinite(F).all() and np.isfinite(d).all()):
        b.check_finite()
    if p:
        mu_s, *_ = np.linalg.lstsq(F, d, rcond=LSTSQ_RCOND)
        res = float(np.linalg.norm(F @ mu_s - d))
        scale = float(np.linalg.norm(F, 2) * np.linalg.norm(mu_s) + np.linalg.norm(d))
    else:
        mu_s, res, scale = np.zeros(0), 0.0, 1.0
    if res > CONSISTENCY_TOL * max(scale, 1e-300):
        raise DynamicsError(
            f"the constraints of arm(s) {sg.tolist()} are inconsistent: the coupled system "
            f"F μ = d has no solution (least-squares residual {res:.3g}, relative "
            f"{res / max(scale, 1e-300):.3g}); check c (velocity consistency) and W"
        )
    a_o = Y[:, p] + Y[:, :p] @ mu_s
    mu_sg = np.zeros((len(sg), m))
    mu_sg[cm_s] = mu_s
    mu[sg] = mu_sg
    if Z is not None:
        mu[reg] = Z[:, :, 6] - Z[:, :, :6] @ a_o
    qdd = X[:, :, m] + np.matmul(X[:, :, :m], mu[:, :, None])[:, :, 0]
    if not np.isfinite(a_o).all():
        b.check_finite()
        raise DynamicsError("singular-arm solve produced a non-finite object acceleration")
    return Solution(a_o, qdd, mu, "singular", tuple(int(i) for i in sg), b)
