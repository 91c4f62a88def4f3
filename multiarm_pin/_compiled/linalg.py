"""Compiled small dense linear algebra: Cholesky factor, solve, inverse diagonal, batched solve.

Mirrors the LAPACK calls of the numpy references (``dpotrf`` / ``dpotrs`` through
``numpy.linalg.solve`` and :mod:`scipy.linalg.lapack` in
:mod:`multiarm_pin.dynamics.object_first`): the same factorisation, written as plain loops on
the leading ``size`` x ``size`` block of preallocated arrays so that the kernels of
:mod:`multiarm_pin._compiled` call it without allocating. Tested against numpy in
``tests/test_kernels.py``.

Callers pass the sizes as int64 values, never as integer literals (``np.int64(6)``, not
``6``): numba compiles one specialisation per literal value of an argument, and each costs
a compile at the first run (issue 14).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, error_model="numpy")
def cholesky(A, L, size):  # pragma: no cover - compiled
    """Lower Cholesky factor of the leading ``size`` x ``size`` block of ``A`` into ``L``.

    Returns False (``L`` partly written) if a pivot is not positive or not finite.
    """
    for j in range(size):
        s = A[j, j]
        for p in range(j):
            s -= L[j, p] * L[j, p]
        if not (s > 0.0 and s < np.inf):
            return False
        d = math.sqrt(s)
        L[j, j] = d
        for i in range(j + 1, size):
            t = A[i, j]
            for p in range(j):
                t -= L[i, p] * L[j, p]
            L[i, j] = t / d
    return True


@njit(cache=True, error_model="numpy")
def cholesky_solve(L, B, size, ncols):  # pragma: no cover - compiled
    """``B[:size, :ncols] ← A⁻¹ B`` in place, ``A = L Lᵀ`` (L from :func:`cholesky`).

    Row-oriented: the innermost loops run along the right-hand sides, independent of each
    other (no dependency chain; the compiler vectorises them).
    """
    for i in range(size):
        for p in range(i):
            lip = L[i, p]
            for col in range(ncols):
                B[i, col] -= lip * B[p, col]
        d = 1.0 / L[i, i]
        for col in range(ncols):
            B[i, col] *= d
    for i in range(size - 1, -1, -1):
        for p in range(i + 1, size):
            lpi = L[p, i]
            for col in range(ncols):
                B[i, col] -= lpi * B[p, col]
        d = 1.0 / L[i, i]
        for col in range(ncols):
            B[i, col] *= d


@njit(cache=True, error_model="numpy")
def inverse_diagonal(L, size, out, col):  # pragma: no cover - compiled
    """``out[j] = (A⁻¹)_jj`` for ``A = L Lᵀ``: squared column norms of ``L⁻¹``.

    ``col`` is scratch of length ``size``.
    """
    for j in range(size):
        for i in range(size):
            col[i] = 0.0
        col[j] = 1.0 / L[j, j]
        acc = col[j] * col[j]
        for i in range(j + 1, size):
            t = 0.0
            for p in range(j, i):
                t -= L[i, p] * col[p]
            col[i] = t / L[i, i]
            acc += col[i] * col[i]
        out[j] = acc



@njit(cache=True, error_model="numpy")
def batched_spd_solve(A, B):  # pragma: no cover - compiled
    """``A_i⁻¹ B_i`` for a stack of symmetric positive definite ``A`` (n, k, k), ``B`` (n, k, p).

    By :func:`cholesky` and :func:`cholesky_solve` per matrix; the result of a matrix that
    is not positive definite (a pivot not positive or not finite) is NaN, so that the caller
    finds the failed ones with one ``isfinite`` (the contract of ``numpy.linalg.solve``'s
    batched LAPACK gufunc with floating-point errors ignored, on SPD matrices).

    Returns:
        (n, k, p) new array.
    """
    n, k, p = B.shape
    out = np.empty((n, k, p))
    L = np.zeros((k, k))
    for i in range(n):
        ok = cholesky(A[i], L, k)
        for a in range(k):
            for c in range(p):
                out[i, a, c] = B[i, a, c] if ok else np.nan
        if ok:
            cholesky_solve(L, out[i], k, p)
    return out


JACOBI_SWEEPS = 60
"""Sweeps of :func:`singular_values` at the most (a safety cap: about six suffice)."""


@njit(cache=True, error_model="numpy")
def singular_values(A, out):  # pragma: no cover - compiled
    """The singular values of ``A`` (r, c) into ``out`` (c,), by one-sided Jacobi.

    ``A`` is overwritten (its columns made orthogonal). Hestenes' method: plane rotations of
    column pairs until every pair is orthogonal to round-off; the column norms are then the
    singular values (``c - r`` of them zero when ``c > r``), in the columns' order, not
    sorted. Accurate to round-off relative to the
    largest (tested against ``np.linalg.svd``), and without the calls and workspaces of
    LAPACK, which numba's ``np.linalg.svd`` makes at every call.
    """
    r, c = A.shape
    eps = 2.220446049250313e-16
    for _ in range(JACOBI_SWEEPS):
        rotated = False
        for p in range(c - 1):
            for q in range(p + 1, c):
                alpha = 0.0
                beta = 0.0
                gamma = 0.0
                for a in range(r):
                    alpha += A[a, p] * A[a, p]
                    beta += A[a, q] * A[a, q]
                    gamma += A[a, p] * A[a, q]
                if gamma == 0.0 or abs(gamma) <= eps * math.sqrt(alpha * beta):
                    continue
                rotated = True
                diff = beta - alpha
                if abs(gamma) * 1e150 < abs(diff):  # |zeta| > 5e149: t = 1 / (2 zeta) to
                    t = gamma / diff                # round-off, without overflowing zeta
                else:
                    zeta = diff / (2.0 * gamma)
                    t = math.copysign(1.0, zeta) / (abs(zeta) + math.sqrt(1.0 + zeta * zeta))
                cs = 1.0 / math.sqrt(1.0 + t * t)
                sn = cs * t
                for a in range(r):
                    ap, aq = A[a, p], A[a, q]
                    A[a, p] = cs * ap - sn * aq
                    A[a, q] = sn * ap + cs * aq
        if not rotated:
            break
    for j in range(c):
        acc = 0.0
        for a in range(r):
            acc += A[a, j] * A[a, j]
        out[j] = math.sqrt(acc)


__all__ = ["batched_spd_solve", "cholesky", "cholesky_solve", "inverse_diagonal",
           "singular_values"]
