"""A joint: the set of frictionless point contacts between one arm's tool and the object.

Thesis Sec 3.7-3.9. At construction the joint is evaluated at its *reference* relative
placement (the tool where it is when the joint is assembled, expressed in the object
frame): every contact must touch there, contacts whose wrenches are linear combinations of
earlier ones are dropped (the kept ones are an independent basis of the constraint space,
so ``rank = n_constraints = N_i`` and ``dof = 6 - rank``), and the motion coordinates
``α_i`` are chosen (Sec 3.8.1).

Matrices (``N = n_constraints``, columns in the order of :attr:`Joint.kept`):

- ``G_tool`` (N, 6), ``G_object`` (N, 6): the constraint rows of docs/ARCHITECTURE.md
  (LWA, world axes, at the tool origin / the COM).
- ``W_mi`` (6, N): thesis' wrench basis in the tool frame about the tool origin; column k is
  the wrench the contact applies *to the object* per unit compressive force
  (``W_mi = -diag(R_toolᵀ, R_toolᵀ) G_toolᵀ``).
- ``W_oi`` (6, N): thesis' object-frame matrix, ``-diag(R_oᵀ, R_oᵀ) G_objectᵀ``, so that
  Eq 3.11 ``W_oi = -[[R, 0], [(x×)R, R]] W_mi`` holds with ``R`` the tool axes in object axes
  and ``x`` the tool origin in the object frame. (Thesis multipliers are ``-μ``.)
- ``W_mi_o = diag(R, R) W_mi`` (6, N): ``W_mi^o`` of Eq 3.21.
- ``T`` (6, 6 - N): basis of the null space of ``W_mi_oᵀ`` (Eq 3.21): allowed twists of the
  tool relative to the object, at the tool origin, in object axes, with the rows
  :attr:`Joint.alpha_rows` equal to the identity (so ``α_i`` are those components of the
  relative twist, guidelines of Sec 3.8.1); ``T_dot`` its time derivative.
- Joint space: ``W̄_i = J_iᵀ G_toolᵀ``, ``W̄_oi = G_objectᵀ``, drift
  ``c_i = -G_tool J̇q̇ - κ`` so that ``W̄_oiᵀ a_o + W̄_iᵀ q̈_i = c_i`` is ``φ̈ = 0``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from multiarm_pin.constraints.contact import Contact, ContactState
from multiarm_pin.exceptions import ConstraintError, InitialGapError, InputError, SingularityError
from multiarm_pin.model.kinematics import BodyKinematics
from multiarm_pin.spatial import as_array

TWIST_NAMES = ("vx", "vy", "vz", "wx", "wy", "wz")
"""Names of the components of a relative twist, in the rows order of ``T``."""

RANK_TOLERANCE = 1e-7
"""Relative singular-value threshold below which a contact wrench counts as redundant."""

ALPHA_THRESHOLD = 0.2
"""Least singular value a chosen ``α`` row set must keep (rows of an orthonormal basis)."""

INITIAL_GAP_TOLERANCE = 1e-6
"""Largest gap [m] a contact may have where it is assembled: at its joint's reference
placement and in a system's initial state (scenarios, simulations)."""


@dataclass(frozen=True)
class JointTerms:
    """One joint at one state (N = independent constraints, k = 6 - N = DOF).

    Attributes:
        phi: (N,) gaps [m].
        phi_dot: (N,) gap rates [m/s].
        G_tool: (N, 6) rows at the tool origin, world axes (LWA twist of the tool).
        G_object: (N, 6) rows at the object COM, world axes (LWA twist of the object).
        kappa: (N,) velocity-product terms [m/s^2].
        contact_points: (N, 3) world contact locations [m].
        normals: (N, 3) world unit directions in which each contact pushes the object.
        W_mi: (6, N) thesis wrench basis, tool frame about the tool origin.
        W_oi: (6, N) thesis wrench basis, object frame about the COM (Eq 3.11).
        W_mi_o: (6, N) ``W_mi`` rotated into object axes (about the tool origin).
        W_mi_o_dot: (6, N) time derivative of ``W_mi_o`` (in object axes).
        relative_twist: (6,) tool relative to object, at the tool origin, object axes.
        T: (6, k) motion space (rows ``alpha_rows`` are the identity).
        T_dot: (6, k) time derivative of ``T``.
        alpha: (k,) the motion coordinates' rates, ``relative_twist[alpha_rows]``.
    """

    phi: np.ndarray
    phi_dot: np.ndarray
    G_tool: np.ndarray
    G_object: np.ndarray
    kappa: np.ndarray
    contact_points: np.ndarray
    normals: np.ndarray
    W_mi: np.ndarray
    W_oi: np.ndarray
    W_mi_o: np.ndarray
    W_mi_o_dot: np.ndarray
    relative_twist: np.ndarray
    T: np.ndarray
    T_dot: np.ndarray
    alpha: np.ndarray

    @property
    def W_bar_o(self) -> np.ndarray:
        """Object-side basis ``W̄_oi = G_objectᵀ`` (6, N), LWA at the COM."""
        return self.G_object.T

    def W_bar(self, jacobian) -> np.ndarray:
        """Joint-space basis ``W̄_i = J_iᵀ G_toolᵀ`` (nv, N).

        Args:
            jacobian: (6, nv) LWA Jacobian of the tool frame.
        """
        J = as_array(jacobian, (6, None), "tool Jacobian (6, nv)")
        return J.T @ self.G_tool.T

    def drift(self, tool_bias_acceleration) -> np.ndarray:
        """``c_i = -G_tool J̇q̇ - κ`` (N,) [m/s^2].

        Args:
            tool_bias_acceleration: (6,) ``J̇q̇``, the tool's classical LWA acceleration at
                ``q̈ = 0`` [m/s^2, rad/s^2].
        """
        a = as_array(tool_bias_acceleration, (6,), "tool bias acceleration J̇q̇ (6,)")
        return -self.G_tool @ a - self.kappa

    def drift_baumgarte(self, tool_bias_acceleration, alpha: float, beta: float) -> np.ndarray:
        """Baumgarte-stabilised drift ``c_i - 2α φ̇ - β² φ`` (N,) (Sec 4.3).

        Args:
            tool_bias_acceleration: (6,) ``J̇q̇`` as in :meth:`drift`.
            alpha: damping rate α [1/s].
            beta: stiffness rate β [1/s].
        """
        return self.drift(tool_bias_acceleration) - 2.0 * alpha * self.phi_dot - beta**2 * self.phi


class Joint:
    """A set of contacts between a tool and the object, reduced to an independent basis.

    Args:
        contacts: the contacts (at least one).
        tool_in_object: the tool's placement in the object frame at which the joint is
            assembled (``pin.SE3``); every contact must touch there.
        kind: joint type name (``"revolute"``, ...), for messages.
        name: label for messages.
        expected_dof: if given, the number of degrees of freedom the contacts must leave.
        alpha_rows: rows of ``T`` to make the identity (indices 0..5 or names from
            ``TWIST_NAMES``); chosen automatically (translations first) when None.
        gap_tolerance: largest gap [m] accepted at the reference placement.
        unilateral: if given, overrides every contact's :attr:`Contact.unilateral` (a
            scenario's per-joint ``unilateral: true/false``); None keeps the contacts' own.
        starts_apart: the unilateral contacts may start separated (e.g. a gripper that
            approaches the object and touches down during the run): :meth:`check_initial`
            does not check their gaps (a tip beside its face has a negative gap to the face's
            extended plane without touching anything: whoever places the tool checks that
            no tip starts in the object, as the scenario builder does). The contacts are
            still defined at ``tool_in_object``.

    Raises:
        ConstraintError: no contacts, a contact not touching its surface at the reference,
            a rank different from ``6 - expected_dof``, or unusable ``alpha_rows``.
    """

    def __init__(
        self,
        contacts: Sequence[Contact],
        tool_in_object: pin.SE3,
        kind: str = "custom",
        name: str = "",
        expected_dof: int | None = None,
        alpha_rows: Sequence[int | str] | None = None,
        gap_tolerance: float = INITIAL_GAP_TOLERANCE,
        unilateral: bool | None = None,
        starts_apart: bool = False,
    ):
        self.kind = kind
        self.starts_apart = bool(starts_apart)
        self.name = name or kind
        self.contacts: tuple[Contact, ...] = tuple(contacts)
        if not self.contacts:
            raise ConstraintError(f"joint {self.name!r}: needs at least one contact")
        for k, c in enumerate(self.contacts):
            if not isinstance(c, Contact):
                raise ConstraintError(
                    f"joint {self.name!r}: contact {k} is a {type(c).__name__}, expected Contact"
                )
        if unilateral is not None:
            if not isinstance(unilateral, bool | np.bool_):
                raise ConstraintError(
                    f"joint {self.name!r}: unilateral must be True, False or None, got "
                    f"{unilateral!r}"
                )
            self.contacts = tuple(dataclasses.replace(c, unilateral=bool(unilateral))
                                  for c in self.contacts)
        if not isinstance(tool_in_object, pin.SE3):
            raise ConstraintError(
                f"joint {self.name!r}: tool_in_object must be a pin.SE3, "
                f"got {type(tool_in_object).__name__}"
            )
        self.tool_in_object = tool_in_object.copy()
        tool, obj = self.reference_kinematics()
        states = [c.evaluate(tool, obj) for c in self.contacts]
        for k, s in enumerate(states):
            if abs(s.phi) > gap_tolerance:
                raise ConstraintError(
                    f"joint {self.name!r} ({kind}): contact {k} {self.contacts[k].name!r} is not "
                    f"on its surface at the reference placement: gap {s.phi:.3g} m "
                    f"(tolerance {gap_tolerance:g} m)"
                )
        self.kept, self.dropped = _independent_subset(np.array([s.G_object for s in states]))
        self.rank = len(self.kept)
        if expected_dof is not None and self.rank != 6 - expected_dof:
            raise ConstraintError(
                f"joint {self.name!r} ({kind}): its {len(self.contacts)} contacts give "
                f"{self.rank} independent constraints ({6 - self.rank} DOF), expected "
                f"{6 - expected_dof} ({expected_dof} DOF); check that the contact points are "
                "distinct and not collinear"
            )
        self._active = tuple(self.contacts[k] for k in self.kept)
        self.alpha_rows = self._choose_alpha_rows(alpha_rows, tool, obj)

    @property
    def n_contacts(self) -> int:
        """Number of contacts given (including dropped ones)."""
        return len(self.contacts)

    @property
    def n_constraints(self) -> int:
        """Independent constraints N_i (= rank)."""
        return self.rank

    @property
    def dof(self) -> int:
        """Degrees of freedom of the tool relative to the object, ``6 - rank``."""
        return 6 - self.rank

    @property
    def active_contacts(self) -> tuple[Contact, ...]:
        """The kept (independent) contacts, in the order of the constraint rows."""
        return self._active

    @property
    def unilateral(self) -> np.ndarray:
        """(N,) bool: which constraint rows (kept contacts, in row order) are unilateral."""
        return np.array([c.unilateral for c in self._active], dtype=bool)

    @property
    def alpha_names(self) -> tuple[str, ...]:
        """Names (``TWIST_NAMES``) of the relative-twist components used as ``α_i``."""
        return tuple(TWIST_NAMES[r] for r in self.alpha_rows)

    def __repr__(self) -> str:
        return (
            f"Joint({self.name!r}, kind={self.kind!r}, n_contacts={self.n_contacts}, "
            f"rank={self.rank}, dof={self.dof}, dropped={self.dropped})"
        )

    def reference_kinematics(self) -> tuple[BodyKinematics, BodyKinematics]:
        """Tool and object at rest at the reference placement (object frame = world)."""
        M = self.tool_in_object
        tool = BodyKinematics.single(M.translation, M.rotation, np.zeros(6))
        obj = BodyKinematics.single(np.zeros(3), np.eye(3), np.zeros(6))
        return tool, obj

    def contact_states(
        self, tool: BodyKinematics, obj: BodyKinematics, active_only: bool = True
    ) -> list[ContactState]:
        """Every (kept, or all) contact's :class:`ContactState` at a state (B = 1 each)."""
        contacts = self._active if active_only else self.contacts
        return [c.evaluate(tool, obj) for c in contacts]

    def evaluate(self, tool: BodyKinematics, obj: BodyKinematics) -> JointTerms:
        """All the joint's matrices at a state (per-joint reference path, not vectorised).

        Args:
            tool: tool kinematics, one body (position (1, 3) [m], rotation (1, 3, 3),
                LWA twist (1, 6)).
            obj: object kinematics, one body (frame at the COM).

        Returns:
            :class:`JointTerms`.

        Raises:
            SingularityError: ``T`` cannot keep its ``α`` rows at this state.
        """
        _check_single(tool, "tool")
        _check_single(obj, "object")
        states = self.contact_states(tool, obj)
        xt, vt = tool.position[0], tool.twist[0]
        xo, Ro, vo = obj.position[0], obj.rotation[0], obj.twist[0]
        G_tool = np.array([s.G_tool for s in states])
        G_object = np.array([s.G_object for s in states])
        W_mi = np.array([s.W_mi for s in states]).T
        W_oi = np.array([s.W_oi for s in states]).T
        # W_mi_o column = wrench on the object about the tool origin, object axes
        w = np.array([np.concatenate([s.normal, np.cross(s.tip_center - xt, s.normal)])
                      for s in states])
        w_dot = np.array(
            [
                np.concatenate(
                    [
                        s.normal_rate,
                        np.cross(s.tip_velocity - vt[:3], s.normal)
                        + np.cross(s.tip_center - xt, s.normal_rate),
                    ]
                )
                for s in states
            ]
        )
        wo = vo[3:]
        W_mi_o = _rotate_rows(Ro.T, w).T
        W_mi_o_dot = _rotate_rows(Ro.T, w_dot - _cross_rows(wo, w)).T
        rel_world = np.concatenate([vt[:3] - vo[:3] - np.cross(wo, xt - xo), vt[3:] - wo])
        rel = np.concatenate([Ro.T @ rel_world[:3], Ro.T @ rel_world[3:]])
        T, T_dot = self._motion_space(W_mi_o, W_mi_o_dot)
        return JointTerms(
            phi=np.array([s.phi for s in states]),
            phi_dot=np.array([s.phi_dot for s in states]),
            G_tool=G_tool,
            G_object=G_object,
            kappa=np.array([s.kappa for s in states]),
            contact_points=np.array([s.point for s in states]),
            normals=np.array([s.normal for s in states]),
            W_mi=W_mi,
            W_oi=W_oi,
            W_mi_o=W_mi_o,
            W_mi_o_dot=W_mi_o_dot,
            relative_twist=rel,
            T=T,
            T_dot=T_dot,
            alpha=rel[list(self.alpha_rows)],
        )

    def check_initial(self, tool: BodyKinematics, obj: BodyKinematics,
                      tol: float = INITIAL_GAP_TOLERANCE,
                      arm: int | None = None) -> None:
        """Raise if any contact (kept or dropped) has ``|φ| > tol`` at this state.

        With :attr:`starts_apart`, the unilateral contacts are not checked (they start
        apart and may touch down later).

        Raises:
            InitialGapError: names the arm (if given), the joint, the contact, the gap, tol.
        """
        for k, s in enumerate(self.contact_states(tool, obj, active_only=False)):
            if self.starts_apart and self.contacts[k].unilateral:
                continue
            if abs(s.phi) > tol:
                where = f"arm {arm}: " if arm is not None else ""
                raise InitialGapError(
                    f"{where}joint {self.name!r} ({self.kind}) contact {k} "
                    f"{self.contacts[k].name!r}: initial gap {s.phi:.6g} m exceeds the "
                    f"tolerance {tol:g} m", arm=arm, contact=k, gap=s.phi, tol=tol,
                )

    # -- motion space ---------------------------------------------------------------------
    def _motion_space(self, W_mi_o: np.ndarray, W_mi_o_dot: np.ndarray):
        """``T`` with rows ``alpha_rows`` = I and ``W_mi_oᵀ T = 0``, and ``Ṫ``.

        With ``A = W_mi_oᵀ`` split into columns S (α rows) and U (the others):
        ``T_U = -A_U⁻¹ A_S``; differentiating ``A T = 0`` with ``Ṫ_S = 0`` gives
        ``Ṫ_U = -A_U⁻¹ Ȧ T``.
        """
        k = self.dof
        S = list(self.alpha_rows)
        U = [r for r in range(6) if r not in S]
        T = np.zeros((6, k))
        T_dot = np.zeros((6, k))
        if k == 0:
            return T, T_dot
        A = W_mi_o.T
        A_U = A[:, U]
        cond = np.linalg.cond(A_U)
        if not np.isfinite(cond) or cond > 1e12:
            raise SingularityError(
                f"W_mi_o^T columns {[TWIST_NAMES[u] for u in U]} of joint {self.name!r}",
                cond,
                f"the motion coordinates {self.alpha_names} no longer parametrise the joint",
            )
        T[S] = np.eye(k)
        T[U] = -np.linalg.solve(A_U, A[:, S])
        T_dot[U] = -np.linalg.solve(A_U, W_mi_o_dot.T @ T)
        return T, T_dot

    def _choose_alpha_rows(self, alpha_rows, tool, obj) -> tuple[int, ...]:
        k = self.dof
        if k == 0:
            return ()
        states = self.contact_states(tool, obj)
        xt = tool.position[0]
        w = np.array([np.concatenate([s.normal, np.cross(s.tip_center - xt, s.normal)])
                      for s in states])
        # reference: object frame = world, so W_mi_o = wᵀ. Twists are compared as
        # [v; L ω] with L the largest lever arm about the tool origin, so that metres and
        # radians weigh alike.
        L = max(float(np.max(np.linalg.norm([s.tip_center - xt for s in states], axis=1))),
                1e-9)
        w = np.hstack([w[:, :3], w[:, 3:] / L])
        _, _, vh = np.linalg.svd(w)
        basis = vh[self.rank:].T  # (6, k) orthonormal null space (scaled twists)
        if alpha_rows is not None:
            rows = tuple(_twist_row(r, self.name) for r in alpha_rows)
            if len(rows) != k or len(set(rows)) != k:
                raise ConstraintError(
                    f"joint {self.name!r}: alpha_rows must name {k} distinct rows of "
                    f"{TWIST_NAMES}, got {list(alpha_rows)}"
                )
            smin = np.linalg.svd(basis[list(rows)], compute_uv=False)[-1]
            if smin < 1e-6:
                raise ConstraintError(
                    f"joint {self.name!r}: alpha_rows {[TWIST_NAMES[r] for r in rows]} cannot "
                    "parametrise the joint's motions (those velocity components are dependent)"
                )
            return rows
        return _greedy_rows(basis)


def _greedy_rows(basis: np.ndarray) -> tuple[int, ...]:
    """Rows of an orthonormal (6, k) basis, translations first, keeping it well conditioned.

    Sec 3.8.1 guideline 1: a translation coordinate of the relative position used as ``α``
    gives a unit row of ``T``; guideline 2 uses the orientation. Greedy: take a row when
    the chosen rows keep a least singular value above ``ALPHA_THRESHOLD``; if that leaves
    fewer than k rows, fall back to column-pivoted QR (best conditioned choice).
    """
    k = basis.shape[1]
    rows: list[int] = []
    for r in range(6):
        trial = rows + [r]
        if np.linalg.svd(basis[trial], compute_uv=False)[-1] > ALPHA_THRESHOLD:
            rows = trial
        if len(rows) == k:
            return tuple(rows)
    from scipy.linalg import qr

    _, _, piv = qr(basis.T, pivoting=True)
    return tuple(sorted(int(p) for p in piv[:k]))


def _twist_row(r, joint_name: str) -> int:
    if isinstance(r, str) and r in TWIST_NAMES:
        return TWIST_NAMES.index(r)
    if isinstance(r, int | np.integer) and not isinstance(r, bool) and 0 <= r < 6:
        return int(r)
    raise ConstraintError(
        f"joint {joint_name!r}: alpha row {r!r} is not one of {TWIST_NAMES} or 0..5"
    )


def _independent_subset(G: np.ndarray) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """Greedy, in order: keep a wrench row when it raises the rank of the kept set.

    Moments are divided by a length scale (the largest lever arm) so that forces and
    moments weigh alike.
    """
    scale = max(float(np.max(np.linalg.norm(G[:, 3:], axis=1))), 1e-9)
    Gs = np.hstack([G[:, :3], G[:, 3:] / scale])
    kept: list[int] = []
    dropped: list[int] = []
    for k in range(len(Gs)):
        trial = Gs[kept + [k]]
        s = np.linalg.svd(trial, compute_uv=False)
        if len(trial) <= 6 and s[-1] > RANK_TOLERANCE * max(1.0, s[0]):
            kept.append(k)
        else:
            dropped.append(k)
    return tuple(kept), tuple(dropped)


def _rotate_rows(R: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Rotate the force and moment parts of each (·, 6) row by ``R``."""
    return np.hstack([rows[:, :3] @ R.T, rows[:, 3:] @ R.T])


def _cross_rows(w: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """``ω × ·`` applied to both halves of each (·, 6) row."""
    return np.hstack([np.cross(w, rows[:, :3]), np.cross(w, rows[:, 3:])])


def _check_single(k: BodyKinematics, name: str) -> None:
    if not isinstance(k, BodyKinematics) or len(k) != 1:
        raise InputError(f"{name}: expected BodyKinematics with one body, got {k!r}")
