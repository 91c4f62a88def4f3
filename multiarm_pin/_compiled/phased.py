"""Compiled ``phased_pd``: its reference, its supported force distribution and its torques.

The compiled counterpart of :mod:`multiarm_pin.sim.controllers.phased` (the same concept at
the compiled layer; that module's ``PhasedPD.reference`` is the oracle, and it packs the
arrays read here). :func:`phased_torques` computes, from the flat buffer of one evaluation
(:mod:`multiarm_pin._compiled.evaluate`, blocks at zero torque) and the support rows:

1. the phase at ``t`` and its minimum-jerk reference (``tilt`` about a pivot, ``move``,
   ``hold``), the PD on the object pose (:func:`~multiarm_pin._compiled.controller_kernels.
   desired_acceleration`), and the held points' offsets of the phases started;
2. the engaged rows (touching and not released), compacted to the front of each arm as
   ``restrict_rows`` does;
3. ``distribute_with_supports``: the pressing support rows' acceleration projection
   (``a - M_o⁻¹ Gᵀ (G M_o⁻¹ Gᵀ)⁺ (G a + κ)``), the part of ``w = M_o a - h_o`` in the range
   of ``W = [W_o (arms) | G_Pᵀ]`` closest in the ``M_o⁻¹`` metric, and the least-norm
   multipliers with per-multiplier margins (:func:`min_norm_forces`, the reference's method:
   least-distance programming by NNLS on the SVD null space of ``W``, then its polish);
4. the held points' tasks and the inverse dynamics on the engaged rows
   (:func:`~multiarm_pin._compiled.controller_kernels.planned_torques`).

When no forces meet the margins (decided by the reference's own test on the least-distance
problem) the forces are planned again with zero margins and, if no pushing forces make the
wrench, with the reference's best effort (its bounded least squares, ``lsq_linear``, here
NNLS on the shifted forces: every multiplier is unilateral then, or the kernel declines).
Whatever this kernel cannot decide as the reference does is reported, and the caller runs the
reference: a bilateral multiplier in the best effort, NNLS not converged, an arm whose rows
are rank deficient (the reference's inverse dynamics decides, or holds the arms
still), NaN, an orientation error near π. Conventions as in ``docs/ARCHITECTURE.md``.

Twins: ``multiarm_pin.sim.controllers.phased`` (the same concept, the ``phased_pd`` controller,
at the sim layer: its ``PhasedPD`` packs the phases as arrays, calls :func:`phased_torques` and
holds the reference that decides what this kernel reports).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from multiarm_pin._compiled.controller_kernels import (
    PD_ARM_RANK,
    PD_FORCES_FAILED,
    PD_LARGE_ROTATION,
    PD_NOT_FINITE,
    PD_OK,
    desired_acceleration,
    planned_torques,
)
from multiarm_pin._compiled.evaluate import _arm_segments, _block_segments
from multiarm_pin._compiled.function_pointers import Compile, compile_of
from multiarm_pin._compiled.jit import kernel
from multiarm_pin._compiled.layout import (
    DIMS_K,
    DIMS_M,
    DIMS_N,
    OX_TWIST,
    PH_ANGLE,
    PH_AXIS,
    PH_DISPLACEMENT,
    PH_DURATION,
    PH_KIND,
    PH_PIVOT,
    PH_START_POSITION,
    PH_START_ROTATION,
    PH_SUPPORT_MARGIN,
    PH_T,
    PHASE_MOVE,
    PHASE_TILT,
    REF_ACCELERATION,
    REF_POSITION,
    REF_ROTATION,
    REF_TWIST,
    REFERENCE_SIZE,
    offsets,
)
from multiarm_pin._compiled.linalg import (
    cholesky,
    cholesky_solve,
    copy1,
    copy2,
    householder_qr,
    householder_reflect,
    mat_mat,
    mat_vec,
    spectral_solve,
)
from multiarm_pin._compiled.trajectory import exp3

PRESSING_GAP = 1e-6
"""[m] A support row planned to press is planned only while its gap is below this (the value
of ``multiarm_pin.sim.controllers.phased.PRESSING_GAP``, which a test checks)."""

RANK_TOL = 1e-10
"""Relative singular value below which ``W`` has no range (the value of
``multiarm_pin.dynamics.inverse_dynamics.RANK_TOL``, the reference's rank of ``W``)."""

BEST_EFFORT_SLACK = 1e-7
"""``dynamics.force_distribution.BEST_EFFORT_SLACK``: the relative relaxation of the margins in
the best-effort distribution's minimum-norm step."""
PINV_RCOND = 1e-12
"""``rcond`` of the pseudo-inverse of ``G M_o⁻¹ Gᵀ`` (the reference's ``np.linalg.pinv``)."""


@kernel
def minimum_jerk(tau):  # pragma: no cover - compiled
    """``(s, ds/dτ, d²s/dτ²)`` of the minimum-jerk profile at ``τ`` clipped to [0, 1]."""
    t = min(max(tau, 0.0), 1.0)
    t2 = t * t
    return (t2 * t * (10.0 - 15.0 * t + 6.0 * t2), 30.0 * t2 * (1.0 - 2.0 * t + t2),
            60.0 * t * (1.0 - 3.0 * t + 2.0 * t2))


@kernel
def phase_index(t, phases):  # pragma: no cover - compiled
    """Index of the phase at ``t``: the last one started (0 before the first)."""
    k = 0
    for i in range(phases.shape[0]):
        if t >= phases[i, PH_T]:
            k = i
    return k


@kernel
def phase_reference(t, phases, ref):  # pragma: no cover - compiled
    """The reference pose, twist and acceleration at ``t`` into ``ref`` (REFERENCE_FIELDS).

    ``PhasedPD.reference_pose``: the motion of the phase at ``t`` applied to its start pose,
    minimum-jerk over its duration, held after it (and before the first phase).

    Args:
        t: time [s].
        phases: (P, PHASE_SIZE) the phase table (``PHASE_FIELDS``).
        ref: output (REFERENCE_SIZE,).
    """
    k = phase_index(t, phases)
    t0, dur = phases[k, PH_T], phases[k, PH_DURATION]
    if t < t0:
        s, ds, dds = 0.0, 0.0, 0.0
    else:
        s, ds1, dds1 = minimum_jerk((t - t0) / dur)
        ds, dds = ds1 / dur, dds1 / dur ** 2
        if t > t0 + dur:
            ds = dds = 0.0
    kind = int(phases[k, PH_KIND])
    p0 = phases[k, PH_START_POSITION:PH_START_POSITION + 3]
    R0 = phases[k, PH_START_ROTATION:PH_START_ROTATION + 9]
    for a in range(REFERENCE_SIZE):
        ref[a] = 0.0
    for a in range(3):
        ref[REF_POSITION + a] = p0[a]
    for a in range(9):
        ref[REF_ROTATION + a] = R0[a]
    if kind == PHASE_TILT:
        ax = phases[k, PH_AXIS:PH_AXIS + 3]
        ang = phases[k, PH_ANGLE]
        piv = phases[k, PH_PIVOT:PH_PIVOT + 3]
        Rk = np.empty((3, 3))
        exp3(ax[0] * (ang * s), ax[1] * (ang * s), ax[2] * (ang * s), Rk)
        r = np.empty(3)
        w = np.empty(3)
        al = np.empty(3)
        for a in range(3):
            r[a] = (Rk[a, 0] * (p0[0] - piv[0]) + Rk[a, 1] * (p0[1] - piv[1])
                    + Rk[a, 2] * (p0[2] - piv[2]))
            w[a] = ax[a] * (ang * ds)
            al[a] = ax[a] * (ang * dds)
        v = np.empty(3)
        v[0] = w[1] * r[2] - w[2] * r[1]
        v[1] = w[2] * r[0] - w[0] * r[2]
        v[2] = w[0] * r[1] - w[1] * r[0]
        ref[REF_ACCELERATION + 0] = (al[1] * r[2] - al[2] * r[1]) + (w[1] * v[2] - w[2] * v[1])
        ref[REF_ACCELERATION + 1] = (al[2] * r[0] - al[0] * r[2]) + (w[2] * v[0] - w[0] * v[2])
        ref[REF_ACCELERATION + 2] = (al[0] * r[1] - al[1] * r[0]) + (w[0] * v[1] - w[1] * v[0])
        for a in range(3):
            ref[REF_POSITION + a] = piv[a] + r[a]
            ref[REF_TWIST + a] = v[a]
            ref[REF_TWIST + 3 + a] = w[a]
            ref[REF_ACCELERATION + 3 + a] = al[a]
            for b in range(3):
                ref[REF_ROTATION + 3 * a + b] = (Rk[a, 0] * R0[b] + Rk[a, 1] * R0[3 + b]
                                                 + Rk[a, 2] * R0[6 + b])
    elif kind == PHASE_MOVE:
        d = phases[k, PH_DISPLACEMENT:PH_DISPLACEMENT + 3]
        for a in range(3):
            ref[REF_POSITION + a] = p0[a] + s * d[a]
            ref[REF_TWIST + a] = ds * d[a]
            ref[REF_ACCELERATION + a] = dds * d[a]


@kernel
def phase_offsets(t, phases, named, offs, offset_start, out):  # pragma: no cover - compiled
    """(n, 3) object-frame offsets [m] of each arm's held points at ``t`` into ``out``.

    ``PhasedPD.offsets``: from ``offset_start``, each phase started moves the offsets of the
    arms it names toward its own, minimum-jerk over its duration.

    Args:
        t: time [s].
        phases: (P, PHASE_SIZE) the phase table.
        named: (P, n) bool, the arms whose offsets each phase sets.
        offs: (P, n, 3) those offsets [m] (object frame).
        offset_start: (n, 3) the offsets before the first phase.
        out: output (n, 3).
    """
    n = out.shape[0]
    for i in range(n):
        for a in range(3):
            out[i, a] = offset_start[i, a]
    for p in range(phases.shape[0]):
        if t < phases[p, PH_T]:
            break
        s = minimum_jerk((t - phases[p, PH_T]) / phases[p, PH_DURATION])[0]
        for i in range(n):
            if named[p, i]:
                for a in range(3):
                    out[i, a] = out[i, a] + s * (offs[p, i, a] - out[i, a])


@kernel
def column_least_squares(E, cols, n, f, out):  # pragma: no cover - compiled
    """``out[:n] = argmin ‖E[:, cols[:n]] x - f‖`` by Householder QR (no allocation by LAPACK).

    For the passive columns of :func:`nnls` (linearly independent by construction); when a
    column is dependent on the ones before it (``|R_jj|`` at round-off of the largest), or
    there are more columns than rows, the minimum-norm solution of ``np.linalg.lstsq``
    (its rank, by one SVD) decides instead. The QR is
    :func:`~multiarm_pin._compiled.linalg.householder_qr` on a copy of the columns.

    Args:
        E: (p, q) matrix.
        cols: (>= n,) int, the columns used, in order.
        n: how many.
        f: (p,) right-hand side.
        out: output (>= n,).
    """
    p = E.shape[0]
    A = np.empty((p, n))
    for c in range(n):
        for a in range(p):
            A[a, c] = E[a, cols[c]]
    b = f.copy()
    r = min(n, p)
    beta = np.empty(r)
    diag = np.empty(r)
    householder_qr(A, p, n, beta, diag)
    for j in range(r):  # b ← Qᵀ b
        householder_reflect(A, p, j, beta, b)
    rmax = 0.0
    for j in range(r):
        rmax = max(rmax, abs(diag[j]))
    eps = np.finfo(np.float64).eps
    ok = n <= p
    for j in range(r):
        if not abs(diag[j]) > 10.0 * eps * max(p, n) * rmax:
            ok = False
    if not ok:
        # lstsq's minimum-norm solution at its rank (singular values above eps max(p, n) of
        # the largest) by one thin SVD: out = V Σ⁺ Uᵀ f (np.linalg.lstsq gives the same to
        # round-off, and compiles for seconds)
        Ep = np.empty((p, n))
        for c in range(n):
            for a in range(p):
                Ep[a, c] = E[a, cols[c]]
        U, sv, Vt = np.linalg.svd(Ep, full_matrices=False)
        spectral_solve(U, sv, Vt, f, eps * max(p, n) * sv[0], out[:n])
        return
    for j in range(n - 1, -1, -1):
        acc = b[j]
        for c in range(j + 1, n):
            acc -= A[j, c] * out[c]  # R[j, c] (j < c) is stored above the diagonal
        out[j] = acc / diag[j]


@kernel
def nnls(E, f, max_iter, u):  # pragma: no cover - compiled
    """``u = argmin_{u >= 0} ‖E u - f‖`` (Lawson & Hanson's active-set method) into ``u``.

    Args:
        E: (p, q) matrix.
        f: (p,) right-hand side.
        max_iter: cap on the outer iterations.
        u: output (q,).

    Returns:
        True when it converged (no positive gradient component on the bound variables).
    """
    p, q = E.shape
    enorm = 0.0
    for a in range(p):
        for j in range(q):
            enorm = max(enorm, abs(E[a, j]))
    tol = 10.0 * max(p, q) * np.finfo(np.float64).eps * max(enorm, 1e-300)
    passive = np.zeros(q, dtype=np.bool_)
    for j in range(q):
        u[j] = 0.0
    resid = f.copy()
    s = np.zeros(q)
    cols = np.empty(q, dtype=np.int64)
    sp = np.empty(q)
    for _ in range(max_iter):
        best, jb = tol, -1
        for j in range(q):
            if passive[j]:
                continue
            g = 0.0
            for a in range(p):
                g += E[a, j] * resid[a]
            if g > best:
                best, jb = g, j
        if jb < 0:
            return True
        passive[jb] = True
        for _inner in range(3 * q + 3):
            npass = 0
            for j in range(q):
                if passive[j]:
                    cols[npass] = j
                    npass += 1
            column_least_squares(E, cols, npass, f, sp)
            for j in range(q):
                s[j] = 0.0
            low = False
            for c in range(npass):
                s[cols[c]] = sp[c]
                if sp[c] <= 0.0:
                    low = True
            if not low:
                break
            alpha = 1.0
            for c in range(npass):
                j = cols[c]
                if s[j] <= 0.0:
                    alpha = min(alpha, u[j] / (u[j] - s[j]))
            for j in range(q):
                u[j] += alpha * (s[j] - u[j])
                if passive[j] and u[j] <= tol:
                    passive[j] = False
                    u[j] = 0.0
        for j in range(q):
            u[j] = s[j] if passive[j] else 0.0
        for a in range(p):
            acc = f[a]
            for j in range(q):
                acc -= E[a, j] * u[j]
            resid[a] = acc
    return False


@kernel
def min_norm_forces(W, w, unilateral, margins, mu):  # pragma: no cover - compiled
    """``dynamics.force_distribution.min_norm_forces`` (per-multiplier margins) into ``mu``.

    ``min ‖μ‖²`` with ``W μ = w`` (``w`` in the range of ``W``) and ``μ_j >= m_j`` on the
    unilateral multipliers, as the reference solves it: ``μ = W⁺ w + A z`` with ``A`` the SVD
    basis of the null space of ``W`` (rank at :data:`RANK_TOL`), the least-distance problem
    ``min ‖z‖, G z >= g`` by NNLS (Lawson & Hanson ch. 23), infeasible when the residual's last
    component is above ``-1e-12``, then the reference's polish on the active set.

    Args:
        W: (6, C) columns.
        w: (6,) the wrench.
        unilateral: (C,) bool.
        margins: (C,) least values (0 where not unilateral).
        mu: output (C,).

    Returns:
        True, or False where the reference raises (no forces meet the margins) or NNLS did
        not converge.
    """
    C = W.shape[1]
    # full_matrices given as a bool, as this module's thin SVDs give it: one numba compile of
    # np.linalg.svd serves every call
    U, sv, Vt = np.linalg.svd(W, full_matrices=True)
    rank = 0
    if sv.shape[0] and sv[0] > 0.0:
        for p in range(sv.shape[0]):
            if sv[p] > RANK_TOL * sv[0]:
                rank += 1
    # μ_p = W⁺ w
    y = np.zeros(6)
    for p in range(rank):
        acc = 0.0
        for a in range(6):
            acc += U[a, p] * w[a]
        y[p] = acc / sv[p]
    mu_p = np.zeros(C)
    for j in range(C):
        acc = 0.0
        for p in range(rank):
            acc += Vt[p, j] * y[p]
        mu_p[j] = acc
    nu = 0
    m_max = 0.0
    for j in range(C):
        if unilateral[j]:
            nu += 1
            m_max = max(m_max, margins[j])
    if nu == 0:
        copy1(mu, mu_p)
        return True
    tol = 1e-9
    scale = 1e-12
    for j in range(C):
        scale = max(scale, abs(mu_p[j]))
    scale = max(scale, m_max)
    k = C - rank
    idx = np.empty(nu, dtype=np.int64)
    c = 0
    for j in range(C):
        if unilateral[j]:
            idx[c] = j
            c += 1
    if k == 0:
        for c in range(nu):
            j = idx[c]
            if margins[j] - mu_p[j] > tol * scale:
                return False
        copy1(mu, mu_p)
        return True
    # E = [Gᵀ; gᵀ], G = A[idx], g = m - μ_p[idx]; A = Vt[rank:]ᵀ
    E = np.empty((k + 1, nu))
    for c in range(nu):
        j = idx[c]
        for r in range(k):
            E[r, c] = Vt[rank + r, j]
        E[k, c] = margins[j] - mu_p[j]
    f = np.zeros(k + 1)
    f[k] = 1.0
    u = np.empty(nu)
    if not nnls(E, f, 50 * (k + 1 + nu), u):
        return False
    rho = np.empty(k + 1)
    mat_vec(E, u, rho)
    for r in range(k + 1):
        rho[r] -= f[r]
    if -rho[k] <= 1e-12:
        return False
    for j in range(C):
        acc = mu_p[j]
        for r in range(k):
            acc += Vt[rank + r, j] * (-rho[r] / rho[k])
        mu[j] = acc
    for c in range(nu):
        j = idx[c]
        if mu[j] < margins[j] - tol * scale:
            return False
    polish(W, w, unilateral, margins, mu)
    return True


@kernel
def polish(W, w, unilateral, margins, mu):  # pragma: no cover - compiled
    """The reference's ``_polish``: the exact minimiser on the active set of ``mu``, if optimal.

    The unilateral multipliers at their margin (to 1e-9 relative) are held there; the others
    are the minimum-norm solution of ``W_F μ_F = w - W_A m_A``; kept (written into ``mu``)
    when ``W_F`` has rank 6 and the result is primal and dual feasible to 1e-9 relative.
    """
    C = W.shape[1]
    sc = 1e-300
    for j in range(C):
        sc = max(sc, abs(mu[j]), margins[j])
    act = np.zeros(C, dtype=np.bool_)
    nf = 0
    for j in range(C):
        act[j] = unilateral[j] and mu[j] <= margins[j] + 1e-9 * sc
        if not act[j]:
            nf += 1
    Wf = np.empty((6, nf))
    rhs = w.copy()
    c = 0
    for j in range(C):
        if act[j]:
            for a in range(6):
                rhs[a] -= W[a, j] * margins[j]
        else:
            for a in range(6):
                Wf[a, c] = W[a, j]
            c += 1
    if nf < 6:
        return
    # lstsq's minimum-norm solution and rank (rcond eps max(6, nf)) by one thin SVD:
    # y = V Σ⁻¹ Uᵀ rhs; λ = lstsq(W_Fᵀ, y) = U Σ⁻¹ Vᵀ y (rank 6)
    U, sv, Vt = np.linalg.svd(Wf, full_matrices=False)
    eps = np.finfo(np.float64).eps
    for a in range(6):
        if not sv[a] > eps * max(6, nf) * sv[0]:
            return
    g = np.empty(6)
    for a in range(6):
        acc = 0.0
        for c in range(6):
            acc += U[c, a] * rhs[c]
        g[a] = acc / sv[a]
    y = np.zeros(nf)
    for j in range(nf):
        acc = 0.0
        for a in range(6):
            acc += Vt[a, j] * g[a]
        y[j] = acc
    lam = np.zeros(6)
    for a in range(6):
        acc = 0.0
        for j in range(nf):
            acc += Vt[a, j] * y[j]
        acc /= sv[a]
        for c in range(6):
            lam[c] += U[c, a] * acc
    out = np.empty(C)
    c = 0
    for j in range(C):
        if act[j]:
            out[j] = margins[j]
        else:
            out[j] = y[c]
            c += 1
    tol = 1e-9 * sc
    for a in range(6):
        acc = -w[a]
        for j in range(C):
            acc += W[a, j] * out[j]
        if abs(acc) > tol:
            return
    for j in range(C):
        if unilateral[j] and out[j] < margins[j] - tol:
            return
        if act[j]:
            nu = margins[j]
            for a in range(6):
                nu -= W[a, j] * lam[a]
            if nu < -tol:
                return
    copy1(mu, out)


@kernel
def supported_distribution(M_o, h_o, a_d, W, cols, G, kappa, unilateral, margins, mu, a_o,
                           best_effort):  # pragma: no cover - compiled
    """``distribute_with_supports``: ``a_o`` and the multipliers.

    Args:
        M_o: (6, 6) object inertia at the COM, world axes.
        h_o: (6,) object bias wrench (``M_o a_o = h_o + W μ``).
        a_d: (6,) desired object acceleration.
        W: (6, C) the arms' engaged columns (``W_o``) then the pressing support rows' ``Gᵀ``
            (the first ``cols`` used).
        cols: columns used; the last ``G.shape[0]`` of them are the supports'.
        G: (P, 6) the pressing support rows ``[n; r × n]``.
        kappa: (P,) their velocity-product terms [m/s²].
        unilateral: (C,) bool.
        margins: (C,) least pushes [N].
        mu: output (C,) multipliers [N] (arms' then supports').
        a_o: output (6,) the object acceleration these forces give.
        best_effort: when no forces meet the margins, the reference's ``best_effort``: the
            forces ``x >= margins`` whose wrench is closest to ``w`` in the ``M_o⁻¹`` metric
            (a bounded least squares: NNLS on ``x - margins``, every multiplier being
            unilateral here; with a bilateral one it returns False), then the smallest
            forces making that wrench; the rest of ``w`` is left to the motion.

    Returns:
        True, or False when no forces meet the margins (without ``best_effort``) or the
        solve failed (the caller uses the reference).
    """
    P = G.shape[0]
    a = a_d.copy()
    # M_o⁻¹ by its Cholesky factor (M_o is symmetric positive definite; numpy's solve, which
    # the reference calls, gives the same to round-off, and compiles several times longer)
    L = np.empty((6, 6))
    if not cholesky(M_o, L, 6):
        return False
    step = np.empty((6, 1))
    if P:
        Minv_Gt = np.empty((6, P))
        copy2(Minv_Gt, G.T)
        cholesky_solve(L, Minv_Gt, 6, P)
        GMG = np.empty((P, P))
        mat_mat(G, Minv_Gt, GMG)
        rhs = np.empty(P)
        mat_vec(G, a_d, rhs)
        for p in range(P):
            rhs[p] += kappa[p]
        # (G M_o⁻¹ Gᵀ)⁺ rhs: the pseudo-inverse of the symmetric positive semi-definite
        # matrix by its eigenvalues (its singular values), those above PINV_RCOND of the
        # largest kept, as np.linalg.pinv decides
        lev, LV = np.linalg.eigh(GMG)
        top = 0.0
        for p in range(P):
            top = max(top, abs(lev[p]))
        lam = np.empty(P)
        spectral_solve(LV, lev, LV.T, rhs, PINV_RCOND * top, lam)
        mat_vec(Minv_Gt, lam, a)
        for i in range(6):
            a[i] = a_d[i] - a[i]
    w = np.empty(6)
    mat_vec(M_o, a, w)
    for i in range(6):
        w[i] -= h_o[i]
    wr = np.zeros(6)
    Wc = np.empty((6, cols))
    copy2(Wc, W[:, :cols])
    ev, V = np.linalg.eigh(M_o)
    S = np.empty((6, 6))
    for i in range(6):
        for j in range(6):
            acc = 0.0
            for p in range(6):
                acc += V[i, p] * V[j, p] / math.sqrt(ev[p])
            S[i, j] = acc
    SW = np.empty((6, cols))
    mat_mat(S, Wc, SW)
    Sw = np.empty(6)
    mat_vec(S, w, Sw)
    if cols:
        # lstsq's W x = M_o^{1/2} P S w, P the projector on the range of S W at lstsq's
        # rank (singular values above eps max(6, C) of the largest): one thin SVD
        U, sv, _ = np.linalg.svd(SW, full_matrices=False)
        eps = np.finfo(np.float64).eps
        Pw = np.zeros(6)
        for p in range(sv.shape[0]):
            if sv[p] > eps * max(6, cols) * sv[0]:
                acc = 0.0
                for i in range(6):
                    acc += U[i, p] * Sw[i]
                for i in range(6):
                    Pw[i] += acc * U[i, p]
        for i in range(6):  # M_o^{1/2} = V diag(√ev) Vᵀ
            acc = 0.0
            for j in range(6):
                root = 0.0
                for p in range(6):
                    root += V[i, p] * V[j, p] * math.sqrt(ev[p])
                acc += root * Pw[j]
            wr[i] = acc
    unreached = w - wr
    for i in range(6):
        step[i, 0] = unreached[i]
    cholesky_solve(L, step, 6, 1)
    for i in range(6):
        a_o[i] = a[i] - step[i, 0]
    if not cols:
        return True
    uni, marg, x = unilateral[:cols], margins[:cols], mu[:cols]
    if min_norm_forces(Wc, wr, uni, marg, x):
        return True
    if not best_effort:
        return False
    for j in range(cols):
        if not uni[j]:
            return False  # a bilateral multiplier: not a shifted NNLS (the reference decides)
    # lsq_linear(S W, S w, bounds=(margins, inf)): y = x - margins >= 0 minimises
    # ‖S W y - (S w - S W margins)‖
    f = np.empty(6)
    mat_vec(SW, marg, f)
    for i in range(6):
        f[i] = Sw[i] - f[i]
    y = np.empty(cols)
    if not nnls(SW, f, 50 * (6 + cols), y):
        return False
    for j in range(cols):
        y[j] += marg[j]
    wx = np.empty(6)
    mat_vec(Wc, y, wx)
    # the smallest such forces making that wrench (the bounded least squares leaves the
    # internal forces arbitrary), the margins relaxed by BEST_EFFORT_SLACK of the wrench's scale
    # as the reference does (y is strictly feasible then); y itself where that solve fails
    scale = 1e-12  # of the wrench, which is unique (y is not)
    for i in range(6):
        scale = max(scale, abs(wx[i]))
    for j in range(cols):
        scale = max(scale, marg[j])
    relaxed = np.zeros(cols)
    for j in range(cols):
        if uni[j]:
            relaxed[j] = marg[j] - BEST_EFFORT_SLACK * scale
    if not min_norm_forces(Wc, wx, uni, relaxed, x):
        copy1(x, y)
    for j in range(cols):  # back onto the margins (the reference's clip)
        if uni[j] and x[j] < marg[j]:
            x[j] = marg[j]
    mat_vec(Wc, x, unreached)
    for i in range(6):
        unreached[i] = w[i] - unreached[i]
    for i in range(6):
        step[i, 0] = unreached[i]
    cholesky_solve(L, step, 6, 1)
    for i in range(6):
        a_o[i] = a[i] - step[i, 0]
    return True


@kernel
def phased_torques(t, buf, dims, N, nv_arm, unilateral, active, obj, G_sup, kappa_sup, phi_sup,
                   phases, press, release, named, offs, margins, offset_start, pd_gains, z,
                   hold_tool, grasp_obj, hold_n, gains, tau, mu, lam, qdd, a_pts,
                   a_d, a_o, distribute, plan):  # pragma: no cover - compiled
    """``PhasedPD`` torques at ``t`` from the flat buffer and the support rows (see the module).

    Args:
        t: time [s].
        buf: the flat buffer (blocks at zero torque, ``h = -nle``).
        dims: (DIMS_SIZE,) int ``(k, m, nv, n)``.
        N: (n,) int constraint rows per arm.
        nv_arm: (n,) int joints per arm.
        unilateral: (n, m) bool mask of the unilateral rows.
        active: (n, m) bool, the arms' rows that touch.
        obj: (OBJECT_STATE_SIZE,) object position, quaternion ``[x, y, z, w]``, twist.
        G_sup: (K, 6) every support row ``[n; r × n]`` at the COM, world axes.
        kappa_sup: (K,) their velocity-product terms [m/s²].
        phi_sup: (K,) their gaps [m].
        phases: (P, PHASE_SIZE) the phase table (``PHASE_FIELDS``).
        press: (P, K) bool, the support rows each phase keeps pressing.
        release: (P, n) bool, the arms each phase releases.
        named: (P, n) bool, the arms whose offsets each phase sets.
        offs: (P, n, 3) those offsets [m], object frame.
        margins: (P, n, m) least push [N] of each arm row in each phase (0 on loose rows).
        offset_start: (n, 3) the offsets before the first phase [m].
        pd_gains: (PD_GAINS_SIZE,) ``K_p``, ``K_d``.
        z: (n, k) joint-space PD ``null_kp (q_ref ⊖ q) - null_kd v`` [rad/s²].
        hold_tool: (n, h, 3) held points in the tool frame [m].
        grasp_obj: (n, h, 3) their grasp places in the object frame [m] (offsets added here).
        hold_n: (n,) int held points per arm.
        gains: (HOLD_GAINS_SIZE,) ``hold_kp``, ``hold_kd``, Jacobian damping (margin unread).
        tau: output (n, k) torques [N m] to add to ``h``.
        mu: output (n, m) planned arm multipliers [N] (0 on rows not engaged).
        lam: output (K,) planned support forces [N] (0 on rows not pressing).
        qdd: output (n, k) planned joint accelerations.
        a_pts: output (n, h, 3) desired point accelerations [m/s²].
        a_d: output (6,) desired object acceleration.
        a_o: output (6,) the planned object acceleration (``SupportedDistribution.a_o``).
        distribute: :func:`supported_distribution`, or its first-class function.
        plan: :func:`~multiarm_pin._compiled.controller_kernels.planned_torques`, or its
            first-class function. A compiled loop passes both by address
            (:mod:`~multiarm_pin._compiled.function_pointers`): each is then compiled once, on
            its own, and not again inside this kernel.

    Returns:
        ``(status, margin_kept)``: :data:`PD_OK` or the reason the caller must use the
        reference (outputs then meaningless); False when no forces keep the margins and the
        forces were planned with zero margins (the reference's first fallback:
        ``PhasedPD.margin_kept``). Where zero margins fail too the reference decides (its
        bounded least squares, :data:`PD_FORCES_FAILED`).
    """
    k, m, n = dims[DIMS_K], dims[DIMS_M], dims[DIMS_N]
    off = offsets(dims)
    M, _, J, Jdq, tp, tR, ttw, _ = _arm_segments(buf, off, n, k, m)
    _, h, W, W_o, c, M_o, h_o = _block_segments(buf, off, n, k, m)
    ph = phase_index(t, phases)
    ref = np.empty(REFERENCE_SIZE)
    phase_reference(t, phases, ref)
    obj_x = np.empty(OX_TWIST + 6)
    if not desired_acceleration(obj, ref, pd_gains, obj_x, a_d):
        return PD_LARGE_ROTATION, True
    off3 = np.empty((n, 3))
    phase_offsets(t, phases, named, offs, offset_start, off3)
    hold_obj = grasp_obj.copy()
    for i in range(n):
        for p in range(hold_n[i]):
            for a in range(3):
                hold_obj[i, p, a] = grasp_obj[i, p, a] + off3[i, a]
    # the engaged rows, compacted to the front of each arm (restrict_rows)
    W_r = np.zeros((n, k, m))
    W_o_r = np.zeros((n, 6, m))
    c_r = np.zeros((n, m))
    N_r = np.zeros(n, dtype=np.int64)
    index = np.zeros((n, m), dtype=np.int64)
    K = G_sup.shape[0]
    C = n * m + K
    Wall = np.zeros((6, max(C, 1)))
    uni = np.zeros(max(C, 1), dtype=np.bool_)
    marg = np.zeros(max(C, 1))
    cols = 0
    for i in range(n):
        p = 0
        if not release[ph, i]:
            for s in range(N[i]):
                if not active[i, s]:
                    continue
                for j in range(k):
                    W_r[i, j, p] = W[i, j, s]
                for a in range(6):
                    W_o_r[i, a, p] = W_o[i, a, s]
                    Wall[a, cols] = W_o[i, a, s]
                c_r[i, p] = c[i, s]
                uni[cols] = unilateral[i, s]
                marg[cols] = margins[ph, i, s] if unilateral[i, s] else 0.0
                index[i, p] = s
                p += 1
                cols += 1
        N_r[i] = p
    ka = cols
    rows = np.zeros(K, dtype=np.int64)
    P = 0
    for j in range(K):
        if press[ph, j] and phi_sup[j] <= PRESSING_GAP:
            rows[P] = j
            P += 1
    G = np.empty((P, 6))
    kap = np.empty(P)
    for q in range(P):
        j = rows[q]
        kap[q] = kappa_sup[j]
        for a in range(6):
            G[q, a] = G_sup[j, a]
            Wall[a, cols] = G_sup[j, a]
        uni[cols] = True
        marg[cols] = phases[ph, PH_SUPPORT_MARGIN]
        cols += 1
    mu_all = np.zeros(max(C, 1))
    kept = distribute(M_o, h_o, a_d, Wall, cols, G, kap, uni, marg, mu_all, a_o, False)
    if not kept:
        # no forces keep the margins: pushing forces (margins 0), the closest wrench they
        # make if none makes the whole, as the reference falls back
        for j in range(cols):
            marg[j] = 0.0
        if not distribute(M_o, h_o, a_d, Wall, cols, G, kap, uni, marg, mu_all, a_o, True):
            return PD_FORCES_FAILED, False
    mu_r = np.zeros((n, m))
    col = 0
    for i in range(n):
        for p in range(N_r[i]):
            mu_r[i, p] = mu_all[col]
            col += 1
    for j in range(K):
        lam[j] = 0.0
    for q in range(P):
        lam[rows[q]] = mu_all[ka + q]
    status = plan(M, J, Jdq, tp, tR, ttw, h, W_r, W_o_r, c_r, N_r, nv_arm, obj_x, a_o, z,
                  hold_tool, hold_obj, hold_n, gains, tau, mu_r, qdd, a_pts)
    if status != PD_OK:
        return status, kept
    for i in range(n):
        for s in range(m):
            mu[i, s] = 0.0
        for p in range(N_r[i]):
            mu[i, index[i, p]] = mu_r[i, p]
    return PD_OK, kept


def callee_compiles(buf, nv_arm, z, hold_tool, hold_n, gains, tau, qdd, a_pts, a_d,
                    a_o) -> tuple[Compile, Compile]:
    """The compiles of :func:`phased_torques`' ``distribute`` and ``plan``, for the types it passes.

    Each is compiled once, on its own, and called through its address by a compiled caller
    (:mod:`~multiarm_pin._compiled.function_pointers`). The arguments are those of
    :func:`phased_torques` of the same names (their types are what count); the arrays
    :func:`phased_torques` makes itself, and the views of ``buf``, are C-contiguous.
    """
    int64 = numba.types.int64

    def made(ndim, dtype=np.float64):  # an array as phased_torques makes it
        return np.zeros((0,) * ndim, dtype=dtype)

    def view(ndim):  # a view of buf
        return buf[:0].reshape((0,) * ndim)

    distribute = compile_of(supported_distribution,
                            (view(2), view(1), a_d, made(2), 0, made(2), made(1),
                             made(1, np.bool_), made(1), made(1), a_o, False),
                            numba.types.boolean)
    plan = compile_of(planned_torques,
                      (view(3), view(3), view(2), view(2), view(3), view(2), view(2), made(3),
                       made(3), made(2), made(1, np.int64), nv_arm, made(1), a_o, z, hold_tool,
                       made(3), hold_n, gains, tau, made(2), qdd, a_pts), int64)
    return distribute, plan


__all__ = ["PD_ARM_RANK", "PD_FORCES_FAILED", "PD_NOT_FINITE", "PINV_RCOND", "PRESSING_GAP",
           "RANK_TOL", "callee_compiles", "column_least_squares", "min_norm_forces",
           "minimum_jerk", "nnls", "phase_index", "phase_offsets", "phase_reference",
           "phased_torques", "polish", "supported_distribution"]
