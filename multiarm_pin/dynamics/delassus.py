"""The Delassus operator of the contact rows, object-first: numpy reference, compiled solve.

With the blocks of :class:`~multiarm_pin.dynamics.blocks.SystemBlocks` the normal
accelerations of the rows are ``φ̈ = G μ + b`` with::

    G = blockdiag_i(W_iᵀ M_i⁻¹ W_i) + W_oᵀ M_o⁻¹ W_o      (per-arm blocks + rank-6 coupling)
    b = W_oᵀ M_o⁻¹ h_o + Wᵀ M⁻¹ h - c                      (φ̈ of the motion with μ = 0)

built arm by arm; the dense ``J M⁻¹ Jᵀ`` over all arms is never formed.
:func:`delassus_operator` is the numpy reference: ``G`` and ``b`` of every real row (one
batched solve with all ``M_i``, one 6 x 6 Cholesky solve for the object).

:func:`contact_kernel` (numba) does the whole unilateral solve in one call: a Cholesky
factorisation of every ``M_i`` and ``X_i = M_i⁻¹ [W_i h_i]``, one 6 x 6 Cholesky solve
``M_o⁻¹ [W_o h_o]`` on the active rows, ``G`` and ``b`` on the active rows only (per-arm
blocks ``W_iᵀ X_i`` plus the object coupling), :func:`~multiarm_pin.dynamics.mlcp.mlcp`, then
``a_o``, ``q̈`` and ``φ̈``. :mod:`multiarm_pin.dynamics.unilateral` calls it and hands the rare
cases it reports (a singular ``M_i``, non-finite values) to the reference, which raises the
documented errors.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.linalg import lapack

from multiarm_pin._compiled import linalg as _kernels
from multiarm_pin.dynamics.blocks import SystemBlocks
from multiarm_pin.dynamics.mlcp import OK, mlcp
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


BAD_MASS, NOT_FINITE, UNI_PADDING, ACT_PADDING = 4, 5, 6, 7
"""Status codes of :func:`contact_kernel` beyond :func:`~multiarm_pin.dynamics.mlcp.mlcp`'s."""


@njit(cache=True, error_model="numpy")
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

