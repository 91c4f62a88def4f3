"""Warm-started force distribution: the least-norm QP of ch. 5 on the per-arm blocks, compiled.

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

The result is exact: the kernel returns it only when the KKT conditions hold to
``KKT_TOL`` (relative to the size of the forces) and ``W_F W_Fᵀ`` is well conditioned;
otherwise (a free set whose columns do not span the wrenches, no convergence within the
iteration cap) it reports failure and :class:`WarmForceDistribution` solves cold with
:func:`~multiarm_pin.dynamics.force_distribution.min_norm_forces` (NNLS), which also raises
the documented errors (unreachable wrench, infeasible margin).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from multiarm_pin._compiled.linalg import cholesky, cholesky_solve, inverse_diagonal
from multiarm_pin.dynamics.force_distribution import min_norm_forces
from multiarm_pin.exceptions import InputError

KKT_TOL = 1e-11
"""Relative tolerance of the compiled solve's KKT check (primal and dual feasibility), relative
to ``max(‖w‖∞, m, max |μ|)``."""

GRAM_COND_LIMIT = 1e6
"""Largest accepted condition estimate of ``W_F W_Fᵀ`` (its error grows with the square of the
condition of ``W_F``); beyond it the cold solve decides."""

QP_OK = 0
"""Status of :func:`least_norm_forces`: solved, KKT conditions verified."""
QP_FAILED = 1
"""Status: degenerate free set, ill-conditioned ``W_F W_Fᵀ`` or no convergence (cold solve)."""


@njit(cache=True, error_model="numpy")
def least_norm_forces(W_o, N, unilateral, wrench, margin, active, mu,
                      max_iter):  # pragma: no cover - compiled
    """Least-norm multipliers with unilateral margins, warm-started from ``active``.

    Args:
        W_o: (n, 6, m) object wrench bases of the arms' multipliers (``blocks.W_o``; wrench
            ``[f; m]`` at the COM, world axes, per unit multiplier), zero on padding.
        N: (n,) int multipliers per arm.
        unilateral: (n, m) bool, True for multipliers that must stay >= ``margin``.
        wrench: (6,) object wrench ``w`` the multipliers must produce [N, N m].
        margin: the margin ``m >= 0`` [N].
        active: (n, m) uint8, in: the starting active set (1 = held at the margin; read only
            where ``unilateral``), out: the final one.
        mu: output (n, m) multipliers [N] (positive = pushing), zero on padding.
        max_iter: iteration cap.

    Returns:
        ``(status, iterations)``: :data:`QP_OK` or :data:`QP_FAILED` (``mu`` meaningless).
    """
    n, _, m = W_o.shape
    G = np.empty((6, 6))
    L = np.zeros((6, 6))
    lam = np.empty((6, 1))
    dinv = np.empty(6)
    col = np.empty(6)
    wmax = 0.0
    for a in range(6):
        wmax = max(wmax, abs(wrench[a]))
    for i in range(n):
        for s in range(m):
            if not unilateral[i, s] or s >= N[i]:
                active[i, s] = 0
    for it in range(max_iter):
        for a in range(6):
            lam[a, 0] = wrench[a]
            for b in range(6):
                G[a, b] = 0.0
        for i in range(n):
            for s in range(N[i]):
                if active[i, s]:
                    for a in range(6):
                        lam[a, 0] -= margin * W_o[i, a, s]
                else:
                    for a in range(6):
                        w = W_o[i, a, s]
                        for b in range(a + 1):
                            G[a, b] += w * W_o[i, b, s]
        for a in range(6):
            for b in range(a):
                G[b, a] = G[a, b]
        if not cholesky(G, L, np.int64(6)):
            return QP_FAILED, it
        inverse_diagonal(L, np.int64(6), dinv, col)
        gmax = 0.0
        imax = 0.0
        for a in range(6):
            gmax = max(gmax, G[a, a])
            imax = max(imax, dinv[a])
        if not (gmax * imax <= GRAM_COND_LIMIT):
            return QP_FAILED, it
        cholesky_solve(L, lam, np.int64(6), np.int64(1))
        scale = max(wmax, margin)
        for i in range(n):
            for s in range(m):
                if s >= N[i]:
                    mu[i, s] = 0.0
                elif active[i, s]:
                    mu[i, s] = margin
                else:
                    acc = 0.0
                    for a in range(6):
                        acc += W_o[i, a, s] * lam[a, 0]
                    mu[i, s] = acc
                    scale = max(scale, abs(acc))
        tol = KKT_TOL * max(scale, 1e-300)
        # one change each way per iteration: the most violated bound enters the active set,
        # the most negative bound multiplier leaves it (all at once can empty the free set)
        worst_p, ip, sp = -tol, -1, -1
        worst_d, idd, sd = -tol, -1, -1
        for i in range(n):
            for s in range(N[i]):
                if not unilateral[i, s]:
                    continue
                if active[i, s]:
                    nu = margin
                    for a in range(6):
                        nu -= W_o[i, a, s] * lam[a, 0]
                    if nu < worst_d:  # the bound pulls: release it
                        worst_d, idd, sd = nu, i, s
                elif mu[i, s] - margin < worst_p:  # below the margin: hold it there
                    worst_p, ip, sp = mu[i, s] - margin, i, s
        changed = ip >= 0 or idd >= 0
        if ip >= 0:
            active[ip, sp] = 1
        if idd >= 0:
            active[idd, sd] = 0
        if not changed:
            total = 0.0
            for i in range(n):
                for s in range(m):
                    total += mu[i, s]
            if not math.isfinite(total):
                return QP_FAILED, it + 1
            return QP_OK, it + 1
    return QP_FAILED, max_iter


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
