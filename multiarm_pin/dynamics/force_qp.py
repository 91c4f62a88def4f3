"""Warm-started force distribution: the least-norm QP of ch. 5 on the per-arm blocks.

The same problem as :func:`~multiarm_pin.dynamics.force_distribution.min_norm_forces`::

    minimise ½ ‖μ‖²  subject to  W_o μ = w,  μ_j >= m for every unilateral multiplier j

solved without the SVD of the stacked ``W_o`` (6 x Σ N_i): for an active set ``A`` (unilateral
multipliers held at the margin) the KKT conditions give ``μ_A = m``, ``μ_F = W_Fᵀ λ`` with
``(W_F W_Fᵀ) λ = w - m W_A 1`` (a 6 x 6 Cholesky; ``W_F W_Fᵀ`` is summed arm by arm over the
columns of ``W_o,i``) and the bound multipliers ``ν_j = m - w_jᵀ λ`` of the active ones. An
active-set iteration moves the multiplier furthest below the margin into ``A`` and the one
with the most negative ``ν`` out of it, until neither exists. Between two control steps the
active set rarely changes, so started from the previous step's set
(:class:`WarmForceDistribution`) it usually stops after one 6 x 6 solve.

The result is exact: the kernel (:func:`multiarm_pin._compiled.force_qp.least_norm_forces`)
returns it only when the KKT conditions hold to ``KKT_TOL`` (relative to the size of the
forces) and ``W_F W_Fᵀ`` is well conditioned;
otherwise (a free set whose columns do not span the wrenches, no convergence within the
iteration cap) it reports failure and :class:`WarmForceDistribution` solves cold with
:func:`~multiarm_pin.dynamics.force_distribution.min_norm_forces` (NNLS), which also raises
the documented errors (unreachable wrench, infeasible margin).

Twins: ``multiarm_pin._compiled.force_qp`` (the same concept, the warm-started least-norm force
QP, at the compiled layer: this module is its Python driver, which keeps the active set between
calls and solves cold when it fails; that one is the kernel, ``least_norm_forces``).
"""

from __future__ import annotations

import numpy as np

from multiarm_pin._compiled.force_qp import (
    KKT_TOL,
    QP_FAILED,
    QP_OK,
    least_norm_forces,
)
from multiarm_pin.dynamics.force_distribution import min_norm_forces
from multiarm_pin.exceptions import InputError


class WarmForceDistribution:
    """The force distribution of one system, warm-started from the previous call's active set.

    Args:
        N: (n,) int multipliers per arm.
        unilateral: (n, N_max) bool mask of unilateral multipliers (padding False).

    Attributes:
        active: (n, N_max) uint8, the active set of the last solve (1 = at the margin).
        iterations: active-set iterations of the last compiled solve.
        cold_solves: how many calls fell back to the cold NNLS solve.
    """

    def __init__(self, N, unilateral):
        self.N = np.ascontiguousarray(N, dtype=np.int64)
        U = np.asarray(unilateral)
        if U.dtype != bool or U.ndim != 2 or U.shape[0] != len(self.N):
            raise InputError(f"unilateral: expected an (n, N_max) bool mask, got {U!r}")
        self.unilateral = np.ascontiguousarray(U)
        self.active = np.zeros(U.shape, dtype=np.uint8)
        self._mask = np.arange(U.shape[1])[None, :] < self.N[:, None]
        self.iterations = 0
        self.cold_solves = 0

    def solve(self, W_o: np.ndarray, wrench: np.ndarray, margin: float) -> np.ndarray:
        """Multipliers (n, N_max) [N] of the least-norm QP (see the module docstring).

        Args:
            W_o: (n, 6, N_max) object wrench bases (``blocks.W_o``), zero on padding.
            wrench: (6,) object wrench to produce [N, N m].
            margin: least push of the unilateral multipliers [N] (>= 0).

        Raises:
            DynamicsError: unreachable wrench or infeasible margin (from the cold solve).
        """
        W = np.ascontiguousarray(W_o, dtype=float)
        w = np.ascontiguousarray(wrench, dtype=float)
        mu = np.empty(self.unilateral.shape)
        status, self.iterations = least_norm_forces(
            W, self.N, self.unilateral, w, float(margin), self.active, mu,
            20 + 2 * int(self.N.sum()))
        if status == QP_OK:
            return mu
        return self.cold(W, w, margin)

    def cold(self, W_o: np.ndarray, wrench: np.ndarray, margin: float) -> np.ndarray:
        """:func:`min_norm_forces` (SVD and NNLS), and its active set kept for the next call."""
        self.cold_solves += 1
        Wf = W_o.transpose(0, 2, 1)[self._mask].T
        mu_flat = min_norm_forces(Wf, wrench, self.unilateral[self._mask], margin)
        mu = np.zeros(self.unilateral.shape)
        mu[self._mask] = mu_flat
        self.seed(mu, margin)
        return mu

    def seed(self, mu: np.ndarray, margin: float) -> None:
        """Start the next solve from the active set of multipliers ``mu`` (n, N_max) [N].

        The unilateral multipliers within ``1e-9`` (relative) of ``margin`` are active.
        """
        scale = max(float(np.abs(mu).max(initial=0.0)), margin, 1e-300)
        self.active = (self.unilateral & (mu <= margin + 1e-9 * scale)).astype(np.uint8)


__all__ = ["KKT_TOL", "QP_FAILED", "QP_OK", "WarmForceDistribution", "least_norm_forces"]
