"""The whole unilateral contact solve in one compiled call: Delassus operator, mixed LCP, motion.

The compiled counterpart of :mod:`multiarm_pin.dynamics.delassus` (the same concept, the
Delassus operator of the contact rows built object-first, at the compiled layer):
:func:`contact_kernel` does a Cholesky factorisation of every ``M_i`` and
``X_i = M_i⁻¹ [W_i h_i]``, one 6 x 6 Cholesky solve ``M_o⁻¹ [W_o h_o]`` on the active rows,
``G`` and ``b`` on the active rows only (per-arm blocks ``W_iᵀ X_i`` plus the object
coupling), :func:`~multiarm_pin._compiled.mlcp.mlcp`, then ``a_o``, ``q̈`` and ``φ̈``.
:mod:`multiarm_pin.dynamics.unilateral` calls it and hands the rare cases it reports (a
singular ``M_i``, non-finite values) to the numpy reference, which raises the documented
errors; the compiled contact loop calls it directly.

Twins: ``multiarm_pin.dynamics.delassus`` (the same concept at the dynamics layer: the numpy
reference of the ``G`` and ``b`` this kernel builds).
"""

from __future__ import annotations

import numpy as np

from multiarm_pin._compiled import linalg as _kernels
from multiarm_pin._compiled.jit import kernel
from multiarm_pin._compiled.mlcp import OK, mlcp

BAD_MASS, NOT_FINITE, UNI_PADDING, ACT_PADDING = 4, 5, 6, 7
"""Status codes of :func:`contact_kernel` beyond :func:`~multiarm_pin._compiled.mlcp.mlcp`'s."""


@kernel
def contact_kernel(M, h, W, W_o, c, M_o, h_o, nv, N, uni, act, guess, use_guess, dep_rtol,
                   viol_rtol, cons_rtol, a_o, qdd, mu, Av):  # pragma: no cover - compiled
    """The whole unilateral solve, compiled: object-first Delassus, :func:`mlcp`, motion.

    Per arm a Cholesky factorisation of ``M_i`` and ``X_i = M_i⁻¹ [W_i h_i]``; one 6 x 6
    Cholesky solve ``Y = M_o⁻¹ [W_o,active h_o]``; ``G`` and ``b`` on the active rows only
    (per-arm blocks ``W_iᵀ X_i`` plus the object coupling ``W_oᵀ Y``); the mixed LCP; then
    ``a_o``, ``q̈``, ``μ`` (padded outputs) and ``Av = W_oᵀ a_o + Wᵀ q̈`` on every real row.
    The warm start is every active row, or with ``use_guess`` the active rows that are
    bilateral or in ``guess`` (n, N_max) bool.

    Returns:
        ``(status, pivots, arm, row, value)``: status as :func:`mlcp` (arm and row of the
        offending row, its ``φ``), 4 singular ``M_i`` (arm), 5 non-finite result, 6 / 7
        ``uni`` / ``act`` True on the padding row (arm, row).
    """
    n, k, m = W.shape
    for i in range(n):
        for r in range(N[i], m):
            if uni[i, r]:
                return UNI_PADDING, 0, i, r, 0.0
            if act[i, r]:
                return ACT_PADDING, 0, i, r, 0.0
    P = 0
    for i in range(n):
        for r in range(N[i]):
            if act[i, r]:
                P += 1
    arm_of = np.empty(P, dtype=np.int64)
    row_of = np.empty(P, dtype=np.int64)
    a = 0
    for i in range(n):
        for r in range(N[i]):
            if act[i, r]:
                arm_of[a] = i
                row_of[a] = r
                a += 1
    # per arm: X_i = M_i⁻¹ [W_i h_i] (columns 0..N_i-1 and N_i)
    X = np.zeros((n, k, m + 1))
    L = np.zeros((k, k))
    for i in range(n):
        ni, Ni = nv[i], N[i]
        if ni == 0:
            continue
        if not _kernels.cholesky(M[i], L, ni):
            return BAD_MASS, 0, i, -1, 0.0
        Xi = X[i]
        for j in range(ni):
            for r in range(Ni):
                Xi[j, r] = W[i, j, r]
            Xi[j, Ni] = h[i, j]
        _kernels.cholesky_solve(L, Xi, ni, Ni + 1)
    # object: Y = M_o⁻¹ [W_o of the active rows, h_o]
    Lo = np.zeros((6, 6))
    if not _kernels.cholesky(M_o, Lo, np.int64(6)):
        return NOT_FINITE, 0, -1, -1, 0.0
    Y = np.zeros((6, P + 1))
    for a in range(P):
        for r in range(6):
            Y[r, a] = W_o[arm_of[a], r, row_of[a]]
    for r in range(6):
        Y[r, P] = h_o[r]
    _kernels.cholesky_solve(Lo, Y, np.int64(6), P + 1)
    # Delassus operator and free normal accelerations of the active rows
    G = np.zeros((P, P))
    bvec = np.zeros(P)
    for a in range(P):
        ia, ra = arm_of[a], row_of[a]
        for bb in range(a, P):
            ib, rb = arm_of[bb], row_of[bb]
            g = 0.0
            for r in range(6):
                g += W_o[ia, r, ra] * Y[r, bb]
            if ia == ib:
                for j in range(nv[ia]):
                    g += W[ia, j, ra] * X[ia, j, rb]
            G[a, bb] = g
        t = -c[ia, ra]
        for r in range(6):
            t += W_o[ia, r, ra] * Y[r, P]
        for j in range(nv[ia]):
            t += W[ia, j, ra] * X[ia, j, N[ia]]
        bvec[a] = t
    for a in range(P):
        for bb in range(a):
            G[a, bb] = G[bb, a]
    scale = 0.0
    for a in range(P):
        scale = max(scale, abs(bvec[a]))
    if not (scale < np.inf):
        return NOT_FINITE, 0, -1, -1, 0.0
    uni_a = np.empty(P, dtype=np.bool_)
    start = np.empty(P, dtype=np.bool_)
    for a in range(P):
        uni_a[a] = uni[arm_of[a], row_of[a]]
        start[a] = (guess[arm_of[a], row_of[a]] or not uni_a[a]) if use_guess else True
    mu_a = np.empty(P)
    phi = np.empty(P)
    in_a = np.empty(P, dtype=np.bool_)
    status, pivots, q = mlcp(G, bvec, uni_a, dep_rtol, viol_rtol * scale, cons_rtol * scale,
                              1000 + 20 * P, start, mu_a, phi, in_a)
    if status != OK:
        return status, pivots, arm_of[q], row_of[q], phi[q]
    # motion
    for i in range(n):
        for r in range(m):
            mu[i, r] = 0.0
    for a in range(P):
        mu[arm_of[a], row_of[a]] = mu_a[a]
    for r in range(6):
        t = Y[r, P]
        for a in range(P):
            t += Y[r, a] * mu_a[a]
        a_o[r] = t
    ok = True
    for i in range(n):
        ni, Ni = nv[i], N[i]
        for j in range(k):
            qdd[i, j] = 0.0
        for j in range(ni):
            t = X[i, j, Ni]
            for r in range(Ni):
                t += X[i, j, r] * mu[i, r]
            qdd[i, j] = t
        for r in range(m):
            Av[i, r] = 0.0
        for r in range(Ni):
            t = 0.0
            for s in range(6):
                t += W_o[i, s, r] * a_o[s]
            for j in range(ni):
                t += W[i, j, r] * qdd[i, j]
            Av[i, r] = t
            if not (abs(t) < np.inf):
                ok = False
    if not ok:
        return NOT_FINITE, pivots, -1, -1, 0.0
    return OK, pivots, -1, -1, 0.0


__all__ = ["ACT_PADDING", "BAD_MASS", "NOT_FINITE", "UNI_PADDING", "contact_kernel"]
