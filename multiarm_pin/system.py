"""Assembly: arms + object + joints + a state -> the coefficient blocks of the dynamics.

:class:`MultiArmSystem` owns one :class:`~multiarm_pin.model.arm_set.ArmSet` (all arms as one
combined Pinocchio model, with the system's gravity) and one
:class:`~multiarm_pin.constraints.ConstraintSet`. For a :class:`SystemState` it computes, with
one Pinocchio pass (per group of at most 16 arms) and one call of the compiled kernels
(:class:`~multiarm_pin.dynamics.evaluation.CompiledSystem`, no Python loop over arms), the padded
:class:`~multiarm_pin.dynamics.SystemBlocks` of ``docs/ARCHITECTURE.md``; the numpy
implementation (one vectorised constraint evaluation and a few ``einsum`` calls) stays as the
reference, ``blocks(..., reference=True)``. :meth:`MultiArmSystem.forward_dynamics` with
``"auto"`` or ``"object_first"`` runs blocks and solve in the same compiled call::

    W_i = J_iᵀ G_tool,iᵀ        W_o,i = G_object,iᵀ        h_i = τ_i - nle_i
    c_i = -G_tool,i J̇q̇_i - κ_i  (Baumgarte: - 2α φ̇_i - β² φ_i)
    M_o = diag(m I, R I_c Rᵀ)   h_o = [m g; -ω × I_w ω]

Joints whose geometry is "where the tool is at t = 0" need the initial tool and object
placements: :func:`joints_from_initial_state` (or :meth:`MultiArmSystem.from_initial_state`)
builds them from the arms' initial configurations and the object's initial pose.

State layout: ``q`` (nq,) and ``v`` (nv,) are the arms' configurations and velocities
concatenated in arm order (``system.arm_set.q_slices`` / ``v_slices``); the object has its
own :class:`~.model.rigid_object.ObjectState` (COM position, quaternion ``[x, y, z, w]``,
twist ``[ẋ; ω]`` in world axes).

This module is the public system only (most of it the public methods' docstrings); the
compiled evaluation and its buffer views are in :mod:`multiarm_pin.dynamics.evaluation`, the
stacking of every contact row (arms and supports) in
:mod:`multiarm_pin.dynamics.contact_rows`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from multiarm_pin.constraints import (
    JOINT_TYPES,
    ConstraintSet,
    ConstraintTerms,
    Joint,
    make_joint_from_placements,
)
from multiarm_pin.constraints.joint import INITIAL_GAP_TOLERANCE
from multiarm_pin.constraints.supports import Support, SupportSet
from multiarm_pin.dynamics import SOLVERS, Solution, SystemBlocks, solve, solver_entry
from multiarm_pin.dynamics.contact_rows import ContactRows, ContactRowTable, stack_contact_blocks
from multiarm_pin.dynamics.evaluation import (
    CompiledSystem,
    Evaluation,
    reference_evaluation,
)
from multiarm_pin.exceptions import ConstraintError, DynamicsError, InitialGapError, InputError
from multiarm_pin.model.arm import Arm
from multiarm_pin.model.arm_set import ArmSet
from multiarm_pin.model.rigid_object import ObjectState, RigidObject
from multiarm_pin.spatial import as_array, as_se3, cross, se3_to_pose

VELOCITY_TOLERANCE = 1e-6
"""Default largest accepted initial ``|φ̇|`` [m/s] (:meth:`MultiArmSystem.check_initial_state`)."""


@dataclass(frozen=True)
class SystemState:
    """State of the whole system.

    Attributes:
        q: (nq,) arms' joint positions, concatenated in arm order [rad or m].
        v: (nv,) arms' joint velocities, same order [rad/s or m/s].
        obj: the object's pose and twist (:class:`ObjectState`).
    """

    q: np.ndarray
    v: np.ndarray
    obj: ObjectState


JointSpec = Joint | str | Mapping | Callable[[pin.SE3, pin.SE3], Joint]
"""What :func:`joints_from_initial_state` accepts for one arm (see there)."""


def joints_from_initial_state(
    arms: Sequence[Arm],
    obj: RigidObject,
    specs: Sequence[JointSpec],
    q0: Sequence,
    object_placement: pin.SE3,
) -> list[Joint]:
    """Build each arm's joint from where its tool is at t = 0.

    Same argument order as :meth:`MultiArmSystem.from_initial_state`.

    Args:
        arms: the n arms.
        obj: the object (its shape is used by fingertip grasps).
        specs: one per arm, each either a ready :class:`Joint`; a joint type name of
            :data:`~multiarm_pin.constraints.JOINT_TYPES` that is placeable (``"weld"``,
            ``"revolute"``, ...; the joint frame is the tool frame at t = 0); a mapping
            ``{"type": name, **params}`` (extra parameters such as ``size``; for
            ``"fingertips"``, given the object's shape: ``contacts`` =
            ``[(face, point_in_object), ...]`` and ``radius`` [m]); or a callable
            ``f(tool_placement, object_placement) -> Joint``.
        q0: n initial configurations, ``q0[i]`` of shape (nq_i,).
        object_placement: the object's (COM frame) initial placement in the world,
            ``pin.SE3`` (object axes -> world axes, COM position [m]).

    Returns:
        The n joints.

    Raises:
        InputError: wrong counts, a placement that is not a ``pin.SE3``, or a spec that is
            none of the above.
        ConstraintError: from the joint library (unknown type, bad parameters).
    """
    if len(arms) != len(specs) or len(arms) != len(q0):
        raise InputError(
            f"joints_from_initial_state: {len(arms)} arms, {len(q0)} configurations and "
            f"{len(specs)} joint specs; expected one of each per arm"
        )
    oMo = as_se3(object_placement, "object_placement")
    joints = []
    for i, (arm, q, spec) in enumerate(zip(arms, q0, specs, strict=True)):
        oMt = arm.tool_placement(q)
        if isinstance(spec, Joint):
            joints.append(spec)
        elif isinstance(spec, str):
            joints.append(make_joint_from_placements(spec, oMt, oMo, name=f"{arm.name}:{spec}"))
        elif isinstance(spec, Mapping):
            params = dict(spec)
            kind = params.pop("type", None)
            params.setdefault("name", f"{arm.name}:{kind}")
            if kind in JOINT_TYPES and JOINT_TYPES[kind].from_contacts:
                params.setdefault("polyhedron", obj.shape)
            try:
                joints.append(make_joint_from_placements(kind, oMt, oMo, **params))
            except ConstraintError as exc:
                raise ConstraintError(f"arm {i} ({arm.name}): {exc}") from exc
        elif callable(spec):
            joints.append(spec(oMt, oMo))
        else:
            raise InputError(
                f"arm {i} ({arm.name}): joint spec must be a Joint, a type name, a mapping "
                f"with 'type', or a callable(tool_placement, object_placement); got "
                f"{type(spec).__name__}"
            )
    return joints


class MultiArmSystem:
    """n arms holding one rigid object through joints made of frictionless point contacts.

    Args:
        arms: the arms (unique names); ``joints[i]`` connects arm i's tool and the object.
        obj: the object.
        joints: one :class:`Joint` per arm.
        gravity: (3,) gravity acceleration in the world [m/s²]; set on the combined
            Pinocchio model too.
        supports: fixed planes the object may rest on (:class:`Support`, unilateral rows);
            with supports, ``arms`` may be empty (an object on supports alone).

    Attributes:
        n_arms, nq, nv: numbers of arms, configuration variables and joint velocities.
        arm_set: the combined Pinocchio model of the arms (:class:`ArmSet`).
        constraint_set: the joints, vectorised (:class:`ConstraintSet`).
        obj: the object; joints: the joints; gravity: (3,) [m/s²].
        unilateral: (n, N_max) bool, True on the arms' constraint rows whose contact is
            unilateral (:attr:`Contact.unilateral`), False on bilateral rows and padding.
        supports: the :class:`SupportSet` (K rows).
        n_blocks: n, plus 1 when there are supports (their zero-dof block, after the arms).
        rows_max: padded rows per block of :meth:`contact_blocks` (``max(N_max, K)``).
        contact_mask, contact_unilateral: (n_blocks, rows_max) bool, real rows and unilateral
            rows of :meth:`contact_blocks` (the arms' rows, then the supports').
        contact_restitution: (n_blocks, rows_max) Newton's coefficient of each row (0 on the
            arms' rows and padding).
        contact_labels: one ``(block, row, label)`` per real row: ``"<arm>:<contact>"`` or
            ``"<support>[j]"``.
    """

    def __init__(self, arms: list[Arm], obj: RigidObject, joints: list[Joint],
                 gravity=(0.0, 0.0, -9.81), supports: Sequence[Support] = ()):
        if not isinstance(obj, RigidObject):
            raise InputError(f"obj: expected a RigidObject, got {type(obj).__name__}")
        if len(arms) != len(joints):
            raise InputError(
                f"MultiArmSystem: {len(arms)} arms but {len(joints)} joints; expected one "
                "joint per arm"
            )
        self.gravity = as_array(gravity, (3,), "gravity [m/s^2]")
        self.supports = SupportSet(supports)
        if not arms:
            if not self.supports.n_rows:
                raise InputError("MultiArmSystem: no arms and no supports; expected at least "
                                 "one of them")
            self._init_without_arms(obj)
            return
        self.arm_set = ArmSet(list(arms), gravity=self.gravity)
        self.constraint_set = ConstraintSet(joints)
        self.obj = obj
        self.joints = list(joints)
        self.arms = list(arms)
        self.n_arms = self.arm_set.n
        self.nq = self.arm_set.nq
        self.nv = self.arm_set.nv
        self._nv_arm = self.arm_set.nv_arm.copy()
        self._N = self.constraint_set.N.copy()
        self.N_max = self.constraint_set.N_max
        self.unilateral = self.constraint_set.unilateral  # per contact (Contact.unilateral)
        self.compiled = CompiledSystem(self.arm_set, self.constraint_set, obj, self.gravity,
                                       self.check_state)
        self._init_contact_rows()

    def _init_without_arms(self, obj: RigidObject) -> None:
        """An object on supports alone: no arms, no joints, one zero-dof support block."""
        self.arm_set = None
        self.constraint_set = None
        self.obj = obj
        self.joints, self.arms = [], []
        self.n_arms = self.nq = self.nv = 0
        self._nv_arm = np.zeros(0, dtype=int)
        self._N = np.zeros(0, dtype=int)
        self.N_max = 0
        self.unilateral = np.zeros((0, 0), dtype=bool)
        self.unilateral.setflags(write=False)
        self.compiled = None
        self._init_contact_rows()

    def _init_contact_rows(self) -> None:
        """Row tables of :meth:`contact_blocks` (arms' rows, then the supports' block)."""
        names = [[f"{arm.name}:{c.name}" for c in joint.active_contacts]
                 for arm, joint in zip(self.arms, self.joints, strict=True)]
        table = ContactRowTable.build(self._nv_arm, self._N, self.unilateral, names,
                                      self.supports)
        self._contact_rows = table
        self.n_blocks, self.rows_max = table.n_blocks, table.rows_max
        self.contact_mask, self.contact_unilateral = table.mask, table.unilateral
        self.contact_restitution = table.restitution
        self.contact_labels = table.labels

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_initial_state(cls, arms: list[Arm], obj: RigidObject, specs: Sequence[JointSpec],
                           q0: Sequence, object_placement: pin.SE3,
                           gravity=(0.0, 0.0, -9.81)) -> tuple[MultiArmSystem, SystemState]:
        """A system whose joints hold the tools where they are at t = 0, and that state at rest.

        Same argument order as :func:`joints_from_initial_state`.

        Args:
            arms: the arms.
            obj: the object.
            specs: one joint spec per arm (see :func:`joints_from_initial_state`).
            q0: n initial configurations (nq_i,).
            object_placement: the object's (COM frame) initial placement in the world,
                ``pin.SE3``.
            gravity: (3,) [m/s²].

        Returns:
            ``(system, state)`` with zero velocities.
        """
        joints = joints_from_initial_state(arms, obj, specs, q0, object_placement)
        system = cls(arms, obj, joints, gravity)
        position, quaternion = se3_to_pose(object_placement)
        state = system.state(system.arm_set.stack_q(list(q0)), None, position, quaternion)
        return system, state

    def state(self, q, v=None, object_position=(0, 0, 0), object_quaternion=(0, 0, 0, 1),
              object_twist=None) -> SystemState:
        """A validated :class:`SystemState`.

        Args:
            q: (nq,) combined configuration.
            v: (nv,) combined velocity (zero when None).
            object_position: (3,) COM [m].
            object_quaternion: (4,) ``[x, y, z, w]``.
            object_twist: (6,) ``[ẋ; ω]`` world axes (zero when None).

        Raises:
            InputError: wrong shape, NaN, or a non-unit quaternion.
        """
        return SystemState(
            as_array(q, (self.nq,), "arms' q"),
            np.zeros(self.nv) if v is None else as_array(v, (self.nv,), "arms' v"),
            ObjectState.create(object_position, object_quaternion, object_twist),
        )

    # ------------------------------------------------------------------ validation
    def check_state(self, state: SystemState) -> None:
        """Raise if the state has wrong shapes or NaN/infinite entries.

        Raises:
            InputError: wrong type or shape.
            DynamicsError: NaN or infinity, naming the field (``q``, ``v``, object ...).
        """
        if not isinstance(state, SystemState):
            raise InputError(f"state: expected a SystemState, got {type(state).__name__}")
        o = state.obj
        try:  # fast path (hot): right shapes and a finite sum (NaN and inf propagate)
            if (state.q.shape == (self.nq,) and state.v.shape == (self.nv,)
                    and o.position.shape == (3,) and o.quaternion.shape == (4,)
                    and o.twist.shape == (6,)
                    and np.isfinite(state.q.sum() + state.v.sum() + o.position.sum()
                                    + o.quaternion.sum() + o.twist.sum())):
                return
        except AttributeError:
            pass
        fields = (("arms' q", state.q, (self.nq,)), ("arms' v", state.v, (self.nv,)),
                  ("object position", o.position, (3,)), ("object quaternion", o.quaternion, (4,)),
                  ("object twist", o.twist, (6,)))
        for name, value, shape in fields:
            arr = np.asarray(value)
            if arr.shape != shape:
                raise InputError(f"state: {name} expected shape {shape}, got {arr.shape}")
            if not np.all(np.isfinite(arr)):
                bad = np.flatnonzero(~np.isfinite(arr)).tolist()
                raise DynamicsError(
                    f"state: {name} contains NaN or infinity at index(es) {bad}: {arr.tolist()}"
                )

    def check_initial_state(self, state: SystemState, tol: float = INITIAL_GAP_TOLERANCE,
                            velocity_tol: float = VELOCITY_TOLERANCE) -> None:
        """Check that an initial state satisfies every joint at position and velocity level.

        Args:
            state: the initial state.
            tol: largest accepted ``|φ|`` [m] of any contact (dropped redundant ones too).
            velocity_tol: largest accepted ``|φ̇|`` [m/s] of any kept contact.

        Raises:
            DynamicsError / InputError: NaN or wrong shapes (:meth:`check_state`).
            ConstraintError: a gap or gap rate beyond tolerance, naming the arm, joint,
                contact and value (use :meth:`project_velocities` to fix velocities).
        """
        self.check_state(state)
        self.check_supports(state, tol)
        if not self.n_arms:
            return
        tools = self.arm_set.tool_kinematics(state.q, state.v)
        objk = state.obj.kinematics()
        self.constraint_set.check_initial(tools, objk, tol=tol)
        ct = self.constraint_set.evaluate(tools, objk)
        rate = np.where(ct.mask, np.abs(ct.phi_dot), 0.0)
        i, k = np.unravel_index(int(np.argmax(rate)), rate.shape)
        if rate[i, k] > velocity_tol:
            j = self.joints[i]
            raise ConstraintError(
                f"inconsistent initial velocities: arm {i} ({self.arms[i].name}) joint "
                f"{j.name!r} ({j.kind}) contact {k}: gap rate φ̇ = {ct.phi_dot[i, k]:.6g} m/s "
                f"exceeds the tolerance {velocity_tol:g} m/s ({int((rate > velocity_tol).sum())} "
                "contact(s) violated); use MultiArmSystem.project_velocities(state)"
            )

    def constraint_jacobian(self, state: SystemState) -> np.ndarray:
        """Velocity-level constraint matrix ``A`` with ``φ̇ = A [v; v_o]`` (real rows only).

        Args:
            state: positions are used (velocities are ignored).

        Returns:
            (Σ N_i, nv + 6): row block i is ``[0 .. W_iᵀ .. 0, W_o,iᵀ]`` (``W_iᵀ`` on arm i's
            velocity slice, ``W_o,iᵀ = G_object,i`` on the object twist ``[ẋ; ω]``).
        """
        if not self.n_arms:
            return np.zeros((0, 6))
        ev = self.blocks(state)
        b = ev.blocks
        A = np.zeros((b.n_constraints, self.nv + 6))
        row = 0
        for i, sl in enumerate(self.arm_set.v_slices):  # not a hot path
            Ni, nvi = int(b.N[i]), int(b.nv[i])
            A[row:row + Ni, sl] = b.W[i, :nvi, :Ni].T
            A[row:row + Ni, self.nv:] = b.W_o[i, :, :Ni].T
            row += Ni
        return A

    def project_velocities(self, state: SystemState) -> SystemState:
        """The state with the least-norm velocity correction that makes every ``φ̇ = 0``.

        Solves ``min ‖δ‖`` subject to ``A ([v; v_o] + δ) = 0`` (``A`` from
        :meth:`constraint_jacobian`; Euclidean norm on ``[v; ẋ_o; ω_o]``), i.e. projects
        ``[v; v_o]`` onto the null space of ``A``. Positions are unchanged.
        """
        self.check_state(state)
        A = self.constraint_jacobian(state)
        x = np.concatenate([state.v, state.obj.twist])
        x_new = x - np.linalg.pinv(A, rcond=1e-12) @ (A @ x)
        o = state.obj
        return SystemState(state.q.copy(), x_new[: self.nv],
                           ObjectState(o.position.copy(), o.quaternion.copy(), x_new[self.nv:]))

    # ------------------------------------------------------------------ the hot path
    def pad(self, x: np.ndarray) -> np.ndarray:
        """Combined joint vector (nv,) -> stacked, zero-padded (n, nv_max)."""
        if not self.n_arms:
            return np.zeros((0, 1))
        return self.arm_set.pad_v(x)

    def unpad(self, x: np.ndarray) -> np.ndarray:
        """Stacked (n, nv_max) -> combined (nv,) (blocks beyond the arms are ignored)."""
        if not self.n_arms:
            return np.zeros(0)
        return self.arm_set.unpad_v(np.asarray(x)[:self.n_arms])

    def blocks(self, state: SystemState, tau: np.ndarray | None = None,
               baumgarte: tuple[float, float] | None = None, *,
               reference: bool = False) -> Evaluation:
        """The coefficient blocks of the equations of motion at a state.

        Computed by the compiled kernels of :mod:`multiarm_pin._compiled.evaluate` after the three
        Pinocchio calls of :meth:`ArmSet.pinocchio_pass`: every returned array is new (views
        of one buffer allocated per call), so an :class:`Evaluation` stays valid after later
        calls.

        Args:
            state: the system state (validated: NaN raises :class:`DynamicsError`).
            tau: (nv,) joint torques [N m or N], zero when None.
            baumgarte: ``(α, β)`` [1/s]: ``c_i ← c_i - 2α φ̇_i - β² φ_i`` (thesis Sec 4.3).
            reference: if True, compute with the numpy reference implementation
                (:meth:`ArmSet.evaluate`, :meth:`ConstraintSet.evaluate`, ``einsum``
                assembly) instead; same results to round-off (for tests and benchmarks).

        Returns:
            :class:`Evaluation` (blocks, arm terms, constraint terms).

        Raises:
            InputError: the system has no arms (use :meth:`contact_blocks`).
        """
        if not self.n_arms:
            raise InputError("MultiArmSystem.blocks: the system has no arms; its only rows are "
                             "the supports' (use contact_blocks)")
        if reference:
            return self._blocks_reference(state, tau, baumgarte)
        return self._compiled(state, tau, baumgarte, False)[0]

    def _compiled(self, state: SystemState, tau, baumgarte, step: bool
                  ) -> tuple[Evaluation, Solution | None]:
        """The compiled hot path: blocks and, if ``step``, the object-first solution.

        :meth:`CompiledSystem.evaluate`; the solution is None if ``step`` is False or the
        kernel reported a doubtful case, which the caller hands to the numpy solvers.
        """
        return self.compiled.evaluate(state, tau, baumgarte, step)

    def _blocks_reference(self, state: SystemState, tau: np.ndarray | None = None,
                          baumgarte: tuple[float, float] | None = None) -> Evaluation:
        """:meth:`blocks` by the numpy reference implementation (the compiled path's oracle)."""
        self.check_state(state)
        return reference_evaluation(self.arm_set, self.constraint_set, self.obj, self.gravity,
                                    state, tau, baumgarte)

    def forward_dynamics(self, state: SystemState, tau: np.ndarray | None = None,
                         solver: str = "auto",
                         baumgarte: tuple[float, float] | None = None
                         ) -> tuple[Solution, Evaluation]:
        """Accelerations and contact multipliers at a state.

        Args:
            state: the state.
            tau: (nv,) joint torques [N m] (zero when None).
            solver: a name of :data:`multiarm_pin.dynamics.SOLVERS`.
            baumgarte: ``(α, β)`` [1/s] or None.

        Returns:
            ``(solution, evaluation)``: ``solution.a_o`` (6,) ``[ẍ; ω̇]`` world at the COM,
            ``solution.qdd`` (n, nv_max) (use :meth:`unpad`), ``solution.mu`` (n, N_max) [N].

        Raises:
            DynamicsError: NaN in the state, or no solution (inconsistent constraints).
            InputError: unknown solver (lists the known ones).
        """
        entry = SOLVERS.get(solver) if type(solver) is str else None
        if entry is None:
            entry = solver_entry(solver)  # raises, listing the known names
        if entry.compiled:  # blocks and solve in one compiled call
            ev, sol = self.compiled.evaluate(state, tau, baumgarte, True)
            if sol is None:  # doubtful case: the numpy reference decides, falls back or raises
                sol = entry.function(ev.blocks, compiled=False)
            return sol, ev
        ev = self.blocks(state, tau, baumgarte)
        return solve(ev.blocks, solver), ev

    def contact_dynamics(self, state: SystemState, tau: np.ndarray | None = None,
                         active: np.ndarray | None = None,
                         baumgarte: tuple[float, float] | None = None,
                         external_wrench=None):
        """Forward dynamics of the whole system: arms, supports and unilateral contacts.

        The mixed complementarity problem of
        :func:`~multiarm_pin.dynamics.unilateral.solve_unilateral` on every contact row of
        :meth:`contact_blocks` (the arms' rows, then the supports' block): bilateral rows
        ``φ̈ = 0``, active unilateral rows ``0 <= μ ⟂ φ̈ >= 0``, inactive rows ``μ = 0``.
        This is what one evaluation of :func:`~multiarm_pin.sim.simulation.simulate` solves
        (without the controller); :meth:`forward_dynamics` covers the arms' rows only, all
        held as equalities.

        Args:
            state: the state.
            tau: (nv,) joint torques [N m] (zero when None; must be None without arms).
            active: (n_blocks, rows_max) bool, the touching rows (bilateral rows must be
                in it to be held); None: every real row (all contacts touching).
            baumgarte: ``(α, β)`` [1/s] or None.
            external_wrench: (6,) ``[f; m]`` at the COM, world axes [N, N m], or None.

        Returns:
            ``(solution, rows)``: the
            :class:`~multiarm_pin.dynamics.unilateral.ContactSolution` (``a_o`` (6,),
            ``qdd`` (n_blocks, nv_max), ``mu`` and ``phi_dd`` (n_blocks, rows_max) in the
            layout of :meth:`contact_blocks`) and the :class:`ContactRows` (gaps, rates,
            points, normals) of the same rows.

        Raises:
            InputError: ``active`` of the wrong shape, or torques for a system without arms.
            DynamicsError: NaN in the state, or no solution.
        """
        from multiarm_pin.dynamics.unilateral import solve_unilateral

        if active is not None:
            active = np.asarray(active)
            if active.shape != (self.n_blocks, self.rows_max) or active.dtype != bool:
                raise InputError(f"active: expected a bool array of shape ({self.n_blocks}, "
                                 f"{self.rows_max}), got {active.dtype} {active.shape}")
            active = active & self.contact_mask
        if self.n_arms:
            ev = self.blocks(state, tau, baumgarte)
            full, rows = self.contact_blocks(state, ev.blocks, ev.constraints, baumgarte,
                                             external_wrench)
        else:
            if tau is not None and np.size(tau):
                raise InputError("tau: the system has no arms, expected None")
            full, rows = self.contact_blocks(state, None, None, baumgarte, external_wrench)
        return solve_unilateral(full, self.contact_unilateral, active), rows

    # ------------------------------------------------------------------ contacts
    def support_terms(self, state: SystemState):
        """The support rows at a state (:class:`~multiarm_pin.constraints.SupportTerms`)."""
        o = state.obj
        return self.supports.evaluate(o.position, o.rotation, o.twist)

    def contact_blocks(self, state: SystemState, blocks: SystemBlocks | None = None,
                       constraints: ConstraintTerms | None = None,
                       baumgarte: tuple[float, float] | None = None,
                       external_wrench=None) -> tuple[SystemBlocks, ContactRows]:
        """The blocks of every contact row: the arms' blocks, then one zero-dof support block.

        The support block (``nv = 0``: identity padding of ``M``, ``W = 0``) holds the K
        support rows: ``W_o = G_objectᵀ`` (``[n; r × n]``), ``c = -κ`` (and, with Baumgarte,
        ``- 2α φ̇ - β² φ``). Without supports the arms' blocks are returned as they are.

        Args:
            state: the state.
            blocks: the arms' blocks at this state (with torques), from :meth:`blocks`;
                None when the system has no arms.
            constraints: the arms' constraint rows of the same evaluation (None: no arms).
            baumgarte: ``(α, β)`` [1/s] of the support rows (the arms' are in ``blocks``).
            external_wrench: (6,) ``[f; m]`` at the COM in world axes [N, N m] added to
                ``h_o``, or None.

        Returns:
            ``(blocks, rows)``: :class:`SystemBlocks` with ``n_blocks`` blocks padded to
            ``rows_max`` rows, and their :class:`ContactRows`.
        """
        n, K = self.n_arms, self.supports.n_rows
        o = state.obj
        R = o.rotation if (K or not n) else None  # computed once (a property, not stored)
        if n:
            M_o, h_o = blocks.M_o, blocks.h_o
        else:
            M_o = self.obj.mass_matrix(R)
            h_o = self.obj.bias_wrench(R, o.twist, self.gravity)
        if external_wrench is not None:
            h_o = h_o + np.asarray(external_wrench, dtype=float)
        if not K:
            if external_wrench is not None:
                blocks = blocks.replaced(h_o=h_o)
            ct = constraints
            return blocks, ContactRows(ct.phi, ct.phi_dot, ct.contact_points, ct.normals)
        return stack_contact_blocks(self._contact_rows, M_o, h_o,
                                    self.supports.evaluate(o.position, R, o.twist),
                                    blocks, constraints, baumgarte)

    def check_supports(self, state: SystemState, tol: float = INITIAL_GAP_TOLERANCE) -> None:
        """Raise if the object penetrates a support by more than ``tol`` [m].

        A point outside its support's rectangle (``extent``) is beside the support, not in
        it: only points inside count.

        Raises:
            InitialGapError: names the support, the point and its gap.
        """
        if not self.supports.n_rows:
            return
        st = self.support_terms(state)
        phi = st.phi
        if self.supports.finite:
            phi = np.where(self.supports.edge_margins(st.contact_points) > 0.0, phi, np.inf)
        k = int(np.argmin(phi))
        if phi[k] < -tol:
            raise InitialGapError(
                f"the object starts penetrating support {self.supports.labels[k]!r}: gap "
                f"{phi[k]:.6g} m (tolerance {tol:g} m, "
                f"{int((phi < -tol).sum())} point(s) below the plane)",
                support=int(self.supports.support_index[k]),
                contact=int(self.supports.point_index[k]), gap=phi[k], tol=tol,
            )

    # ------------------------------------------------------------------ physics
    @property
    def _groups(self) -> list:
        """The arm groups of the Pinocchio pass (none without arms)."""
        return [] if self.arm_set is None else self.arm_set.groups

    def gravity_torques(self, q: np.ndarray) -> np.ndarray:
        """(nv,) joint torques that hold the arms (alone) against gravity [N m]."""
        if not self.n_arms:
            return np.zeros(0)
        return self.arm_set.gravity_combined(q)

    def kinetic_energy(self, state: SystemState) -> float:
        """Arms' ``½ vᵀ M v`` plus the object's ``½ m |ẋ|² + ½ ωᵀ I_w ω`` [J].

        Summed over the arm groups' Pinocchio models (:attr:`ArmSet.groups`), so that large
        systems never need the ``Data`` of one model of all arms.
        """
        e = sum(float(pin.computeKineticEnergy(g.model, g.data, state.q[g.q], state.v[g.v]))
                for g in self._groups)
        return e + self.obj.kinetic_energy(state.obj)

    def potential_energy(self, state: SystemState) -> float:
        """Gravitational potential energy ``-Σ m g·c`` of arms and object [J] (zero at z = 0)."""
        e = sum(float(pin.computePotentialEnergy(g.model, g.data, state.q[g.q]))
                for g in self._groups)
        return e - self.obj.mass * float(self.gravity @ state.obj.position)

    def momentum(self, state: SystemState) -> np.ndarray:
        """(6,) total ``[linear; angular]`` momentum of arms and object about the world origin.

        Arms: ``pin.computeCentroidalMomentum`` of each arm group (about its COM) shifted to
        the origin; object: ``[m ẋ; I_w ω + x × m ẋ]``. Units [kg m/s, kg m²/s], world axes.
        """
        lin = self.obj.mass * state.obj.twist[:3]
        ho = self.obj.momentum(state.obj)
        ang = ho[3:] + cross(state.obj.position, ho[:3])
        for g in self._groups:
            hg = pin.computeCentroidalMomentum(g.model, g.data, state.q[g.q], state.v[g.v])
            lin = lin + hg.linear
            ang = ang + hg.angular + cross(g.data.com[0], hg.linear)
        return np.concatenate([lin, ang])


__all__ = [
    "ContactRows",
    "Evaluation",
    "MultiArmSystem",
    "SystemState",
    "joints_from_initial_state",
]
