"""Compiled object-first forward dynamics (thesis Eq 4.10-4.12) with per-arm Cholesky.

Mirrors :func:`multiarm_pin.dynamics.object_first.solve_object_first_numpy` (the vectorised
numpy reference: same elimination, same conditioning criteria and thresholds); whenever the
kernel reports a doubtful case (:data:`SOLVE_ARM_SINGULAR`, :data:`SOLVE_OBJECT_SINGULAR`)
the callers hand the blocks to that reference, which decides.

Twins: ``multiarm_pin.dynamics.object_first`` (the same concept at the dynamics layer: its
``solve_object_first`` calls this kernel and its ``solve_object_first_numpy`` is the numpy
reference).
"""

from __future__ import annotations

import math

import numpy as np

from multiarm_pin._compiled.jit import kernel
from multiarm_pin._compiled.linalg import cholesky, cholesky_solve, inverse_diagonal

SOLVE_OK = 0
"""Status of :func:`object_first`: solved."""
SOLVE_ARM_SINGULAR = 1
"""Status: some ``M_i`` or ``S_i`` failed to factor, or ``S_i`` is badly conditioned."""
SOLVE_OBJECT_SINGULAR = 2
"""Status: the reduced object matrix is badly conditioned or the result is not finite."""


@kernel
def object_first(M, h, W, W_o, c, M_o, h_o, N, rcond_tol, object_rcond_tol,
                 a_o, qdd, mu):  # pragma: no cover - compiled
    """Object-first forward dynamics (``solve_object_first_numpy``) with per-arm Cholesky.

    Per arm: ``X = M_i⁻¹ [W_i h_i]``, ``S_i = W_iᵀ X_W`` (padded diagonal set to the arm's
    largest ``S_jj``, or 1), ``r_i = c_i - W_iᵀ M_i⁻¹ h_i``, the condition estimate
    ``max_j S_jj · max_j (S⁻¹)_jj`` against ``1 / rcond_tol``, ``Z = S_i⁻¹ [W_o,iᵀ r_i]``;
    then ``(M_o + Σ W_o,i Z_W) a_o = h_o + Σ W_o,i Z_r`` by Cholesky, with the reciprocal
    condition number ``1 / (trace(A) ‖A⁻¹‖₁)`` (exact ``‖A⁻¹‖₁``, the quantity LAPACK
    ``dpocon`` estimates from below) checked against ``object_rcond_tol``; finally
    ``μ_i = Z_r - Z_W a_o`` and ``q̈_i = X_h + X_W μ_i``.

    Args:
        M: (n, k, k) mass matrices (identity on padding).
        h: (n, k) ``τ - nle``.
        W: (n, k, m) ``J_iᵀ G_tool,iᵀ``.
        W_o: (n, 6, m) ``G_object,iᵀ``.
        c: (n, m) constraint right-hand sides.
        M_o: (6, 6) object inertia.
        h_o: (6,) object bias wrench.
        N: (n,) int constraint rows per arm.
        rcond_tol: threshold on each ``S_i`` (``DEFAULT_RCOND_TOL``).
        object_rcond_tol: threshold on the reduced object matrix (``OBJECT_RCOND_TOL``).
        a_o: output (6,) object acceleration ``[ẍ; ω̇]`` at the COM, world axes.
        qdd: output (n, k) joint accelerations.
        mu: output (n, m) multipliers (positive = pushing) [N].

    Returns:
        ``SOLVE_OK``, ``SOLVE_ARM_SINGULAR`` or ``SOLVE_OBJECT_SINGULAR`` (outputs meaningless
        unless OK).
    """
    n, k, m = W.shape
    X = np.empty((n, k, m + 1))
    Z = np.empty((n, m, 7))
    L = np.zeros((k, k))
    S = np.empty((m, m))
    WX = np.empty((m, m + 1))
    LS = np.zeros((m, m))
    dinv = np.empty(m)
    col = np.empty(m)
    A = np.empty((6, 6))
    rhs = np.empty(6)
    for a in range(6):
        rhs[a] = h_o[a]
        for b in range(6):
            A[a, b] = M_o[a, b]
    has_padding = False
    for i in range(n):
        if N[i] < m:
            has_padding = True
    for i in range(n):
        if not cholesky(M[i], L, k):
            return SOLVE_ARM_SINGULAR
        Xi = X[i]
        for a in range(k):
            for s in range(m):
                Xi[a, s] = W[i, a, s]
            Xi[a, m] = h[i, a]
        cholesky_solve(L, Xi, k, m + 1)
        Zi = Z[i]
        for s in range(m):  # [S  Wᵀ M⁻¹ h] = Wᵀ X, inner loop along X's rows
            for t in range(m + 1):
                WX[s, t] = 0.0
            for a in range(k):
                w = W[i, a, s]
                for t in range(m + 1):
                    WX[s, t] += w * Xi[a, t]
        smax = -np.inf
        for s in range(m):
            for t in range(m):
                S[s, t] = WX[s, t]
            Zi[s, 6] = c[i, s] - WX[s, m]  # r_i
            if S[s, s] > smax:
                smax = S[s, s]
        if has_padding:
            if not smax > 0.0:
                smax = 1.0
            for s in range(N[i], m):
                S[s, s] += smax
        if not cholesky(S, LS, m):
            return SOLVE_ARM_SINGULAR
        inverse_diagonal(LS, m, dinv, col)
        worst = 0.0
        for s in range(m):
            if dinv[s] > worst:
                worst = dinv[s]
        if not (smax * worst * rcond_tol <= 1.0):
            return SOLVE_ARM_SINGULAR
        for s in range(m):
            for r in range(6):
                Zi[s, r] = W_o[i, r, s]
        cholesky_solve(LS, Zi, m, np.int64(7))
        for a in range(6):
            for s in range(m):
                w = W_o[i, a, s]
                for b in range(6):
                    A[a, b] += w * Zi[s, b]
                rhs[a] += w * Zi[s, 6]
    LA = np.zeros((6, 6))
    if not cholesky(A, LA, np.int64(6)):
        return SOLVE_OBJECT_SINGULAR
    inv = np.zeros((6, 6))
    for a in range(6):
        inv[a, a] = 1.0
    cholesky_solve(LA, inv, np.int64(6), np.int64(6))
    norm1 = 0.0
    trace = 0.0
    for b in range(6):
        trace += A[b, b]
        colsum = 0.0
        for a in range(6):
            colsum += abs(inv[a, b])
        if colsum > norm1:
            norm1 = colsum
    if not (trace * norm1 * object_rcond_tol <= 1.0):
        return SOLVE_OBJECT_SINGULAR
    total = 0.0
    sol = rhs.reshape((6, 1)).copy()
    cholesky_solve(LA, sol, np.int64(6), np.int64(1))
    for a in range(6):
        a_o[a] = sol[a, 0]
        total += sol[a, 0]
    for i in range(n):
        Zi = Z[i]
        Xi = X[i]
        for s in range(m):
            acc = Zi[s, 6]
            for b in range(6):
                acc -= Zi[s, b] * a_o[b]
            mu[i, s] = acc
            total += acc
        for a in range(k):
            acc = Xi[a, m]
            for s in range(m):
                acc += Xi[a, s] * mu[i, s]
            qdd[i, a] = acc
            total += acc
    if not math.isfinite(total):
        return SOLVE_OBJECT_SINGULAR
    return SOLVE_OK


__all__ = ["SOLVE_ARM_SINGULAR", "SOLVE_OBJECT_SINGULAR", "SOLVE_OK", "object_first"]
