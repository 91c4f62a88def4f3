"""The Delassus operator of the contact rows, object-first: the numpy reference.

With the blocks of :class:`~multiarm_pin.dynamics.blocks.SystemBlocks` the normal
accelerations of the rows are ``φ̈ = G μ + b`` with::

    G = blockdiag_i(W_iᵀ M_i⁻¹ W_i) + W_oᵀ M_o⁻¹ W_o      (per-arm blocks + rank-6 coupling)
    b = W_oᵀ M_o⁻¹ h_o + Wᵀ M⁻¹ h - c                      (φ̈ of the motion with μ = 0)

built arm by arm; the dense ``J M⁻¹ Jᵀ`` over all arms is never formed.
:func:`delassus_operator` is the numpy reference: ``G`` and ``b`` of every real row (one
batched solve with all ``M_i``, one 6 x 6 Cholesky solve for the object).

Its compiled counterpart, the whole unilateral solve in one call, is
:func:`multiarm_pin._compiled.delassus.contact_kernel` (the same concept at the compiled
layer); :mod:`multiarm_pin.dynamics.unilateral` calls it and hands the rare cases it reports
(a singular ``M_i``, non-finite values) to this reference, which raises the documented
errors.

Twins: ``multiarm_pin._compiled.delassus`` (the same concept, the object-first Delassus operator
of the contact rows, at the compiled layer: this module is its numpy reference, that one the
compiled kernel, which also solves the mixed LCP and the motion).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import lapack

from multiarm_pin.dynamics.blocks import SystemBlocks
from multiarm_pin.dynamics.object_first import _batched_solve
from multiarm_pin.exceptions import DynamicsError


@dataclass(frozen=True, eq=False)
class DelassusOperator:
    """Delassus operator of the real constraint rows, built object-first.

    Rows are the real (unpadded) rows stacked arm-major (``blocks.constraint_mask`` order).

    Attributes:
        G: (p, p) ``blockdiag_i(W_iᵀ M_i⁻¹ W_i) + W_oᵀ M_o⁻¹ W_o``, ``p = Σ N_i``: normal
            acceleration per unit multiplier.
        b: (p,) normal accelerations ``φ̈`` with all multipliers zero.
        a_o_free: (6,) ``M_o⁻¹ h_o`` [m/s², rad/s²].
        qdd_free: (n, nv_max) ``M_i⁻¹ h_i``.
        Y_o: (6, p) ``M_o⁻¹ W_o``: object acceleration per unit multiplier.
        X: (n, nv_max, N_max) ``M_i⁻¹ W_i``: joint accelerations per unit multiplier.
    """

    G: np.ndarray
    b: np.ndarray
    a_o_free: np.ndarray
    qdd_free: np.ndarray
    Y_o: np.ndarray
    X: np.ndarray

    def motion(self, mu: np.ndarray, blocks: SystemBlocks) -> tuple[np.ndarray, np.ndarray]:
        """Accelerations ``(a_o (6,), q̈ (n, nv_max))`` for padded multipliers ``mu`` (n, N_max)."""
        a_o = self.a_o_free + self.Y_o @ blocks.flatten_mu(mu)
        qdd = self.qdd_free + np.matmul(self.X, mu[:, :, None])[:, :, 0]
        return a_o, qdd


def delassus_operator(blocks: SystemBlocks, *, with_h: bool = True) -> DelassusOperator:
    """Build the Delassus operator ``G`` and the free normal accelerations ``b`` object-first.

    Per arm ``S_i = W_iᵀ M_i⁻¹ W_i`` (one batched solve with all ``M_i``), plus the rank-6
    object coupling ``W_oᵀ M_o⁻¹ W_o`` (one 6 x 6 Cholesky solve); the dense
    ``J M⁻¹ Jᵀ`` over all arms is never formed.

    Args:
        blocks: the system blocks.
        with_h: if False, ``h``, ``h_o`` and ``c`` are taken as zero (impacts): ``b = 0``.

    Returns:
        The :class:`DelassusOperator` of the real rows (arm-major).

    Raises:
        InputError: NaN or infinity in the blocks.
        DynamicsError: some ``M_i`` is singular.
    """
    bl = blocks
    n, k, m = bl.W.shape
    cm = bl.constraint_mask
    with np.errstate(invalid="ignore", divide="ignore"):
        rhs = np.concatenate((bl.W, bl.h[:, :, None]), axis=2) if with_h else bl.W
        X = _batched_solve(bl.M, rhs)
    if not _all_finite(X):
        bl.check_finite()
        bad = ~np.isfinite(X).reshape(n, -1).all(axis=1)
        raise DynamicsError(
            f"joint-space mass matrix M_i of arm(s) {np.flatnonzero(bad).tolist()} is "
            "singular; a mass matrix must be symmetric positive definite"
        )
    XW = X[:, :, :m]
    S = np.matmul(bl.W.transpose(0, 2, 1), XW)  # (n, m, m)
    Wo = bl.stacked_W_o()  # (6, p)
    p = Wo.shape[1]
    chol, info = lapack.dpotrf(bl.M_o, lower=1)[:2]
    if info != 0:  # pragma: no cover - SystemBlocks checks M_o at construction
        raise DynamicsError("object inertia M_o is not positive definite")
    rhs_o = np.concatenate((Wo, bl.h_o[:, None]), axis=1) if with_h else Wo
    Y = lapack.dpotrs(chol, rhs_o, lower=1)[0]
    G = Wo.T @ Y[:, :p]
    arm, row = np.nonzero(cm)
    same = arm[:, None] == arm[None, :]
    G[same] += S[arm[:, None], row[:, None], row[None, :]][same]
    G = 0.5 * (G + G.T)
    if with_h:
        a_o_free = Y[:, p].copy()
        qdd_free = X[:, :, m].copy()
        b = Wo.T @ a_o_free + np.einsum("nkm,nk->nm", bl.W, qdd_free)[cm] - bl.c[cm]
    else:
        a_o_free = np.zeros(6)
        qdd_free = np.zeros((n, k))
        b = np.zeros(p)
    if not (_all_finite(G) and _all_finite(b)):
        bl.check_finite()
    return DelassusOperator(G, b, a_o_free, qdd_free, np.ascontiguousarray(Y[:, :p]),
                            np.ascontiguousarray(XW))


def _all_finite(a: np.ndarray) -> bool:
    return math.isfinite(float(a.sum()))


__all__ = ["DelassusOperator", "delassus_operator"]
