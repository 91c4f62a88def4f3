"""Object-first forward dynamics (thesis Eq 4.10-4.12, Lilly-Orin style), vectorised over arms.

With ``S_i = W_iᵀ M_i⁻¹ W_i`` and ``r_i = c_i - W_iᵀ M_i⁻¹ h_i`` (our sign convention, see
``docs/ARCHITECTURE.md``) the constraint rows give ``S_i μ_i = r_i - W_o,iᵀ a_o``. Eliminating
every ``μ_i`` from the object equation::

    (M_o + Σ W_o,i S_i⁻¹ W_o,iᵀ) a_o = h_o + Σ W_o,i S_i⁻¹ r_i
    μ_i = S_i⁻¹ (r_i - W_o,iᵀ a_o),     q̈_i = M_i⁻¹ (h_i + W_i μ_i)

All per-arm work is done on stacked arrays with batched LAPACK calls: one solve with
``M`` (right-hand sides ``[W h]`` together), one batched Cholesky of ``S`` for the
conditioning test, one solve with ``S`` (right-hand sides ``[W_oᵀ r]`` together), then a
6 x 6 solve. No Python loop over arms.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multiarm_pin.dynamics.blocks import Solution, SystemBlocks
from multiarm_pin.exceptions import DynamicsError, InputError, SingularityError

DEFAULT_RCOND_TOL = 1e-10
"""An arm whose ``S_i`` has an estimated reciprocal condition number below this is singular."""


@dataclass(frozen=True)
class ArmReduction:
    """Per-arm quantities shared by the object-first and singular-arm solvers.

    Attributes:
        X: (n, nv_max, N_max + 1) ``M_i⁻¹ [W_i  h_i]``.
        S: (n, N_max, N_max) ``W_iᵀ M_i⁻¹ W_i``, with a positive value on the padded diagonal
            (the arm's largest diagonal entry, or 1) so that padded multipliers solve to 0.
        r: (n, N_max) ``c_i - W_iᵀ M_i⁻¹ h_i`` (zero on padding).
        rcond: (n,) estimate of the reciprocal condition number of each ``S_i``: from the
            Cholesky factor ``L``, ``min_j L_jj² / max_j S_jj`` (an upper bound of the true
            reciprocal condition number, so a small value proves bad conditioning); from
            the eigenvalues when the Cholesky factorisation fails.
    """

    X: np.ndarray
    S: np.ndarray
    r: np.ndarray
    rcond: np.ndarray


def reduce_arms(blocks: SystemBlocks) -> ArmReduction:
    """Compute ``M_i⁻¹ [W_i h_i]``, ``S_i``, ``r_i`` and the conditioning of every ``S_i``.

    Args:
        blocks: the system blocks.

    Returns:
        The stacked per-arm quantities (see :class:`ArmReduction`).

    Raises:
        InputError: a block contains NaN or infinity.
        DynamicsError: some ``M_i`` is singular.
    """
    b = blocks
    m = b.N_max
    try:
        X = np.linalg.solve(b.M, np.concatenate((b.W, b.h[:, :, None]), axis=2))
    except np.linalg.LinAlgError:
        b.check_finite()
        _raise_singular_mass(b)
    WtX = np.matmul(b.W.transpose(0, 2, 1), X)
    S = WtX[:, :, :m]
    r = b.c - WtX[:, :, m]
    ar = np.arange(m)
    diag = S[:, ar, ar]
    scale = diag.max(axis=1)
    if b.has_constraint_padding:
        pad = np.where(scale > 0.0, scale, 1.0)
        S[:, ar, ar] = np.where(b.constraint_mask, diag, pad[:, None])
        scale = pad
    try:
        L = np.linalg.cholesky(S)
        d = L[:, ar, ar]
        rcond = (d * d).min(axis=1) / scale
    except np.linalg.LinAlgError:
        if not (np.isfinite(S).all() and np.isfinite(r).all()):
            b.check_finite()
        w = np.linalg.eigvalsh(S)
        top = w[:, -1]
        rcond = np.where(top > 0.0, np.maximum(w[:, 0], 0.0) / np.where(top > 0, top, 1.0), 0.0)
    return ArmReduction(X, S, r, rcond)


def _raise_singular_mass(b: SystemBlocks) -> None:
    w = np.linalg.eigvalsh(b.M)
    bad = np.flatnonzero(w[:, 0] <= 1e-14 * np.maximum(np.abs(w[:, -1]), 1e-300))
    raise DynamicsError(
        f"joint-space mass matrix M_i of arm(s) {bad.tolist()} is singular; "
        "a mass matrix must be symmetric positive definite"
    )


def singular_arm_mask(reduction: ArmReduction, rcond_tol: float = DEFAULT_RCOND_TOL) -> np.ndarray:
    """Boolean (n,) mask of arms whose ``S_i`` is singular or badly conditioned."""
    return reduction.rcond < rcond_tol


def solve_object_first(
    blocks: SystemBlocks, rcond_tol: float = DEFAULT_RCOND_TOL, *, fallback: bool = False
) -> Solution:
    """Forward dynamics by eliminating the multipliers into the object (Eq 4.10-4.12).

    Args:
        blocks: the system blocks (see :class:`SystemBlocks`).
        rcond_tol: arms whose estimated reciprocal condition number of ``S_i`` is below this
            are singular.
        fallback: if True, singular arms are handed to the singular-arm variant
            (:func:`multiarm_pin.dynamics.singular.solve_singular`), and the solution says
            so in ``solver``/``singular_arms``; if False they raise.

    Returns:
        The solution: ``a_o`` (6,) [m/s², rad/s²] LWA at the COM, ``qdd`` (n, nv_max),
        ``mu`` (n, N_max).

    Raises:
        SingularityError: some ``S_i`` is singular or badly conditioned and ``fallback`` is
            False.
        DynamicsError: singular ``M_i`` or singular object matrix.
        InputError: NaN or infinity in the blocks.
    """
    _check_tol(rcond_tol)
    b = blocks
    red = reduce_arms(b)
    X, S, r, rcond = red.X, red.S, red.r, red.rcond
    singular = rcond < rcond_tol
    if singular.any():
        arms = tuple(int(i) for i in np.flatnonzero(singular))
        if fallback:
            from multiarm_pin.dynamics.singular import finish_singular

            return finish_singular(b, red, singular)
        worst = float(rcond[singular].min())
        raise SingularityError(
            f"S_i = W_iᵀ M_i⁻¹ W_i of arm(s) {list(arms)}",
            np.inf if worst <= 0 else 1.0 / worst,
            "the arm is at a singularity or has fewer independent joint directions than "
            "constraints; use solver='auto' or solver='singular'",
        )
    m = b.N_max
    Z = np.linalg.solve(S, np.concatenate((b.W_o.transpose(0, 2, 1), r[:, :, None]), axis=2))
    AB = b.W_o.transpose(1, 0, 2).reshape(6, -1) @ Z.reshape(-1, 7)
    try:
        a_o = np.linalg.solve(b.M_o + AB[:, :6], b.h_o + AB[:, 6])
    except np.linalg.LinAlgError:
        b.check_finite()
        raise DynamicsError(
            "object matrix M_o + Σ W_o,i S_i⁻¹ W_o,iᵀ is singular; M_o must be the positive "
            "definite spatial inertia of the object"
        ) from None
    mu = Z[:, :, 6] - Z[:, :, :6] @ a_o
    qdd = X[:, :, m] + np.matmul(X[:, :, :m], mu[:, :, None])[:, :, 0]
    if not np.isfinite(a_o).all():
        b.check_finite()
        raise DynamicsError("object-first solve produced a non-finite object acceleration")
    return Solution(a_o, qdd, mu, "object_first", (), b)


def _check_tol(rcond_tol: float) -> None:
    if not (isinstance(rcond_tol, float | int) and 0.0 <= rcond_tol < 1.0):
        raise InputError(f"rcond_tol: expected a number in [0, 1), got {rcond_tol!r}")
