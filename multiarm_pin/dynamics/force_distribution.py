"""Force distribution: internal forces that keep every unilateral contact pushing (ch. 5).

The arms must apply the object wrench ``w = W_o μ``; the internal forces ``μ_I`` (null space of
``W_o``) are free. A frictionless point contact can only push, so we choose::

    minimise ‖μ‖²  subject to  W_o μ = w,  μ_k >= m for every unilateral multiplier k

(``m >= 0`` a margin [N]). With ``μ = W_o⁺ w + A z`` and ``A`` an orthonormal basis of the null
space, ``‖μ‖² = ‖W_o⁺ w‖² + ‖z‖²``, so this is the least-distance problem
``min ‖z‖ s.t. G z >= g`` (``G = A[U]``, ``g = m - (W_o⁺ w)[U]``), solved exactly by
Lawson & Hanson's reduction to non-negative least squares (``scipy.optimize.nnls``):
with ``E = [Gᵀ; gᵀ]``, ``f = [0; 1]`` and ``u = argmin_{u>=0} ‖E u - f‖``, the residual
``ρ = E u - f`` is zero iff the constraints are infeasible, else ``z = -ρ[:k] / ρ[k]``.

When no internal force meets the margin, :class:`DynamicsError` is raised; its message gives
the largest margin that is achievable (from a linear program).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linprog, lsq_linear, nnls

from multiarm_pin.dynamics.blocks import SystemBlocks
from multiarm_pin.dynamics.inverse_dynamics import InternalForceBasis, internal_force_basis
from multiarm_pin.exceptions import DynamicsError, InputError
from multiarm_pin.spatial import as_array


@dataclass(frozen=True)
class ForceDistribution:
    """The chosen contact multipliers.

    Attributes:
        mu: (n, N_max) multipliers [N] (positive = pushing), zero on padding.
        mu_flat: (Σ N_i,) the same, stacked arm-major.
        mu_I: (k,) internal-force coordinates in ``basis`` (pass to ``inverse_dynamics``).
        basis: the internal-force basis of ``mu_I``.
        margin: the margin that was asked for [N].
        min_unilateral: smallest unilateral multiplier [N] (``inf`` if none is unilateral).
    """

    mu: np.ndarray
    mu_flat: np.ndarray
    mu_I: np.ndarray
    basis: InternalForceBasis
    margin: float
    min_unilateral: float


MIN_NORM_TOL = 1e-9
"""Relative tolerance of :func:`min_norm_forces` (reachability of the wrench, feasibility)."""


def min_norm_forces(
    W_o,
    wrench,
    unilateral,
    margin: float | np.ndarray = 0.0,
    tol: float = MIN_NORM_TOL,
    svd_basis: InternalForceBasis | None = None,
) -> np.ndarray:
    """Smallest multipliers producing ``wrench`` with every unilateral one >= ``margin``.

    Args:
        W_o: (6, K) stacked object wrench bases (wrench ``[f; m]`` at the COM, world axes,
            per unit multiplier).
        wrench: (6,) object wrench the contacts must produce [N, N m].
        unilateral: (K,) bool, True for multipliers that must be >= ``margin``.
        margin: the margin ``m >= 0`` [N], one for all or (K,) one per multiplier.
        tol: relative tolerance (reachability of the wrench, feasibility).
        svd_basis: the ``"svd"`` :class:`InternalForceBasis` of ``W_o`` when the caller has
            it already (it must be orthonormal); built here otherwise.

    Returns:
        ``μ`` (K,) minimising ``‖μ‖²`` under the constraints.

    Raises:
        DynamicsError: the wrench cannot be produced, or no internal force keeps every
            unilateral multiplier >= margin (the message gives the best achievable margin).
        InputError: wrong shapes, NaN, negative margin.
    """
    W = as_array(W_o, (6, None), "W_o (6 x K)")
    K = W.shape[1]
    w = as_array(wrench, (6,), "wrench")
    U = np.asarray(unilateral)
    if U.shape != (K,) or U.dtype != bool:
        raise InputError(f"unilateral: expected a bool array of shape ({K},), got {U!r}")
    m_vec = np.broadcast_to(np.asarray(margin, dtype=float), (K,)) if np.ndim(margin) == 0 \
        else np.asarray(margin, dtype=float)
    if m_vec.shape != (K,) or not (np.all(np.isfinite(m_vec)) and np.all(m_vec >= 0.0)):
        raise InputError(f"margin: expected a finite number >= 0 [N] or {K} of them, got "
                         f"{margin!r}")
    if svd_basis is None:
        basis = internal_force_basis(W, "svd")
    elif svd_basis.method != "svd" or svd_basis.A_o.shape[0] != K:
        raise InputError(f"svd_basis: expected the 'svd' basis of a 6 x {K} W_o")
    else:
        basis = svd_basis
    return _min_norm_forces(W, w, U, np.array(m_vec, dtype=float), tol, basis)


BEST_EFFORT_SLACK = 1e-7
"""Relative relaxation of the margins [N per unit of the wrench's largest entry] in the best-effort
distribution's minimum-norm step (:func:`distribute_with_supports`): its bounded least
squares solution meets the margins, some of them exactly (a force at 0), so the least-norm
problem's feasibility would rest on round-off; with the margins relaxed it is strictly
feasible, by 1e-7 of the wrench's scale, far above round-off (1e-15) and above the polish's
active-set tolerance (1e-9). The forces are clipped back onto the margins afterwards."""


def _min_norm_forces(W: np.ndarray, w: np.ndarray, U: np.ndarray, m_vec: np.ndarray,
                     tol: float, basis: InternalForceBasis) -> np.ndarray:
    """:func:`min_norm_forces` on checked inputs: ``m_vec`` (K,) any finite margins [N]."""
    m_max = float(m_vec.max(initial=0.0))
    mu_p = basis.W_o_pinv @ w
    miss = np.linalg.norm(W @ mu_p - w)
    if miss > tol * max(np.linalg.norm(w), 1e-12):
        raise DynamicsError(
            f"the contacts cannot produce the required object wrench (W_o has rank "
            f"{basis.rank} < 6; unreachable part {miss:.3g})"
        )
    idx = np.flatnonzero(U)
    if idx.size == 0:
        return mu_p
    A = basis.A_o
    G = A[idx]
    g = m_vec[idx] - mu_p[idx]
    scale = max(np.abs(mu_p).max(), m_max, 1e-12)
    # the infeasibility report on the uniform shortfall: the largest t with
    # μ_U >= m_U - m_max + t (t = m_max when the margins are met)
    shifted = mu_p[idx] - m_vec[idx] + m_max
    k = A.shape[1]
    if k == 0:
        if np.all(g <= tol * scale):
            return mu_p
        _raise_infeasible(shifted, G, m_max)
    # Least-distance programming via NNLS (Lawson & Hanson 1974, ch. 23).
    E = np.vstack([G.T, g[None, :]])
    f = np.zeros(k + 1)
    f[k] = 1.0
    u, _ = nnls(E, f, maxiter=50 * (k + 1 + idx.size))
    rho = E @ u - f
    if -rho[k] <= 1e-12:
        _raise_infeasible(shifted, G, m_max)
    z = -rho[:k] / rho[k]
    mu = mu_p + A @ z
    if np.any(mu[idx] < m_vec[idx] - tol * scale):  # pragma: no cover - NNLS round-off guard
        _raise_infeasible(shifted, G, m_max)
    return _polish(W, w, U, m_vec, mu)


def _polish(W: np.ndarray, w: np.ndarray, U: np.ndarray, margin: np.ndarray,
            mu: np.ndarray) -> np.ndarray:
    """The exact minimiser on the active set of ``mu`` (the NNLS solution), if it is optimal.

    The LDP/NNLS route loses a few digits (relative errors of order 1e-11 in ``μ``); with its
    active set ``A`` (unilateral multipliers at the margin) the KKT conditions are linear:
    ``μ_A = m`` and ``μ_F`` the minimum-norm solution of ``W_F μ_F = w - m W_A 1`` (SVD
    least squares). That solution is returned when it is primal and dual feasible to 1e-9
    (relative), i.e. the minimiser to round-off; otherwise ``mu`` itself.
    """
    scale = max(float(np.abs(mu).max(initial=0.0)), float(margin.max(initial=0.0)), 1e-300)
    act = U & (mu <= margin + 1e-9 * scale)
    free = ~act
    Wf = W[:, free]
    rhs = w - W[:, act] @ margin[act]
    y, _, rank, _ = np.linalg.lstsq(Wf, rhs, rcond=None)
    if rank < 6:
        return mu
    lam = np.linalg.lstsq(Wf.T, y, rcond=None)[0]  # μ_F = W_Fᵀ λ (y is in the row space)
    nu = margin[act] - W[:, act].T @ lam
    out = np.array(margin, dtype=float)
    out[free] = y
    tol = 1e-9 * scale
    if (np.abs(W @ out - w).max() <= tol and np.all(out[U] >= margin[U] - tol)
            and np.all(nu >= -tol)):
        return out
    return mu


def _best_margin(mu_p_U: np.ndarray, G: np.ndarray, cap: float) -> float:
    """Largest ``t <= cap`` such that ``mu_p_U + G z >= t`` for some ``z`` (an LP)."""
    u, k = G.shape
    c = np.zeros(k + 1)
    c[-1] = -1.0
    A_ub = np.hstack([-G, np.ones((u, 1))])
    res = linprog(c, A_ub=A_ub, b_ub=mu_p_U, bounds=[(None, None)] * k + [(None, cap)],
                  method="highs")
    return float(res.x[-1]) if res.status == 0 else float("nan")


def _raise_infeasible(mu_p_U: np.ndarray, G: np.ndarray, margin: float) -> None:
    best = _best_margin(mu_p_U, G, margin)
    size = float(np.abs(mu_p_U).max()) if mu_p_U.size else 0.0
    if np.isfinite(best) and best >= margin - 1e-9 * max(1.0, margin, size):
        # the LP reaches the margin: the least-norm solve failed for numerical reasons
        raise DynamicsError(
            f"the internal forces for a {margin:g} N margin exist (a linear program reaches it) "
            f"but the least-norm solve failed; the required contact forces are of order "
            f"{size:.3g} N, which suggests a runaway object wrench (check the controller gains "
            "and the state)"
        )
    raise DynamicsError(
        f"no internal force keeps every unilateral contact force >= {margin:g} N: the largest "
        f"achievable smallest force is {best:.6g} N (the grasp is not form closure for this "
        f"load, or the margin is too large; required forces of order {size:.3g} N)"
    )


@dataclass(frozen=True)
class SupportedDistribution:
    """Arm contact forces planned together with the forces of the supports that press.

    Attributes:
        forces: the arms' multipliers (:class:`ForceDistribution`; its ``mu_I`` in the basis
            of the arms' stacked ``W_o``).
        support_mu: (K,) planned support forces [N] (0 on rows not planned).
        a_o: (6,) the object acceleration ``[ẍ; ω̇]`` at the COM, world axes, that these
            forces give: the desired one with the pressing rows kept on their planes and the
            wrench no contact can make left out.
        support_wrench: (6,) ``Σ_k λ_k [n_k; r_k × n_k]`` at the COM [N, N m].
        unreached: (6,) part of ``M_o a - h_o`` no contact can make [N, N m] (left to the
            motion: ``a_o`` carries it).
    """

    forces: ForceDistribution
    support_mu: np.ndarray
    a_o: np.ndarray
    support_wrench: np.ndarray
    unreached: np.ndarray


def supported_acceleration(M_o: np.ndarray, a: np.ndarray, G: np.ndarray,
                           kappa: np.ndarray) -> np.ndarray:
    """``a`` with the rows ``G`` kept on their planes: ``G a' + κ = 0``, closest in ``M_o``.

    ``a' = a - M_o⁻¹ Gᵀ (G M_o⁻¹ Gᵀ)⁺ (G a + κ)`` (Gauss's principle: the acceleration the
    object takes when the rows push as bilateral constraints against the wrench ``M_o a``).

    Args:
        M_o: (6, 6) object inertia at the COM, world axes.
        a: (6,) desired acceleration ``[ẍ; ω̇]``.
        G: (P, 6) rows ``[n; r × n]`` of the pressing support points.
        kappa: (P,) their velocity-product terms (``φ̈ = G a + κ``).
    """
    if not len(G):
        return np.array(a, dtype=float)
    Minv_Gt = np.linalg.solve(M_o, G.T)
    lam = np.linalg.pinv(G @ Minv_Gt, rcond=1e-12) @ (G @ a + kappa)
    return a - Minv_Gt @ lam


def distribute_with_supports(
    blocks: SystemBlocks,
    a_desired,
    unilateral,
    margin: float | np.ndarray,
    G_support: np.ndarray,
    kappa_support: np.ndarray,
    support_margin: np.ndarray,
    best_effort: bool = False,
) -> SupportedDistribution:
    """Arm contact forces and support forces together (the object resting on supports).

    The support rows planned to press (``support_margin[k]`` finite, >= 0) take part in
    the distribution as unilateral multipliers ``λ_k >= support_margin[k]``; the others
    (NaN: released, or not touching) get none. In order:

    1. ``a = supported_acceleration(M_o, a_desired, G_P, κ_P)`` (the pressing rows stay on
       their planes);
    2. ``w = M_o a - h_o``; its part in the range of ``W = [W_o (arms) | G_Pᵀ]`` closest in
       the ``M_o⁻¹`` metric, ``w_r`` (``W x``, ``x = argmin ‖M_o^{-1/2} (W x - w)‖``), so
       that the rest ``w - w_r`` changes no pressing row's ``φ̈`` (``G_P M_o⁻¹ (w - w_r) =
       0``) and is left to the motion: ``a_o = a - M_o⁻¹ (w - w_r)``;
    3. ``[μ; λ] = argmin ‖μ‖² + ‖λ‖²`` with ``W [μ; λ] = w_r``, ``μ_k >= margin`` on the
       arms' unilateral rows, ``λ_k >= support_margin[k]``
       (:func:`min_norm_forces` with per-multiplier margins).

    With the arms' torques from :func:`~multiarm_pin.dynamics.inverse_dynamics.
    inverse_dynamics` on blocks whose ``h_o`` includes ``support_wrench`` (the supports act
    like an external wrench), the forward dynamics returns ``a_o``, ``μ`` and ``λ``.

    Args:
        blocks: the arms' blocks (touching rows; ``W_o``, ``M_o``, ``h_o``, ``N`` are used).
        a_desired: (6,) desired object acceleration [m/s², rad/s²], world axes at the COM.
        unilateral: (n, N_max) bool, the arms' rows that must push with ``margin``.
        margin: the arms' margin [N], one for all or (n, N_max) one per row.
        G_support: (K, 6) the support rows ``[n; r × n]`` (world axes at the COM).
        kappa_support: (K,) their velocity-product terms [m/s²].
        support_margin: (K,) least force [N] of each support row planned to press, NaN for
            rows not planned.
        best_effort: when no forces meet the margins, instead of raising, the smallest
            forces that meet them and make the wrench closest to ``w`` in the ``M_o⁻¹``
            metric (bounded least squares, :func:`scipy.optimize.lsq_linear`, then
            :func:`min_norm_forces` on its wrench); the rest of ``w`` is left to the motion
            (``unreached``, in ``a_o``), as in step 2.

    Raises:
        DynamicsError: no forces meet the margins (see :func:`min_norm_forces`), unless
            ``best_effort``.
        InputError: wrong shapes.
    """
    b = blocks
    G_all = as_array(G_support, (None, 6), "G_support (K x 6)")
    K = len(G_all)
    kap = as_array(kappa_support, (K,), "kappa_support")
    sm = np.asarray(support_margin, dtype=float)
    if sm.shape != (K,) or np.any(sm < 0.0):
        raise InputError(f"support_margin: expected {K} forces >= 0 [N] or NaN, got {sm!r}")
    P = np.isfinite(sm)
    G = G_all[P]
    a = supported_acceleration(b.M_o, as_array(a_desired, (6,), "a_desired"), G, kap[P])
    w = b.M_o @ a - b.h_o
    W_arm = b.stacked_W_o()
    W = np.hstack([W_arm, G.T])
    # M_o^{-1/2} by the symmetric eigendecomposition (M_o is symmetric positive definite)
    ev, V = np.linalg.eigh(b.M_o)
    S = (V / np.sqrt(ev)) @ V.T
    x = np.linalg.lstsq(S @ W, S @ w, rcond=None)[0] if W.shape[1] else np.zeros(0)
    w_r = W @ x
    unreached = w - w_r
    a_o = a - np.linalg.solve(b.M_o, unreached)
    U_arm = b.flatten_mu(np.asarray(unilateral, dtype=bool))
    Ka = W_arm.shape[1]
    U = np.concatenate([U_arm, np.ones(len(G), dtype=bool)])
    m_arm = (np.full(len(U_arm), float(margin)) if np.ndim(margin) == 0
             else b.flatten_mu(np.asarray(margin, dtype=float)))
    margins = np.concatenate([np.where(U_arm, m_arm, 0.0), sm[P]])
    w_basis = internal_force_basis(W, "svd") if W.shape[1] else None  # for both solves
    try:
        mu_all = (min_norm_forces(W, w_r, U, margins, svd_basis=w_basis) if W.shape[1]
                  else np.zeros(0))
    except DynamicsError:
        if not best_effort:
            raise
        # pushing forces only: the wrench closest to w they make (every multiplier here is
        # unilateral or bilateral as U says)
        lb = np.where(U, margins, -np.inf)
        x = lsq_linear(S @ W, S @ w, bounds=(lb, np.inf), method="bvls", tol=1e-12).x
        # that wrench by the smallest such forces (the bounded least squares leaves the
        # internal forces arbitrary; x itself shows they exist). x lies on the margins'
        # boundary where it is bounded, so the margins are relaxed by BEST_EFFORT_SLACK of
        # the wrench's scale: x is then strictly feasible and the least-distance problem's
        # verdict does not rest on round-off
        wx = W @ x  # unique, unlike x (the slack's scale: the same whatever x the LSQ chose)
        slack = BEST_EFFORT_SLACK * max(float(np.abs(wx).max(initial=0.0)),
                                        float(margins.max(initial=0.0)), 1e-12)
        try:
            mu_all = _min_norm_forces(W, wx, U, np.where(U, margins - slack, 0.0),
                                      MIN_NORM_TOL, w_basis)
            # back onto the margins (a change of at most the slack; the motion takes the
            # wrench it changes, below)
            mu_all = np.where(U, np.maximum(mu_all, margins), mu_all)
        except DynamicsError:  # pragma: no cover - x is strictly feasible: not reached
            mu_all = x
        unreached = w - W @ mu_all
        a_o = a - np.linalg.solve(b.M_o, unreached)
    mu_flat = mu_all[:Ka]
    lam = np.zeros(K)
    lam[P] = mu_all[Ka:]
    basis = internal_force_basis(W_arm, "svd")
    forces = ForceDistribution(
        mu=b.unflatten_mu(mu_flat), mu_flat=mu_flat, mu_I=basis.coordinates(mu_flat),
        basis=basis, margin=float(np.max(margin, initial=0.0)),
        min_unilateral=float(mu_flat[U_arm].min()) if U_arm.any() else float("inf"))
    return SupportedDistribution(forces, lam, a_o, G.T @ mu_all[Ka:], unreached)


def distribute_forces(
    blocks: SystemBlocks,
    wrench,
    unilateral,
    margin: float = 0.0,
    basis: InternalForceBasis | str = "svd",
) -> ForceDistribution:
    """Choose the internal forces of a system's grasp (see :func:`min_norm_forces`).

    Args:
        blocks: the system blocks (only ``W_o`` and ``N`` are used).
        wrench: (6,) object wrench the contacts must produce, ``M_o a_o - h_o`` [N, N m].
        unilateral: (n, N_max) bool, True for multipliers of frictionless contacts that must
            stay >= ``margin`` (padding ignored).
        margin: the margin ``m >= 0`` [N].
        basis: basis for the returned ``mu_I`` (an :class:`InternalForceBasis` of
            ``blocks.stacked_W_o()``, or ``"svd"``/``"echelon"``).

    Returns:
        The multipliers (:class:`ForceDistribution`).

    Raises:
        DynamicsError: infeasible (see :func:`min_norm_forces`).
        InputError: wrong shapes.
    """
    mask = np.asarray(unilateral)
    if mask.shape != (blocks.n, blocks.N_max) or mask.dtype != bool:
        raise InputError(
            f"unilateral: expected a bool array of shape ({blocks.n}, {blocks.N_max}), "
            f"got {mask!r}"
        )
    W_o = blocks.stacked_W_o()
    if isinstance(basis, str):
        basis = internal_force_basis(W_o, basis)
    U = blocks.flatten_mu(mask)
    # the minimum-norm solve needs the orthonormal (SVD) basis: reuse it when it is the one
    svd = basis if basis.method == "svd" else None
    mu_flat = min_norm_forces(W_o, wrench, U, margin, svd_basis=svd)
    return ForceDistribution(
        mu=blocks.unflatten_mu(mu_flat),
        mu_flat=mu_flat,
        mu_I=basis.coordinates(mu_flat),
        basis=basis,
        margin=float(margin),
        min_unilateral=float(mu_flat[U].min()) if U.any() else float("inf"),
    )
