"""The mixed LCP ``φ = G μ + b`` and its exact solver (Goldfarb–Idnani, compiled with numba).

Called by the unilateral solve (:mod:`multiarm_pin.dynamics.unilateral`, which turns its
status codes into errors) and by the contact solve kernel
(:mod:`multiarm_pin._compiled.delassus`).

Problem: on ``p`` rows with a symmetric positive semi-definite ``G`` (p, p) (the Delassus
operator of :mod:`multiarm_pin.dynamics.delassus`), find ``μ`` (p,) with::

    bilateral rows:   φ_k = 0, μ_k free;     unilateral rows:   0 ≤ μ_k ⟂ φ_k ≥ 0.

For contacts, ``φ`` is the normal acceleration ``φ̈`` [m/s²] (or, for impacts, a velocity) and
``μ`` the contact force [N] (impulse [N s]); this module only sees numbers.

Method: the dual active-set method of Goldfarb and Idnani (Math. Prog. 27, 1983) written on
``G`` (:func:`mlcp`, compiled with numba). It keeps an active set ``A`` of linearly
independent rows (``G_AA`` positive definite, checked through the Schur complement
``s = G_pp - G_pA G_AA⁻¹ G_Ap > DEPENDENCY_RTOL · G_pp`` when row ``p`` joins) with
``φ̈_A = 0`` and ``μ ≥ 0`` on its unilateral rows, and all other ``μ = 0``. Each major step
picks a violated row ``p`` (a bilateral row with ``φ̈_p ≠ 0`` first, else the unilateral row
with the most negative ``φ̈_p``) and raises ``|μ_p|`` along the direction that keeps
``φ̈_A = 0``: either ``φ̈_p`` reaches 0 (full step, ``p`` joins ``A``) or a unilateral
multiplier of ``A`` reaches 0 first (partial step, that row leaves ``A``; with a row ``p``
dependent on ``A`` only partial steps exist, which is how redundant rows are handled without
regularisation). If neither can happen the problem is infeasible (status ``INFEASIBLE``;
``INCONSISTENT`` for a bilateral row).

Termination: after every full step ``(μ, A)`` is the unique solution of the equality problem
on ``A``, and the primal objective (the dual function) strictly increases from one full step
to the next (``φ̈_p`` was violated by more than the tolerance and ``s > 0``); so no active
set repeats, and at most ``|A| ≤ rank`` partial steps separate two full steps: the method
stops after finitely many pivots (a cap of ``1000 + 20 p`` pivots only guards against
round-off pathologies: status ``MAX_PIVOTS``). At the end ``μ_A`` is recomputed from
``G_AA μ_A = -b_A`` (a Cholesky solve), so the result is exact to round-off: the only
tolerances decide whether ``φ̈_p`` counts as violated (``VIOLATION_RTOL`` of ``max |b|``),
whether a row is dependent (``DEPENDENCY_RTOL``) and whether a dependent bilateral row is consistent
(``CONSISTENCY_RTOL``). The returned ``μ`` is the basic solution of that final set: its
nonzero multipliers sit on linearly independent rows (with redundant rows, not the
minimum-norm ``μ``).
"""

from __future__ import annotations

import numpy as np

from multiarm_pin._compiled import linalg as _kernels
from multiarm_pin._compiled.jit import kernel

DEPENDENCY_RTOL = 1e-10
"""A row ``p`` is linearly dependent on the active rows when its Schur complement
``G_pp - G_pA G_AA⁻¹ G_Ap`` is at most this times ``G_pp``."""

VIOLATION_RTOL = 1e-11
"""A row counts as violated when ``φ̈_p < -VIOLATION_RTOL · max|b|`` (unilateral) or
``|φ̈_p| > VIOLATION_RTOL · max|b|`` (bilateral): the round-off level of ``φ̈``."""

CONSISTENCY_RTOL = 1e-8
"""A bilateral row dependent on the active rows whose ``|φ̈|`` cannot be reduced is accepted
(multiplier 0) when ``|φ̈| ≤ CONSISTENCY_RTOL · max|b|`` (as the bilateral singular solver's
consistency test); larger means inconsistent bilateral constraints (status ``INCONSISTENT``)."""

OK, INFEASIBLE, INCONSISTENT, MAX_PIVOTS = 0, 1, 2, 3
"""Status codes returned by :func:`mlcp`."""


@kernel
def _factor_active(G, act, na, GA, L):  # pragma: no cover - compiled
    """Cholesky factor of ``G[act[:na], act[:na]]`` into ``L``; False if not positive definite."""
    for a in range(na):
        for c in range(na):
            GA[a, c] = G[act[a], act[c]]
    return _kernels.cholesky(GA, L, na)


@kernel
def mlcp(G, b, uni, dep_rtol, viol_tol, cons_tol, max_pivots, start,
         mu, phi, in_a):  # pragma: no cover - compiled
    """Mixed LCP ``φ = G μ + b``: bilateral ``φ = 0``; unilateral ``0 ≤ μ ⟂ φ ≥ 0``.

    Dual active-set method of Goldfarb-Idnani on ``G`` (see the module docstring).

    Args:
        G: (p, p) symmetric positive semi-definite.
        b: (p,).
        uni: (p,) bool, unilateral rows.
        dep_rtol: dependency tolerance (relative to ``G_pp``).
        viol_tol: violation tolerance on ``φ`` (absolute).
        cons_tol: consistency tolerance of dependent bilateral rows (absolute).
        max_pivots: safety cap on active-set changes.
        start: (p,) bool, rows of the initial active set (warm start): used if they are
            independent and their multipliers push on unilateral rows, else the method
            starts from the empty set. The result does not depend on it (up to the choice
            of ``μ`` among equivalent ones with redundant rows).
        mu: (p,) output, multipliers.
        phi: (p,) output, ``G μ + b``.
        in_a: (p,) bool output, rows of the final active set.

    Returns:
        ``(status, pivots, row)``: status 0 ok, 1 infeasible (row ``row`` can be neither
        satisfied nor relieved), 2 inconsistent bilateral row ``row``, 3 pivot cap reached.
    """
    p = b.shape[0]
    GA = np.zeros((p, p))
    L = np.zeros((p, p))
    rhs = np.zeros((p, 1))
    act = np.zeros(p, dtype=np.int64)
    skip = np.zeros(p, dtype=np.bool_)
    dmu = np.zeros(p)
    for j in range(p):
        mu[j] = 0.0
        phi[j] = b[j]
        in_a[j] = False
    if p == 0:
        return OK, 0, -1
    # ---- warm start: the rows of `start`, if independent and pushing on unilateral rows
    na = 0
    for j in range(p):
        if start[j]:
            act[na] = j
            na += 1
    ok = na > 0 and _factor_active(G, act, na, GA, L)
    if ok:
        for a in range(na):
            if L[a, a] * L[a, a] <= dep_rtol * G[act[a], act[a]]:
                ok = False
    if ok:
        for a in range(na):
            rhs[a, 0] = -b[act[a]]
        _kernels.cholesky_solve(L, rhs, na, np.int64(1))
        for a in range(na):
            if uni[act[a]] and not rhs[a, 0] >= 0.0:
                ok = False
    if ok:
        for a in range(na):
            mu[act[a]] = rhs[a, 0]
            in_a[act[a]] = True
        for i in range(p):
            t = b[i]
            for a in range(na):
                t += G[i, act[a]] * mu[act[a]]
            phi[i] = t
        for a in range(na):
            phi[act[a]] = 0.0
    else:
        na = 0
    pivots = 0
    while True:
        # ---- choose a violated row: bilateral first, then the most negative unilateral
        q = -1
        worst = 0.0
        for j in range(p):
            if not in_a[j] and not skip[j] and not uni[j] and abs(phi[j]) > viol_tol:
                if abs(phi[j]) > worst:
                    worst = abs(phi[j])
                    q = j
        if q < 0:
            for j in range(p):
                if not in_a[j] and uni[j] and phi[j] < -viol_tol and -phi[j] > worst:
                    worst = -phi[j]
                    q = j
        if q < 0:
            break
        sigma = 1.0 if (uni[q] or phi[q] < 0.0) else -1.0
        while True:
            if pivots >= max_pivots:
                return MAX_PIVOTS, pivots, q
            # r = G_AA⁻¹ G_Aq and the Schur complement s
            if na > 0:
                _factor_active(G, act, na, GA, L)
                for a in range(na):
                    rhs[a, 0] = G[act[a], q]
                _kernels.cholesky_solve(L, rhs, na, np.int64(1))
            s = G[q, q]
            for a in range(na):
                s -= G[q, act[a]] * rhs[a, 0]
                dmu[a] = -sigma * rhs[a, 0]
            dependent = not s > dep_rtol * G[q, q]
            t_full = np.inf if dependent else abs(phi[q]) / s
            t_part = np.inf
            blocking = -1
            for a in range(na):
                j = act[a]
                if uni[j] and dmu[a] < 0.0:
                    t = mu[j] / (-dmu[a])
                    if t < t_part:
                        t_part = t
                        blocking = a
            if t_full == np.inf and t_part == np.inf:
                if not uni[q] and abs(phi[q]) <= cons_tol:
                    skip[q] = True  # dependent, consistent to the bilateral tolerance
                    break
                return (INFEASIBLE if uni[q] else INCONSISTENT), pivots, q
            t = min(t_full, t_part)
            # step: μ_q += σ t, μ_A += t dμ_A, φ += t (σ G_:q + G_:A dμ_A)
            mu[q] += sigma * t
            for j in range(p):
                phi[j] += t * sigma * G[j, q]
            for a in range(na):
                j = act[a]
                mu[j] += t * dmu[a]
                for i in range(p):
                    phi[i] += t * dmu[a] * G[i, j]
            pivots += 1
            if t_full <= t_part:
                act[na] = q
                na += 1
                in_a[q] = True
                phi[q] = 0.0
                break
            # partial step: the blocking unilateral row leaves the active set
            jb = act[blocking]
            mu[jb] = 0.0
            in_a[jb] = False
            for a in range(blocking, na - 1):
                act[a] = act[a + 1]
            na -= 1
    if na > 0:
        _factor_active(G, act, na, GA, L)
    return _finish(G, b, uni, act, na, GA, L, rhs, mu, phi, in_a, pivots)


@kernel
def _finish(G, b, uni, act, na, GA, L, rhs, mu, phi, in_a, pivots):  # pragma: no cover
    """Exact multipliers of the final active set (``L`` holds its Cholesky factor)."""
    p = b.shape[0]
    for j in range(p):
        mu[j] = 0.0
    for a in range(na):
        rhs[a, 0] = -b[act[a]]
    if na > 0:
        _kernels.cholesky_solve(L, rhs, na, np.int64(1))
    for a in range(na):
        j = act[a]
        v = rhs[a, 0]
        mu[j] = v if (v > 0.0 or not uni[j]) else 0.0  # round-off below zero -> 0
    for i in range(p):
        t = b[i]
        for a in range(na):
            t += G[i, act[a]] * mu[act[a]]
        phi[i] = t
    return OK, pivots, -1


__all__ = ["CONSISTENCY_RTOL", "DEPENDENCY_RTOL", "INCONSISTENT", "INFEASIBLE", "MAX_PIVOTS",
           "OK", "VIOLATION_RTOL", "mlcp"]
