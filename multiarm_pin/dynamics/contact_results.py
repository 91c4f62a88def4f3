"""Results of the unilateral contact solves: solutions and their residuals.

:class:`ContactSolution` (forces and accelerations), :class:`ImpactSolution` (impulses and
velocity jumps) and their :class:`ContactResiduals`.

Both are produced by :mod:`multiarm_pin.dynamics.unilateral`; padded arrays follow the
(n, nv_max) / (n, N_max) layout of :class:`~multiarm_pin.dynamics.blocks.SystemBlocks`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from multiarm_pin.dynamics.blocks import SystemBlocks

SEPARATION_RTOL = 1e-9
""":attr:`ContactSolution.separating` needs ``φ̈ > SEPARATION_RTOL · max |φ̈|``."""


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
    neg = np.concatenate(([0.0], -mu[uni], -gap[uni]))
    terms = [Mo_a, h_o, Wmu_o, Mqdd, h, Wmu, rate]
    return ContactResiduals(
        object=float(np.linalg.norm(Mo_a - h_o - Wmu_o)),
        arms=float(np.linalg.norm(Mqdd - h - Wmu)),
        constraints=float(np.linalg.norm(rate[bil])),
        complementarity=_complementarity(mu, gap, uni),
        sign=float(max(neg.max(), 0.0)),
        scale=float(max(np.linalg.norm(t) for t in terms)),
    )


def _complementarity(force: np.ndarray, gap: np.ndarray, rows: np.ndarray) -> float:
    """``max |min(force_k, gap_k)|`` over the (n, N_max) bool ``rows`` (0 when there are none)."""
    if not rows.any():
        return 0.0
    return float(np.abs(np.minimum(force[rows], gap[rows])).max())


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
        return _complementarity(self.mu, self.phi_dd, self.active & self.unilateral)

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
        gap = self.phi_dot_plus + self.restitution * self.phi_dot_minus
        return _complementarity(self.P, gap, self.active & self.unilateral)

    def residuals(self) -> ContactResiduals:
        """Residuals of the impact equations (``h`` terms are zero) and of complementarity."""
        b = self.blocks
        gap = self.phi_dot_plus + self.restitution * self.phi_dot_minus
        return _residuals(b, self.dv_o, self.dqd, self.P, np.zeros(6), np.zeros_like(b.h),
                          self.phi_dot_plus, self.unilateral, self.active, gap)

