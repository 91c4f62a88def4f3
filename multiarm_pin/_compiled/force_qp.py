"""The least-norm force QP of ch. 5 on the per-arm blocks, warm-started, compiled.

The compiled counterpart of :mod:`multiarm_pin.dynamics.force_qp` (the same concept at the
compiled layer: that module's :class:`~multiarm_pin.dynamics.force_qp.WarmForceDistribution`
keeps the active set between calls and solves cold when this kernel reports failure; the
problem and the method are described there). :func:`least_norm_forces` is also called by the
compiled controller (:mod:`multiarm_pin._compiled.controller_kernels`).

Twins: ``multiarm_pin.dynamics.force_qp`` (the same concept at the dynamics layer:
``WarmForceDistribution``, the Python driver of this kernel).
"""

from __future__ import annotations

import math

import numpy as np

from multiarm_pin._compiled.jit import kernel
from multiarm_pin._compiled.linalg import cholesky, cholesky_solve, inverse_diagonal

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


@kernel
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


__all__ = ["GRAM_COND_LIMIT", "KKT_TOL", "QP_FAILED", "QP_OK", "least_norm_forces"]
