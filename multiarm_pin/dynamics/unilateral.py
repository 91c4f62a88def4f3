"""Unilateral frictionless contacts: exact mixed-LCP forward dynamics and impacts, object-first.

Problem. With the blocks of :class:`~multiarm_pin.dynamics.blocks.SystemBlocks`
(``docs/ARCHITECTURE.md``: ``M_o a_o = h_o + Σ_i W_o,i μ_i``, ``M_i q̈_i = h_i + W_i μ_i``)
the normal acceleration of contact row ``k`` is ``φ̈ = W_oᵀ a_o + Wᵀ q̈ - c`` (stacked over
arms). Eliminating the accelerations gives ``φ̈ = G μ + b`` with the Delassus operator::

    G = blockdiag_i(W_iᵀ M_i⁻¹ W_i) + W_oᵀ M_o⁻¹ W_o      (per-arm blocks + rank-6 coupling)
    b = W_oᵀ M_o⁻¹ h_o + Wᵀ M⁻¹ h - c                      (φ̈ of the motion with μ = 0)

built arm by arm (:func:`delassus_operator`; the dense ``J M⁻¹ Jᵀ`` over all arms is never
formed), and the mixed LCP on the active rows is::

    bilateral rows:   φ̈_k = 0, μ_k free;     unilateral rows:   0 ≤ μ_k ⟂ φ̈_k ≥ 0.

It is the optimality system of Gauss's principle, the strictly convex QP in the accelerations
``v = (a_o, q̈)``: ``min ½ ‖v - v_free‖²_M`` subject to ``φ̈_k(v) = 0`` (bilateral) and
``φ̈_k(v) ≥ 0`` (unilateral), whose multipliers are ``μ``. So the motion is unique whenever the
problem is feasible, even when ``G`` is only positive semi-definite (redundant rows, e.g. four
coplanar vertices on a table, or rows of an arm with ``nv_i = 0`` acting on the object only);
``μ`` is then not unique.

Method: the dual active-set method of Goldfarb and Idnani (Math. Prog. 27, 1983) written on
``G`` (:func:`_mlcp`, compiled with numba). It keeps an active set ``A`` of linearly
independent rows (``G_AA`` positive definite, checked through the Schur complement
``s = G_pp - G_pA G_AA⁻¹ G_Ap > DEPENDENCY_RTOL · G_pp`` when row ``p`` joins) with
``φ̈_A = 0`` and ``μ ≥ 0`` on its unilateral rows, and all other ``μ = 0``. Each major step
picks a violated row ``p`` (a bilateral row with ``φ̈_p ≠ 0`` first, else the unilateral row
with the most negative ``φ̈_p``) and raises ``|μ_p|`` along the direction that keeps
``φ̈_A = 0``: either ``φ̈_p`` reaches 0 (full step, ``p`` joins ``A``) or a unilateral
multiplier of ``A`` reaches 0 first (partial step, that row leaves ``A``; with a row ``p``
dependent on ``A`` only partial steps exist, which is how redundant rows are handled without
regularisation). If neither can happen the problem is infeasible (:class:`DynamicsError`).

Termination: after every full step ``(μ, A)`` is the unique solution of the equality problem
on ``A``, and the primal objective (the dual function) strictly increases from one full step
to the next (``φ̈_p`` was violated by more than the tolerance and ``s > 0``); so no active
set repeats, and at most ``|A| ≤ rank`` partial steps separate two full steps: the method
stops after finitely many pivots (a cap of ``1000 + 20 p`` pivots only guards against
round-off pathologies and raises). At the end ``μ_A`` is recomputed from ``G_AA μ_A = -b_A``
(a Cholesky solve), so the result is exact to round-off: the only tolerances decide whether
``φ̈_p`` counts as violated (``VIOLATION_RTOL`` of ``max |b|``), whether a row is
dependent (``DEPENDENCY_RTOL``) and whether a dependent bilateral row is consistent
(``CONSISTENCY_RTOL``). The returned ``μ`` is the basic solution of that final set: its
nonzero multipliers sit on linearly independent rows (with redundant rows, not the
minimum-norm ``μ``).

Implementation: :func:`_contact_kernel` (numba) does the whole solve in one call: a Cholesky
factorisation of every ``M_i`` and ``X_i = M_i⁻¹ [W_i h_i]``, one 6 x 6 Cholesky solve
``M_o⁻¹ [W_o h_o]`` on the active rows, ``G`` and ``b`` on the active rows only (per-arm
blocks ``W_iᵀ X_i`` plus the object coupling), :func:`_mlcp`, then ``a_o``, ``q̈`` and
``φ̈``. The numpy :func:`delassus_operator` with the same core is the reference
(``reference=True``) and handles the rare cases the kernel hands over (a singular ``M_i``,
non-finite values), raising the documented errors.

Fast path: when every real row is active and every arm has at least as many joints as rows
(else some ``S_i`` is singular by structure), the compiled bilateral object-first solve
(:func:`multiarm_pin.dynamics.solve_object_first`) runs first; if it is regular and every
unilateral multiplier is ``≥ 0``, it is the answer (``solver = "bilateral"``), identical to
the bilateral solve. Otherwise the active-set method runs, warm started from "all active
rows" when ``G`` restricted to them is positive definite and that solution pushes
everywhere, else from ``A = ∅``.

Cost: per arm one ``nv_i``-Cholesky and ``N_i + 1`` solves (as the bilateral solver), then
``O(p²)`` for ``G`` on the ``p`` active rows and ``O(|A|³)`` per pivot (``G_AA`` is
refactored; about ``p`` pivots from a cold start): negligible against the per-arm work for
tens of contacts. Measured (``benchmarks/results/unilateral.md``): 11 rows of the
two-gripper scenario + table, ~65 µs (~52 µs warm-started with ``guess``), against ~700 µs
for the bilateral ``"auto"`` solve of the same rows (singular-arm path) and ~25 µs for the
compiled bilateral solve of the 7 fingertip rows alone.

Impacts (:func:`solve_impact`) are the same problem at velocity level: with ``h = h_o = 0``
the impulse ``P`` gives ``φ̇⁺ = φ̇⁻ + G P``, and Newton's law
``0 ≤ P_k ⟂ φ̇⁺_k + e_k φ̇⁻_k ≥ 0`` is the mixed LCP with ``b = (1 + e) φ̇⁻`` on unilateral
rows (``b = φ̇⁻`` and ``φ̇⁺ = 0`` on bilateral rows).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit
from scipy.linalg import lapack

from multiarm_pin._compiled import linalg as _kernels
from multiarm_pin.dynamics.blocks import SystemBlocks
from multiarm_pin.dynamics.object_first import _batched_solve, solve_object_first
from multiarm_pin.exceptions import DynamicsError, InputError, SingularityError

DEPENDENCY_RTOL = 1e-10
"""A row ``p`` is linearly dependent on the active rows when its Schur complement
``G_pp - G_pA G_AA⁻¹ G_Ap`` is at most this times ``G_pp``."""

VIOLATION_RTOL = 1e-11
"""A row counts as violated when ``φ̈_p < -VIOLATION_RTOL · max|b|`` (unilateral) or
``|φ̈_p| > VIOLATION_RTOL · max|b|`` (bilateral): the round-off level of ``φ̈``."""

CONSISTENCY_RTOL = 1e-8
"""A bilateral row dependent on the active rows whose ``|φ̈|`` cannot be reduced is accepted
(multiplier 0) when ``|φ̈| ≤ CONSISTENCY_RTOL · max|b|`` (as the bilateral singular solver's
consistency test); larger means inconsistent bilateral constraints (:class:`DynamicsError`)."""

SEPARATION_RTOL = 1e-9
""":attr:`ContactSolution.separating` needs ``φ̈ > SEPARATION_RTOL · max |φ̈|``."""

_OK, _INFEASIBLE, _INCONSISTENT, _MAX_PIVOTS = 0, 1, 2, 3


# ------------------------------------------------------------------ results
@dataclass(frozen=True)
class ContactResiduals:
    """Residuals of a unilateral solve (absolute norms; see :attr:`relative`).

    Attributes:
        object: ``‖M_o a_o - h_o - Σ W_o,i μ_i‖`` [N, N m] (impacts: ``M_o Δv_o - Σ W_o,i P_i``
            [N s]).
        arms: ``‖M_i q̈_i - h_i - W_i μ_i‖`` over all arms (impacts: with ``Δq̇`` and ``P``).
        constraints: ``‖φ̈‖`` over the active bilateral rows (impacts: ``‖φ̇⁺‖``).
        complementarity: ``max |min(μ_k, φ̈_k)|`` over the active unilateral rows (impacts:
            ``max |min(P_k, φ̇⁺_k + e_k φ̇⁻_k)|``).
        sign: largest violation of ``μ ≥ 0`` and ``φ̈ ≥ 0`` on those rows (0 when none).
        scale: size of the terms that should cancel, so that residual / scale is relative.
    """

    object: float
    arms: float
    constraints: float
    complementarity: float
    sign: float
    scale: float

    @property
    def relative(self) -> float:
        """Largest residual divided by :attr:`scale` (the largest itself when scale is 0)."""
        worst = max(self.object, self.arms, self.constraints, self.complementarity, self.sign)
        return worst / self.scale if self.scale > 0 else worst


def _residuals(b: SystemBlocks, a_o, qdd, mu, h_o, h, rate, unilateral, active, gap):
    """Shared residual computation (``gap`` = the complementary quantity on unilateral rows)."""
    Wmu_o = np.einsum("nij,nj->i", b.W_o, mu)
    Mqdd = np.einsum("nij,nj->ni", b.M, qdd)
    Wmu = np.einsum("nij,nj->ni", b.W, mu)
    Mo_a = b.M_o @ a_o
    bil = active & ~unilateral
    uni = active & unilateral
    comp = np.abs(np.minimum(mu[uni], gap[uni]))
    neg = np.concatenate(([0.0], -mu[uni], -gap[uni]))
    terms = [Mo_a, h_o, Wmu_o, Mqdd, h, Wmu, rate]
    return ContactResiduals(
        object=float(np.linalg.norm(Mo_a - h_o - Wmu_o)),
        arms=float(np.linalg.norm(Mqdd - h - Wmu)),
        constraints=float(np.linalg.norm(rate[bil])),
        complementarity=float(comp.max()) if comp.size else 0.0,
        sign=float(max(neg.max(), 0.0)),
        scale=float(max(np.linalg.norm(t) for t in terms)),
    )


@dataclass(frozen=True, eq=False)
class ContactSolution:
    """Result of :func:`solve_unilateral`.

    Attributes:
        a_o: (6,) object classical acceleration ``[ẍ; ω̇]`` at the COM, world axes
            [m/s², rad/s²].
        qdd: (n, nv_max) joint accelerations, zero on padded dofs.
        mu: (n, N_max) contact multipliers (positive = pushing); 0 on inactive rows, on
            unilateral rows that separate, and on padding.
        phi_dd: (n, N_max) normal accelerations ``φ̈ = W_oᵀ a_o + Wᵀ q̈ - c`` at the solution,
            for every real row (active or not); 0 on padding.
        solver: ``"bilateral"`` (fast path: the bilateral object-first solve pushed
            everywhere) or ``"active_set"``.
        pivots: number of active-set changes of the active-set method (0 on the fast path
            or when the warm start was the answer).
        unilateral: (n, N_max) bool, the unilateral flags that were solved.
        active: (n, N_max) bool, the active rows that were solved.
        blocks: the blocks that were solved (not copied).
    """

    a_o: np.ndarray
    qdd: np.ndarray
    mu: np.ndarray
    phi_dd: np.ndarray
    solver: str
    pivots: int
    unilateral: np.ndarray = field(repr=False)
    active: np.ndarray = field(repr=False)
    blocks: SystemBlocks = field(repr=False, compare=False)

    def qdd_of(self, i: int) -> np.ndarray:
        """Joint accelerations of arm ``i`` without padding, shape (nv_i,)."""
        return self.qdd[i, : self.blocks.nv[i]]

    def mu_of(self, i: int) -> np.ndarray:
        """Multipliers of arm ``i`` without padding, shape (N_i,)."""
        return self.mu[i, : self.blocks.N[i]]

    @property
    def singular_arms(self) -> tuple[int, ...]:
        """Always ``()`` (as :attr:`Solution.singular_arms`; redundancy needs no special arm)."""
        return ()

    @property
    def separating(self) -> np.ndarray:
        """(n, N_max) bool: active unilateral rows that carry no force and accelerate apart.

        ``μ = 0`` and ``φ̈ > SEPARATION_RTOL · max |φ̈|`` (over the real rows): a row whose
        ``φ̈`` is zero to round-off (e.g. the fourth of four coplanar table rows, dependent
        on the others) is touching, not separating.
        """
        tol = SEPARATION_RTOL * float(np.abs(self.phi_dd).max(initial=0.0))
        return self.active & self.unilateral & (self.mu == 0.0) & (self.phi_dd > tol)

    @property
    def complementarity(self) -> float:
        """``max |min(μ_k, φ̈_k)|`` over the active unilateral rows (0 when there are none)."""
        uni = self.active & self.unilateral
        if not uni.any():
            return 0.0
        return float(np.abs(np.minimum(self.mu[uni], self.phi_dd[uni])).max())

    def residuals(self) -> ContactResiduals:
        """Residuals of the equations of motion and of complementarity at this solution."""
        b = self.blocks
        return _residuals(b, self.a_o, self.qdd, self.mu, b.h_o, b.h, self.phi_dd,
                          self.unilateral, self.active, self.phi_dd)


@dataclass(frozen=True, eq=False)
class ImpactSolution:
    """Result of :func:`solve_impact`.

    Attributes:
        dv_o: (6,) jump of the object twist ``[v; ω]`` at the COM, world axes [m/s, rad/s].
        dqd: (n, nv_max) jump of the joint velocities, zero on padded dofs.
        P: (n, N_max) contact impulses [N s] (positive = pushing); 0 on inactive rows, on
            unilateral rows that do not take part, and on padding.
        phi_dot_plus: (n, N_max) post-impact normal velocities ``φ̇⁺ = φ̇⁻ + W_oᵀ Δv_o + Wᵀ Δq̇``
            for every real row; 0 on padding.
        solver: ``"active_set"``.
        pivots: number of active-set changes.
        phi_dot_minus: (n, N_max) pre-impact normal velocities that were given.
        restitution: (n, N_max) Newton coefficients that were given.
        unilateral: (n, N_max) bool.
        active: (n, N_max) bool.
        blocks: the blocks (only ``M``, ``W``, ``W_o``, ``M_o`` were used).
    """

    dv_o: np.ndarray
    dqd: np.ndarray
    P: np.ndarray
    phi_dot_plus: np.ndarray
    solver: str
    pivots: int
    phi_dot_minus: np.ndarray = field(repr=False)
    restitution: np.ndarray = field(repr=False)
    unilateral: np.ndarray = field(repr=False)
    active: np.ndarray = field(repr=False)
    blocks: SystemBlocks = field(repr=False, compare=False)

    @property
    def complementarity(self) -> float:
        """``max |min(P_k, φ̇⁺_k + e_k φ̇⁻_k)|`` over the active unilateral rows."""
        uni = self.active & self.unilateral
        if not uni.any():
            return 0.0
        gap = self.phi_dot_plus + self.restitution * self.phi_dot_minus
        return float(np.abs(np.minimum(self.P[uni], gap[uni])).max())

    def residuals(self) -> ContactResiduals:
        """Residuals of the impact equations (``h`` terms are zero) and of complementarity."""
        b = self.blocks
        gap = self.phi_dot_plus + self.restitution * self.phi_dot_minus
        return _residuals(b, self.dv_o, self.dqd, self.P, np.zeros(6), np.zeros_like(b.h),
                          self.phi_dot_plus, self.unilateral, self.active, gap)


# ------------------------------------------------------------------ Delassus operator
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


# ------------------------------------------------------------------ the core (compiled)
@njit(cache=True, error_model="numpy")
def _factor_active(G, act, na, GA, L):  # pragma: no cover - compiled
    """Cholesky factor of ``G[act[:na], act[:na]]`` into ``L``; False if not positive definite."""
    for a in range(na):
        for c in range(na):
            GA[a, c] = G[act[a], act[c]]
    return _kernels.cholesky(GA, L, na)


@njit(cache=True, error_model="numpy")
def _mlcp(G, b, uni, dep_rtol, viol_tol, cons_tol, max_pivots, start,
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
        return _OK, 0, -1
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
        _kernels.cholesky_solve(L, rhs, na, 1)
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
                return _MAX_PIVOTS, pivots, q
            # r = G_AA⁻¹ G_Aq and the Schur complement s
            if na > 0:
                _factor_active(G, act, na, GA, L)
                for a in range(na):
                    rhs[a, 0] = G[act[a], q]
                _kernels.cholesky_solve(L, rhs, na, 1)
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
                return (_INFEASIBLE if uni[q] else _INCONSISTENT), pivots, q
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


@njit(cache=True, error_model="numpy")
def _finish(G, b, uni, act, na, GA, L, rhs, mu, phi, in_a, pivots):  # pragma: no cover
    """Exact multipliers of the final active set (``L`` holds its Cholesky factor)."""
    p = b.shape[0]
    for j in range(p):
        mu[j] = 0.0
    for a in range(na):
        rhs[a, 0] = -b[act[a]]
    if na > 0:
        _kernels.cholesky_solve(L, rhs, na, 1)
    for a in range(na):
        j = act[a]
        v = rhs[a, 0]
        mu[j] = v if (v > 0.0 or not uni[j]) else 0.0  # round-off below zero -> 0
    for i in range(p):
        t = b[i]
        for a in range(na):
            t += G[i, act[a]] * mu[act[a]]
        phi[i] = t
    return _OK, pivots, -1


_BAD_MASS, _NOT_FINITE, _UNI_PADDING, _ACT_PADDING = 4, 5, 6, 7


@njit(cache=True, error_model="numpy")
def _contact_kernel(M, h, W, W_o, c, M_o, h_o, nv, N, uni, act, guess, use_guess, dep_rtol,
                    viol_rtol, cons_rtol, a_o, qdd, mu, Av):  # pragma: no cover - compiled
    """The whole unilateral solve, compiled: object-first Delassus, :func:`_mlcp`, motion.

    Per arm a Cholesky factorisation of ``M_i`` and ``X_i = M_i⁻¹ [W_i h_i]``; one 6 x 6
    Cholesky solve ``Y = M_o⁻¹ [W_o,active h_o]``; ``G`` and ``b`` on the active rows only
    (per-arm blocks ``W_iᵀ X_i`` plus the object coupling ``W_oᵀ Y``); the mixed LCP; then
    ``a_o``, ``q̈``, ``μ`` (padded outputs) and ``Av = W_oᵀ a_o + Wᵀ q̈`` on every real row.
    The warm start is every active row, or with ``use_guess`` the active rows that are
    bilateral or in ``guess`` (n, N_max) bool.

    Returns:
        ``(status, pivots, arm, row, value)``: status as :func:`_mlcp` (arm and row of the
        offending row, its ``φ``), 4 singular ``M_i`` (arm), 5 non-finite result, 6 / 7
        ``uni`` / ``act`` True on the padding row (arm, row).
    """
    n, k, m = W.shape
    for i in range(n):
        for r in range(N[i], m):
            if uni[i, r]:
                return _UNI_PADDING, 0, i, r, 0.0
            if act[i, r]:
                return _ACT_PADDING, 0, i, r, 0.0
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
            return _BAD_MASS, 0, i, -1, 0.0
        Xi = X[i]
        for j in range(ni):
            for r in range(Ni):
                Xi[j, r] = W[i, j, r]
            Xi[j, Ni] = h[i, j]
        _kernels.cholesky_solve(L, Xi, ni, Ni + 1)
    # object: Y = M_o⁻¹ [W_o of the active rows, h_o]
    Lo = np.zeros((6, 6))
    if not _kernels.cholesky(M_o, Lo, 6):
        return _NOT_FINITE, 0, -1, -1, 0.0
    Y = np.zeros((6, P + 1))
    for a in range(P):
        for r in range(6):
            Y[r, a] = W_o[arm_of[a], r, row_of[a]]
    for r in range(6):
        Y[r, P] = h_o[r]
    _kernels.cholesky_solve(Lo, Y, 6, P + 1)
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
        return _NOT_FINITE, 0, -1, -1, 0.0
    uni_a = np.empty(P, dtype=np.bool_)
    start = np.empty(P, dtype=np.bool_)
    for a in range(P):
        uni_a[a] = uni[arm_of[a], row_of[a]]
        start[a] = (guess[arm_of[a], row_of[a]] or not uni_a[a]) if use_guess else True
    mu_a = np.empty(P)
    phi = np.empty(P)
    in_a = np.empty(P, dtype=np.bool_)
    status, pivots, q = _mlcp(G, bvec, uni_a, dep_rtol, viol_rtol * scale, cons_rtol * scale,
                              1000 + 20 * P, start, mu_a, phi, in_a)
    if status != _OK:
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
        return _NOT_FINITE, pivots, -1, -1, 0.0
    return _OK, pivots, -1, -1, 0.0


# ------------------------------------------------------------------ inputs
def _mask(value, name: str, blocks: SystemBlocks, padding: bool = True) -> np.ndarray:
    """Check a (n, N_max) bool mask (and, with ``padding``, that it is False on padding)."""
    shape = (blocks.n, blocks.N_max)
    arr = np.asarray(value)
    if arr.shape != shape or arr.dtype != np.bool_:
        raise InputError(
            f"{name}: expected a bool array of shape (n, N_max) = {shape}, got "
            f"{arr.dtype} array of shape {arr.shape}"
        )
    if padding and (arr > blocks.constraint_mask).any():
        i, k = np.argwhere(arr > blocks.constraint_mask)[0]
        raise _padding_error(name, blocks, int(i), int(k))
    return arr


def _padding_error(name: str, blocks: SystemBlocks, i: int, k: int) -> InputError:
    return InputError(
        f"{name}: True on padding (arm {i}, row {k}, but arm {i} has N_{i} = "
        f"{blocks.N[i]} rows); expected False beyond N_i"
    )


def _rows(value, name: str, blocks: SystemBlocks) -> np.ndarray:
    shape = (blocks.n, blocks.N_max)
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name}: expected an array of numbers, got {value!r}") from exc
    if arr.shape != shape:
        raise InputError(f"{name}: expected shape (n, N_max) = {shape}, got {arr.shape}")
    arr[~blocks.constraint_mask] = 0.0
    if not np.isfinite(arr).all():
        i, k = np.argwhere(~np.isfinite(arr))[0]
        raise InputError(f"{name}: NaN or infinity at arm {i}, row {k}")
    return arr


def _check_blocks(blocks) -> None:
    if not isinstance(blocks, SystemBlocks):
        raise InputError(f"blocks: expected SystemBlocks, got {type(blocks).__name__}")


def _row_name(blocks: SystemBlocks, flat_index: int) -> str:
    arm, row = np.nonzero(blocks.constraint_mask)
    return f"arm {int(arm[flat_index])}, row {int(row[flat_index])}"


# ------------------------------------------------------------------ solvers
def _c(a: np.ndarray) -> np.ndarray:
    """C-contiguous (one compiled specialisation of the kernels for every input)."""
    return a if a.flags.c_contiguous else np.ascontiguousarray(a)


def _solve(b: SystemBlocks, h: np.ndarray, h_o: np.ndarray, c: np.ndarray, uni: np.ndarray,
           act: np.ndarray, what: str, reference: bool, guess: np.ndarray | None = None):
    """Mixed LCP of the blocks with ``h``, ``h_o``, ``c`` given (impacts: zeros and ``-rhs``).

    Returns:
        ``(a_o (6,), qdd (n, nv_max), mu (n, N_max), Av (n, N_max), pivots)`` with
        ``Av = W_oᵀ a_o + Wᵀ q̈`` on the real rows (zero on padding).
    """
    if not reference:
        n, k, m = b.W.shape
        a_o, qdd, mu, Av = np.empty(6), np.empty((n, k)), np.empty((n, m)), np.empty((n, m))
        status, pivots, arm, row, value = _contact_kernel(
            _c(b.M), _c(h), _c(b.W), _c(b.W_o), _c(c), _c(b.M_o), _c(h_o), b.nv, b.N,
            _c(uni), _c(act), _c(act if guess is None else guess), guess is not None,
            DEPENDENCY_RTOL, VIOLATION_RTOL, CONSISTENCY_RTOL, a_o, qdd, mu, Av)
        if status == _OK:
            return a_o, qdd, mu, Av, int(pivots)
        if status in (_UNI_PADDING, _ACT_PADDING):
            name = "unilateral" if status == _UNI_PADDING else "active"
            raise _padding_error(name, b, int(arm), int(row))
        if status in (_INFEASIBLE, _INCONSISTENT, _MAX_PIVOTS):
            raise _lcp_error(what, status, f"arm {arm}, row {row}", value, pivots)
        # singular M_i or a non-finite result: the numpy reference decides and names it
    return _solve_numpy(b, h, h_o, c, uni, act, what, guess)


def _solve_numpy(b: SystemBlocks, h: np.ndarray, h_o: np.ndarray, c: np.ndarray,
                 uni: np.ndarray, act: np.ndarray, what: str, guess: np.ndarray | None = None):
    """Reference path of :func:`_solve`: numpy :func:`delassus_operator` + the compiled core."""
    if h is not b.h or h_o is not b.h_o or c is not b.c:
        b = SystemBlocks(b.M, h, b.W, b.W_o, c, b.M_o, h_o, b.nv, b.N)
    D = delassus_operator(b)
    cm = b.constraint_mask
    idx = np.flatnonzero(act[cm])
    G = np.ascontiguousarray(D.G[np.ix_(idx, idx)])
    bb = np.ascontiguousarray(D.b[idx])
    scale = float(np.abs(bb).max()) if bb.size else 0.0
    p = idx.size
    mu_a, phi, in_a = np.empty(p), np.empty(p), np.empty(p, dtype=np.bool_)
    start = np.ones(p, dtype=np.bool_) if guess is None else (guess | ~uni)[cm][idx]
    status, pivots, q = _mlcp(G, bb, np.ascontiguousarray(uni[cm][idx]), DEPENDENCY_RTOL,
                              VIOLATION_RTOL * scale, CONSISTENCY_RTOL * scale,
                              1000 + 20 * p, np.ascontiguousarray(start), mu_a, phi, in_a)
    if status != _OK:
        raise _lcp_error(what, status, _row_name(b, int(idx[q])), phi[q], pivots)
    flat = np.zeros(b.n_constraints)
    flat[idx] = mu_a
    mu = b.unflatten_mu(flat)
    a_o, qdd = D.motion(mu, b)
    return a_o, qdd, mu, _rates(b, a_o, qdd, np.zeros_like(b.c)), int(pivots)


def _lcp_error(what: str, status: int, name: str, value: float, pivots: int) -> DynamicsError:
    if status == _INFEASIBLE:
        return DynamicsError(
            f"{what}: the contacts cannot all hold: unilateral row ({name}) would penetrate "
            f"({value:.3g}) and no force can prevent it; the bilateral constraints or the "
            "other contacts forbid the motion"
        )
    if status == _INCONSISTENT:
        return DynamicsError(
            f"{what}: the bilateral constraints are inconsistent: row ({name}) depends on the "
            f"other active rows but its rate cannot be zeroed (residual {value:.3g}); check "
            "c (velocity consistency) and W"
        )
    return DynamicsError(  # pragma: no cover - safety net of the finite method
        f"{what}: the active-set method did not terminate in {pivots} pivots (last row "
        f"{name}); round-off cycling, please report the state"
    )


def solve_unilateral(
    blocks: SystemBlocks,
    unilateral: np.ndarray,
    active: np.ndarray | None = None,
    *,
    fast_path: bool = True,
    reference: bool = False,
    guess: np.ndarray | None = None,
) -> ContactSolution:
    """Forward dynamics with mixed bilateral / unilateral contacts (mixed LCP, exact).

    Active unilateral rows satisfy ``0 ≤ μ ⟂ φ̈ ≥ 0``, active bilateral rows ``φ̈ = 0``
    (``μ`` free in sign); inactive rows are dropped (``μ = 0``, separated contacts) but their
    ``φ̈`` is still reported. Method, termination and cost: see the module docstring.
    Redundant rows (four coplanar vertices on a table, rows of an arm with ``nv_i = 0`` that
    act on the object only) work: ``a_o`` and ``q̈`` are unique, ``μ`` is not; the returned
    ``μ`` is the bilateral solve's when every unilateral row of it pushes (fast path; the
    minimum-norm ``μ`` when that solve is singular is not used: the fast path only accepts
    a regular bilateral solve), else the basic solution of the final active set (its forces
    sit on linearly independent rows).

    Args:
        blocks: the system blocks (:class:`SystemBlocks`).
        unilateral: (n, N_max) bool, True where row ``k`` of arm ``i`` is a unilateral
            contact (False on padding).
        active: (n, N_max) bool, the rows that take part (touching contacts and bilateral
            rows); None means every real row. False on padding.
        fast_path: try the bilateral solve first (see the module docstring); False runs
            the active-set method in any case (for checks).
        reference: use the numpy :func:`delassus_operator` (and no fast path) instead of
            the compiled kernel (for checks; same core).
        guess: (n, N_max) bool or None: unilateral rows expected to push (e.g. the previous
            step's ``sol.mu > 0``), with the active bilateral rows the warm start of the
            active-set method (instead of "all active rows"). Only a starting point: if those
            rows are dependent or some of their multipliers pull, the method starts cold; the
            motion never depends on it. Saves the pivots when the contact state has not
            changed (a simulation between events).

    Returns:
        :class:`ContactSolution` with ``a_o`` (6,) [m/s², rad/s²], ``qdd`` (n, nv_max),
        ``mu`` (n, N_max), ``phi_dd`` (n, N_max).

    Raises:
        InputError: masks of the wrong shape or dtype, True on padding, NaN or infinity in
            the blocks.
        DynamicsError: infeasible (inconsistent bilateral constraints, or a unilateral
            contact that must penetrate), or a singular ``M_i``.
    """
    _check_blocks(blocks)
    b = blocks
    # padding of the masks is checked here for the reference, else by the compiled kernel
    uni = _mask(unilateral, "unilateral", b, reference)
    act = b.constraint_mask if active is None else _mask(active, "active", b, reference)
    if fast_path and not reference and b.n > 0 and bool((b.nv >= b.N).all()) \
            and (active is None or np.array_equal(act, b.constraint_mask)):
        # (with nv_i < N_i, S_i is singular by structure: the bilateral solve cannot be regular)
        _mask(unilateral, "unilateral", b)
        fast = _bilateral_fast_path(b, uni)
        if fast is not None:
            return fast
    if guess is not None:
        guess = _mask(guess, "guess", b)
    a_o, qdd, mu, Av, pivots = _solve(b, b.h, b.h_o, b.c, uni, act, "solve_unilateral",
                                      reference, guess)
    return ContactSolution(a_o, qdd, mu, Av - b.c, "active_set", pivots, uni.copy(),
                           act.copy(), b)


def _bilateral_fast_path(b: SystemBlocks, uni: np.ndarray) -> ContactSolution | None:
    """The bilateral object-first solution if it is regular and pushes on every unilateral row."""
    try:
        sol = solve_object_first(b, fallback=False)
    except (SingularityError, DynamicsError):
        return None
    if not (sol.mu[uni] >= 0.0).all():
        return None
    phi_dd = _rates(b, sol.a_o, sol.qdd, b.c)
    return ContactSolution(sol.a_o, sol.qdd, sol.mu, phi_dd, "bilateral", 0, uni.copy(),
                           b.constraint_mask.copy(), b)


def _rates(b: SystemBlocks, a_o: np.ndarray, qdd: np.ndarray, c: np.ndarray) -> np.ndarray:
    """``W_oᵀ a_o + Wᵀ v - c`` per row, (n, N_max), zero on padding."""
    out = np.einsum("nij,i->nj", b.W_o, a_o) + np.einsum("nij,ni->nj", b.W, qdd) - c
    out[~b.constraint_mask] = 0.0
    return out


def solve_impact(
    blocks: SystemBlocks,
    unilateral: np.ndarray,
    active: np.ndarray,
    phi_dot_minus: np.ndarray,
    restitution: np.ndarray,
    *,
    reference: bool = False,
) -> ImpactSolution:
    """Velocity-level impact law (Newton restitution) with the object-first structure.

    ``M_o Δv_o = Σ W_o,i P_i``, ``M_i Δq̇_i = W_i P_i``, ``φ̇⁺ = φ̇⁻ + W_oᵀ Δv_o + Wᵀ Δq̇``;
    active unilateral rows: ``0 ≤ P_k ⟂ φ̇⁺_k + e_k φ̇⁻_k ≥ 0``; active bilateral rows:
    ``φ̇⁺_k = 0``. Only ``M``, ``W``, ``W_o`` and ``M_o`` of the blocks are used (``h``,
    ``h_o``, ``c`` are ignored). The same mixed LCP as :func:`solve_unilateral` with
    ``b = (1 + e) φ̇⁻`` (unilateral) or ``φ̇⁻`` (bilateral); always the active-set method.

    This is Moreau's form of Newton's law, applied to every active row, the ones already
    separating (``φ̇⁻_k > 0``) included: such a row may take an impulse and leave with
    ``φ̇⁺_k = -e_k φ̇⁻_k < 0`` when the other impulses push it down. The kinetic energy changes
    by ``½ Σ_k P_k (1 - e_k) φ̇⁻_k``: it cannot increase when the rows that take an impulse
    were closing, and it is conserved when every ``e_k = 1``.

    Args:
        blocks: the system blocks.
        unilateral: (n, N_max) bool, unilateral rows (False on padding).
        active: (n, N_max) bool, rows that take part in the impact (False on padding).
        phi_dot_minus: (n, N_max) pre-impact normal velocities ``φ̇⁻`` [m/s] (values on
            padding are ignored).
        restitution: (n, N_max) Newton coefficients ``e`` in [0, 1] (ignored on padding and
            on bilateral rows).
        reference: use the numpy :func:`delassus_operator` instead of the compiled kernel
            (for checks; same core).

    Returns:
        :class:`ImpactSolution` with ``dv_o`` (6,), ``dqd`` (n, nv_max), ``P`` (n, N_max)
        [N s] and ``phi_dot_plus`` (n, N_max).

    Raises:
        InputError: wrong shapes or dtypes, True on padding, NaN, restitution outside [0, 1].
        DynamicsError: infeasible (as :func:`solve_unilateral`).
    """
    _check_blocks(blocks)
    b = blocks
    uni = _mask(unilateral, "unilateral", b)
    act = _mask(active, "active", b)
    vm = _rows(phi_dot_minus, "phi_dot_minus", b)
    e = _rows(restitution, "restitution", b)
    bad = b.constraint_mask & ~((e >= 0.0) & (e <= 1.0))
    if bad.any():
        i, k = np.argwhere(bad)[0]
        raise InputError(
            f"restitution: expected Newton coefficients in [0, 1], got {float(e[i, k])!r} at arm "
            f"{i}, row {k}"
        )
    rhs = np.where(uni, (1.0 + e) * vm, vm)
    dv_o, dqd, P, Av, pivots = _solve(b, np.zeros_like(b.h), np.zeros(6), -rhs, uni, act,
                                      "solve_impact", reference)
    return ImpactSolution(dv_o, dqd, P, Av + vm, "active_set", pivots, vm, e, uni, act, b)
