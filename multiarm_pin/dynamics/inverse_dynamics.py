"""Whole-system inverse dynamics (thesis Eq 3.7-3.10) on the coefficient blocks.

Given a desired object acceleration ``a_o``, the arms must apply the object wrench
``w = M_o a_o - h_o = W_o μ`` (``W_o = [W_o,1 ... W_o,n]``, 6 x Σ N_i). Its solutions are
(Eq 3.4) ``μ = W_o⁺ w + A_o μ_I`` with ``A_o`` a basis of the null space of ``W_o``: ``μ_I``
are the internal forces, which do not move the object. Each arm's joint accelerations must
satisfy its constraint rows ``W_iᵀ q̈_i = c_i - W_o,iᵀ a_o``; the remaining freedom (relative
motion, redundancy) is set by the desired joint accelerations. The torques then follow from
the arm equations ``τ_i = M_i q̈_i - h_i - W_i μ_i``.

Two choices of ``A_o`` (Sec 3.7.3): ``"svd"`` (orthonormal columns), and ``"echelon"``: one
free multiplier per column, ``A_o`` restricted to the free rows is the identity, so
``μ_I,j = μ_free(j) - (W_o⁺ w)_free(j)`` is the change of one contact force only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multiarm_pin.dynamics.blocks import SystemBlocks
from multiarm_pin.exceptions import DynamicsError, InputError
from multiarm_pin.spatial import as_array

RANK_TOL = 1e-10
"""Relative singular-value threshold for the rank of ``W_o`` and of the ``W_i``."""

BASIS_METHODS = ("svd", "echelon")


@dataclass(frozen=True)
class InternalForceBasis:
    """A basis of the internal forces of a grasp: the null space of ``W_o`` (Eq 3.4).

    Attributes:
        A_o: (K, k) basis of the null space of ``W_o``, ``K = Σ N_i`` (stacked arm-major
            multipliers), ``k = K - rank``.
        W_o: (6, K) the stacked object wrench matrix it was built from.
        W_o_pinv: (K, 6) Moore-Penrose pseudo-inverse of ``W_o``: ``W_o⁺ w`` is the
            minimum-norm multiplier vector producing the object wrench ``w``.
        rank: rank of ``W_o`` (6 for a grasp that can exert any wrench).
        method: ``"svd"`` (orthonormal ``A_o``) or ``"echelon"``.
        free: (k,) indices (into the stacked multipliers) of the free multipliers of the
            echelon basis (``A_o[free] = I``); for ``"svd"``, empty.
    """

    A_o: np.ndarray
    W_o: np.ndarray
    W_o_pinv: np.ndarray
    rank: int
    method: str
    free: np.ndarray

    def coordinates(self, mu_flat: np.ndarray) -> np.ndarray:
        """Internal-force coordinates ``μ_I`` (k,) of a stacked multiplier vector (K,).

        Only the null-space part ``mu_flat - W_o⁺ W_o mu_flat`` counts.
        """
        null_part = mu_flat - self.W_o_pinv @ (self.W_o @ mu_flat)
        if self.method == "echelon":
            return null_part[self.free]
        return self.A_o.T @ null_part


def internal_force_basis(
    W_o: np.ndarray, method: str = "svd", tol: float = RANK_TOL
) -> InternalForceBasis:
    """Null-space basis ``A_o`` and pseudo-inverse of the stacked object wrench matrix.

    Args:
        W_o: (6, K) stacked object wrench bases ``[W_o,1 ... W_o,n]`` (wrench ``[f; m]`` at
            the COM in world axes per unit multiplier), e.g. ``blocks.stacked_W_o()``.
        method: ``"svd"`` or ``"echelon"`` (Sec 3.7.3).
        tol: relative singular-value threshold for the rank.

    Returns:
        The basis (see :class:`InternalForceBasis`).

    Raises:
        InputError: unknown method, wrong shape, NaN.
    """
    if method not in BASIS_METHODS:
        raise InputError(f"unknown A_o method {method!r}; known: {', '.join(BASIS_METHODS)}")
    W = as_array(W_o, (6, None), "W_o (6 x Σ N_i)")
    K = W.shape[1]
    U, s, Vt = np.linalg.svd(W, full_matrices=True)
    rank = int(np.sum(s > tol * s[0])) if K and s[0] > 0 else 0
    pinv = Vt[:rank].T @ (U[:, :rank] / s[:rank]).T
    if method == "svd":
        return InternalForceBasis(Vt[rank:].T.copy(), W, pinv, rank, "svd", np.zeros(0, int))
    # Echelon: the first independent columns (the pivots of the reduced row echelon form of
    # W_o) are basic, the others free; A_o[free] = I, A_o[basic] = -W_B⁺ W_F.
    basic: list[int] = []
    Q = np.zeros((6, 0))
    scale = np.abs(W).max() if K else 1.0
    for j in range(K):
        resid = W[:, j] - Q @ (Q.T @ W[:, j])
        if np.linalg.norm(resid) > tol * max(scale, 1e-300) * 10 and len(basic) < rank:
            basic.append(j)
            Q = np.column_stack([Q, resid / np.linalg.norm(resid)])
    free = np.array([j for j in range(K) if j not in basic], dtype=int)
    A_o = np.zeros((K, K - len(basic)))
    A_o[free, np.arange(len(free))] = 1.0
    if basic:
        A_o[basic] = -np.linalg.lstsq(W[:, basic], W[:, free], rcond=None)[0]
    return InternalForceBasis(A_o, W, pinv, rank, "echelon", free)


@dataclass(frozen=True)
class InverseDynamicsResult:
    """Joint torques that realise a desired motion with given internal forces.

    Attributes:
        tau: (n, nv_max) joint torques to add to ``blocks.h`` [N m or N] (zero on padding).
            With ``h = -nle`` in the blocks these are the full actuator torques.
        mu: (n, N_max) contact multipliers (positive = pushing), zero on padding.
        qdd: (n, nv_max) joint accelerations used, zero on padding.
        a_o: (6,) the object acceleration ``[ẍ; ω̇]`` at the COM, world axes.
        mu_I: (k,) internal-force coordinates in ``basis``.
        basis: the internal-force basis used.
    """

    tau: np.ndarray
    mu: np.ndarray
    qdd: np.ndarray
    a_o: np.ndarray
    mu_I: np.ndarray
    basis: InternalForceBasis


def inverse_dynamics(
    blocks: SystemBlocks,
    a_o,
    qdd_desired=None,
    mu_I=None,
    basis: InternalForceBasis | str = "svd",
    tol: float = 1e-9,
) -> InverseDynamicsResult:
    """Torques for a desired object acceleration, relative motion and internal force (Eq 3.10).

    Args:
        blocks: the system blocks, normally with zero torque (``h = -nle``).
        a_o: (6,) desired object classical acceleration ``[ẍ; ω̇]`` at the COM, world axes
            [m/s², rad/s²].
        qdd_desired: (n, nv_max) desired joint accelerations (padding ignored); the result
            is the closest (Euclidean norm) ``q̈_i`` that satisfies the constraint rows, so
            only its part along the arm's free motions counts. Default zero: minimum-norm
            ``q̈_i``.
        mu_I: (k,) internal force in the coordinates of ``basis`` (default zero: the
            minimum-norm multipliers).
        basis: an :class:`InternalForceBasis` of ``blocks.stacked_W_o()``, or the method name
            (``"svd"``, ``"echelon"``) to build one.
        tol: relative tolerance for the checks that the object wrench and the constraint
            rows can be met.

    Returns:
        The torques, multipliers and accelerations (:class:`InverseDynamicsResult`).
        Forward dynamics with ``blocks.with_torques(tau)`` reproduces ``a_o`` and ``qdd``.

    Raises:
        DynamicsError: the contacts cannot produce the wrench needed for ``a_o``, or an arm
            cannot follow the object (its constraint rows cannot be met).
        InputError: wrong shapes or NaN, a basis of the wrong size.
    """
    b = blocks
    a = as_array(a_o, (6,), "a_o")
    W_o = b.stacked_W_o()
    if isinstance(basis, str):
        basis = internal_force_basis(W_o, basis)
    elif not isinstance(basis, InternalForceBasis):
        raise InputError(f"basis: expected InternalForceBasis or a method name, got {basis!r}")
    K, k = basis.A_o.shape
    if K != W_o.shape[1]:
        raise InputError(f"basis: built for {K} multipliers, the blocks have {W_o.shape[1]}")
    muI = np.zeros(k) if mu_I is None else as_array(mu_I, (k,), f"mu_I (k = {k})")
    # Object: W_o μ = M_o a_o - h_o.
    wrench = b.M_o @ a - b.h_o
    mu_flat = basis.W_o_pinv @ wrench + basis.A_o @ muI
    miss = np.linalg.norm(W_o @ mu_flat - wrench)
    if miss > tol * max(np.linalg.norm(wrench), np.linalg.norm(b.M_o @ a), 1e-12):
        raise DynamicsError(
            f"the contacts cannot produce the object wrench needed for a_o (W_o has rank "
            f"{basis.rank} < 6; unreachable part {miss:.3g} N or N m)"
        )
    mu = b.unflatten_mu(mu_flat)
    # Arms: W_iᵀ q̈_i = c_i - W_o,iᵀ a_o, closest to the desired q̈_i.
    if qdd_desired is None:
        q0 = np.zeros((b.n, b.nv_max))
    else:
        q0 = as_array(qdd_desired, (b.n, b.nv_max), "qdd_desired (n, nv_max)")
        q0 = np.where(b.dof_mask, q0, 0.0)
    Wt = b.W.transpose(0, 2, 1)  # (n, N_max, nv_max)
    target = b.c - np.einsum("nij,i->nj", b.W_o, a)
    gap = target - np.einsum("nij,nj->ni", Wt, q0)
    qdd = q0 + np.einsum("nij,nj->ni", np.linalg.pinv(Wt, rcond=RANK_TOL), gap)
    miss_arm = np.linalg.norm(np.einsum("nij,nj->ni", Wt, qdd) - target, axis=1)
    scale = np.maximum(np.abs(target).max(axis=1), np.abs(q0).max(axis=1)) + 1e-12
    bad = miss_arm > tol * np.maximum(scale, np.abs(qdd).max(axis=1))
    if bad.any():
        raise DynamicsError(
            f"arm(s) {np.flatnonzero(bad).tolist()} cannot follow the object: their constraint "
            f"rows W_iᵀ q̈_i = c_i - W_o,iᵀ a_o have no solution (fewer independent joint "
            f"directions than constraints; residual {miss_arm[bad].max():.3g})"
        )
    tau = (
        np.einsum("nij,nj->ni", b.M, qdd) - b.h - np.einsum("nij,nj->ni", b.W, mu)
    )
    tau[~b.dof_mask] = 0.0
    return InverseDynamicsResult(tau, mu, qdd, a, muI, basis)
