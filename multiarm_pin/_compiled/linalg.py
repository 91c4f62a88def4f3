"""Compiled small dense linear algebra: Cholesky factor and solves, Householder QR, SVD values.

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

from multiarm_pin._compiled.jit import kernel


@kernel
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


@kernel
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


@kernel
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


@kernel
def householder_qr(A, nrows, ncols, beta, diag):  # pragma: no cover - compiled
    """Householder QR of the leading ``nrows`` x ``ncols`` block of ``A``, in place.

    ``A[:nrows, :ncols] = H_0 H_1 ... H_{r-1} R`` with ``r = min(nrows, ncols)`` reflectors
    ``H_j = I - beta[j] v_j v_jᵀ`` (``v_j`` zero above row ``j``) and ``R`` (nrows, ncols)
    upper triangular; ``R[j, j] = -sign(A_jj) ‖A[j:, j]‖`` after the reflectors before it
    (``+`` for a negative entry: no cancellation in ``v_j``'s first entry), LAPACK's
    ``dgeqrf`` sign rule (``np.linalg.qr``'s ``R``), except that ``dgeqrf`` leaves a column
    already zero below the diagonal as it is (the last one of a square or wide block: its row
    of ``R`` has the opposite sign here). A zero column gives ``beta[j] = 0``
    (``H_j = I``) and ``R[j, j] = 0``. Nothing is allocated. The kernel of
    ``controller_kernels.min_norm_rows`` and ``phased.column_least_squares``.

    Args:
        A: (>= nrows, >= ncols) matrix, overwritten in its leading block: ``A[j:nrows, j]``
            holds ``v_j`` (``v_j[j]`` at ``A[j, j]``), ``A[p, t]`` for ``p < t`` holds
            ``R[p, t]``; the rest of ``A`` is not touched.
        nrows: rows of the block (int64).
        ncols: columns of the block (int64); more columns than rows is allowed
            (``r = nrows`` reflectors then).
        beta: output (>= r,) the reflectors' ``2 / ‖v_j‖²``.
        diag: output (>= r,) ``R``'s diagonal.
    """
    for j in range(min(nrows, ncols)):
        norm = 0.0
        for a in range(j, nrows):
            norm += A[a, j] * A[a, j]
        norm = math.sqrt(norm)
        alpha = -norm if A[j, j] >= 0.0 else norm
        v0 = A[j, j] - alpha
        vnorm2 = v0 * v0
        for a in range(j + 1, nrows):
            vnorm2 += A[a, j] * A[a, j]
        A[j, j] = v0
        beta[j] = 2.0 / vnorm2 if vnorm2 > 0.0 else 0.0
        for t in range(j + 1, ncols):  # apply H_j to the columns on the right
            dot = 0.0
            for a in range(j, nrows):
                dot += A[a, j] * A[a, t]
            dot *= beta[j]
            for a in range(j, nrows):
                A[a, t] -= dot * A[a, j]
        diag[j] = alpha


@kernel
def householder_reflect(A, nrows, j, beta, x):  # pragma: no cover - compiled
    """``x[:nrows] ← H_j x[:nrows]``, ``H_j = I - beta[j] v_j v_jᵀ`` of :func:`householder_qr`.

    ``Qᵀ b`` is ``H_{r-1} ... H_0 b`` (``j`` ascending), ``Q y`` is ``H_0 ... H_{r-1} y``
    (``j`` descending); only ``x[j:nrows]`` changes.

    Args:
        A: the factored matrix of :func:`householder_qr` (``v_j`` in ``A[j:nrows, j]``).
        nrows: its block's rows (int64).
        j: the reflector.
        beta: (> j,) the reflectors' ``beta``.
        x: (>= nrows,) vector, overwritten.
    """
    dot = 0.0
    for a in range(j, nrows):
        dot += A[a, j] * x[a]
    dot *= beta[j]
    for a in range(j, nrows):
        x[a] -= dot * A[a, j]


@kernel
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


@kernel
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


@kernel(refcounts=False)
def copy1(dst, src):  # pragma: no cover - compiled
    """``dst[:] = src`` for two vectors of one length, element by element.

    numba's slice assignment compiles its shape checks and their messages at every type.
    """
    for i in range(src.shape[0]):
        dst[i] = src[i]


@kernel(refcounts=False)
def copy2(dst, src):  # pragma: no cover - compiled
    """``dst[:] = src`` for two matrices of one shape, element by element."""
    for i in range(src.shape[0]):
        for j in range(src.shape[1]):
            dst[i, j] = src[i, j]


@kernel
def mat_vec(A, x, out):  # pragma: no cover - compiled
    """``out = A x`` for a matrix ``A`` (r, c) and a vector ``x`` (c,), summed in column order.

    numpy's ``A @ x`` (BLAS, with its shape checks and their messages) compiles for about
    half a second at every type.
    """
    for i in range(A.shape[0]):
        acc = 0.0
        for j in range(A.shape[1]):
            acc += A[i, j] * x[j]
        out[i] = acc


@kernel
def mat_mat(A, B, out):  # pragma: no cover - compiled
    """``out = A B`` for matrices ``A`` (r, s) and ``B`` (s, c) (see :func:`mat_vec`)."""
    for i in range(A.shape[0]):
        for j in range(B.shape[1]):
            acc = 0.0
            for k in range(A.shape[1]):
                acc += A[i, k] * B[k, j]
            out[i, j] = acc


@kernel
def spectral_solve(U, s, Vt, f, tol, out):  # pragma: no cover - compiled
    """``out = Σ_q Vt[q]ᵀ (U[:, q]·f) / s[q]`` over the ``q`` with ``|s[q]| > tol``.

    The pseudo-inverse solve of a factorisation ``A = U diag(s) Vt`` (a thin SVD, or an
    eigendecomposition ``V diag(s) Vᵀ`` with ``Vt = Vᵀ``), the values at or below ``tol``
    (and NaN) dropped.

    Args:
        U: (r, K) left vectors in columns.
        s: (K,) singular values or eigenvalues.
        Vt: (K, c) right vectors in rows.
        f: (r,) right-hand side.
        tol: the largest value dropped.
        out: output (c,).
    """
    for c in range(out.shape[0]):
        out[c] = 0.0
    for q in range(s.shape[0]):
        if abs(s[q]) > tol:
            acc = 0.0
            for a in range(U.shape[0]):
                acc += U[a, q] * f[a]
            acc /= s[q]
            for c in range(out.shape[0]):
                out[c] += Vt[q, c] * acc


__all__ = ["batched_spd_solve", "cholesky", "cholesky_solve", "copy1", "copy2",
           "householder_qr", "householder_reflect", "inverse_diagonal", "mat_mat", "mat_vec",
           "singular_values", "spectral_solve"]
