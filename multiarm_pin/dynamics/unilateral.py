"""Unilateral frictionless contacts: exact mixed-LCP forward dynamics and impacts, object-first.

Problem. With the blocks of :class:`~multiarm_pin.dynamics.blocks.SystemBlocks`
(``docs/ARCHITECTURE.md``: ``M_o a_o = h_o + Σ_i W_o,i μ_i``, ``M_i q̈_i = h_i + W_i μ_i``)
the normal acceleration of contact row ``k`` is ``φ̈ = W_oᵀ a_o + Wᵀ q̈ - c`` (stacked over
arms). Eliminating the accelerations gives ``φ̈ = G μ + b`` with the Delassus operator::

    G = blockdiag_i(W_iᵀ M_i⁻¹ W_i) + W_oᵀ M_o⁻¹ W_o      (per-arm blocks + rank-6 coupling)
    b = W_oᵀ M_o⁻¹ h_o + Wᵀ M⁻¹ h - c                      (φ̈ of the motion with μ = 0)

built arm by arm (:func:`~multiarm_pin.dynamics.delassus.delassus_operator`; the dense
``J M⁻¹ Jᵀ`` over all arms is never formed), and the mixed LCP on the active rows is::

    bilateral rows:   φ̈_k = 0, μ_k free;     unilateral rows:   0 ≤ μ_k ⟂ φ̈_k ≥ 0.

It is the optimality system of Gauss's principle, the strictly convex QP in the accelerations
``v = (a_o, q̈)``: ``min ½ ‖v - v_free‖²_M`` subject to ``φ̈_k(v) = 0`` (bilateral) and
``φ̈_k(v) ≥ 0`` (unilateral), whose multipliers are ``μ``. So the motion is unique whenever the
problem is feasible, even when ``G`` is only positive semi-definite (redundant rows, e.g. four
coplanar vertices on a table, or rows of an arm with ``nv_i = 0`` acting on the object only);
``μ`` is then not unique.

Method and termination: the dual active-set method of Goldfarb and Idnani written on ``G``,
exact to round-off (:mod:`multiarm_pin._compiled.mlcp`). The operator ``G``, ``b`` is built
object-first, by a compiled kernel that does the whole solve in one call or by the numpy
reference (``reference=True``), which also takes the rare cases the kernel hands over (a
singular ``M_i``, non-finite values) and raises the documented errors
(:mod:`multiarm_pin.dynamics.delassus`). The results are
:class:`~multiarm_pin.dynamics.contact_results.ContactSolution` and
:class:`~multiarm_pin.dynamics.contact_results.ImpactSolution`
(:mod:`multiarm_pin.dynamics.contact_results`); this module holds the two solves, their input
checks and the fast path, and re-exports those names.

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
tens of contacts. Timings against the bilateral solves: ``benchmarks/results/unilateral.md``.

Impacts (:func:`solve_impact`) are the same problem at velocity level: with ``h = h_o = 0``
the impulse ``P`` gives ``φ̇⁺ = φ̇⁻ + G P``, and Newton's law
``0 ≤ P_k ⟂ φ̇⁺_k + e_k φ̇⁻_k ≥ 0`` is the mixed LCP with ``b = (1 + e) φ̇⁻`` on unilateral
rows (``b = φ̇⁻`` and ``φ̇⁺ = 0`` on bilateral rows).
"""

from __future__ import annotations

import numpy as np

from multiarm_pin._compiled.delassus import ACT_PADDING, UNI_PADDING, contact_kernel
from multiarm_pin._compiled.mlcp import (
    CONSISTENCY_RTOL,
    DEPENDENCY_RTOL,
    INCONSISTENT,
    INFEASIBLE,
    MAX_PIVOTS,
    OK,
    VIOLATION_RTOL,
    mlcp,
)
from multiarm_pin.dynamics.blocks import SystemBlocks
from multiarm_pin.dynamics.contact_results import (
    SEPARATION_RTOL,
    ContactResiduals,
    ContactSolution,
    ImpactSolution,
)
from multiarm_pin.dynamics.delassus import DelassusOperator, delassus_operator
from multiarm_pin.dynamics.object_first import solve_object_first
from multiarm_pin.exceptions import DynamicsError, InputError, SingularityError

UNILATERAL_SOLVERS = ("bilateral", "active_set")
"""The solver names a unilateral solve records (``ContactSolution.solver``): its bilateral
fast path (the object-first solve, every unilateral multiplier ``>= 0``), the active-set
method; in the order of the compiled contact loop's solver codes."""


def lcp_error(what: str, status: int, name: str, value: float, pivots: int) -> DynamicsError:
    """The error of a failed :func:`~multiarm_pin._compiled.mlcp.mlcp` status.

    For the caller ``what`` and the row ``name``.
    """
    if status == INFEASIBLE:
        return DynamicsError(
            f"{what}: the contacts cannot all hold: unilateral row ({name}) would penetrate "
            f"({value:.3g}) and no force can prevent it; the bilateral constraints or the "
            "other contacts forbid the motion"
        )
    if status == INCONSISTENT:
        return DynamicsError(
            f"{what}: the bilateral constraints are inconsistent: row ({name}) depends on the "
            f"other active rows but its rate cannot be zeroed (residual {value:.3g}); check "
            "c (velocity consistency) and W"
        )
    return DynamicsError(  # pragma: no cover - safety net of the finite method
        f"{what}: the active-set method did not terminate in {pivots} pivots (last row "
        f"{name}); round-off cycling, please report the state"
    )


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
        status, pivots, arm, row, value = contact_kernel(
            _c(b.M), _c(h), _c(b.W), _c(b.W_o), _c(c), _c(b.M_o), _c(h_o), b.nv, b.N,
            _c(uni), _c(act), _c(act if guess is None else guess), guess is not None,
            DEPENDENCY_RTOL, VIOLATION_RTOL, CONSISTENCY_RTOL, a_o, qdd, mu, Av)
        if status == OK:
            return a_o, qdd, mu, Av, int(pivots)
        if status in (UNI_PADDING, ACT_PADDING):
            name = "unilateral" if status == UNI_PADDING else "active"
            raise _padding_error(name, b, int(arm), int(row))
        if status in (INFEASIBLE, INCONSISTENT, MAX_PIVOTS):
            raise lcp_error(what, status, f"arm {arm}, row {row}", value, pivots)
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
    status, pivots, q = mlcp(G, bb, np.ascontiguousarray(uni[cm][idx]), DEPENDENCY_RTOL,
                              VIOLATION_RTOL * scale, CONSISTENCY_RTOL * scale,
                              1000 + 20 * p, np.ascontiguousarray(start), mu_a, phi, in_a)
    if status != OK:
        raise lcp_error(what, status, _row_name(b, int(idx[q])), phi[q], pivots)
    flat = np.zeros(b.n_constraints)
    flat[idx] = mu_a
    mu = b.unflatten_mu(flat)
    a_o, qdd = D.motion(mu, b)
    return a_o, qdd, mu, _rates(b, a_o, qdd, np.zeros_like(b.c)), int(pivots)


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
    return ContactSolution(a_o, qdd, mu, Av - b.c, UNILATERAL_SOLVERS[1], pivots, uni.copy(),
                           act.copy(), b)


def _bilateral_fast_path(b: SystemBlocks, uni: np.ndarray) -> ContactSolution | None:
    """The bilateral object-first solution if it is regular and pushes on every unilateral row."""
    try:
        sol = solve_object_first(b)
    except (SingularityError, DynamicsError):
        return None
    if not (sol.mu[uni] >= 0.0).all():
        return None
    phi_dd = _rates(b, sol.a_o, sol.qdd, b.c)
    return ContactSolution(sol.a_o, sol.qdd, sol.mu, phi_dd, UNILATERAL_SOLVERS[0], 0, uni.copy(),
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
    return ImpactSolution(dv_o, dqd, P, Av + vm, UNILATERAL_SOLVERS[1], pivots, vm, e, uni, act,
                          b)

__all__ = [
    "CONSISTENCY_RTOL",
    "DEPENDENCY_RTOL",
    "SEPARATION_RTOL",
    "UNILATERAL_SOLVERS",
    "VIOLATION_RTOL",
    "ContactResiduals",
    "ContactSolution",
    "DelassusOperator",
    "ImpactSolution",
    "delassus_operator",
    "solve_impact",
    "solve_unilateral",
]
