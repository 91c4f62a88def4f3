"""Controllers: joint torques from the time, the state and the blocks of the dynamics.

A controller is a callable ``controller(t, state, evaluation) -> tau (nv,)`` [N m] where
``evaluation`` (:class:`~multiarm_pin.system.Evaluation`) holds the blocks at zero torque
(``h = -nle``), so a controller can use the mass matrices, Jacobians and constraint rows
without recomputing them. Build one by name with :func:`make_controller`:

- ``none``: zero torque;
- ``gravity_compensation``: ``τ = g(q)``, the arms' own weight only (the object's weight is
  not compensated);
- ``joint_pd``: ``τ = g(q) + K_p (q_ref ⊖ q) - K_d v`` (``q_ref`` defaults to the
  configuration at the first call, i.e. ``q0``);
- ``object_pd``: object-level computed torque. A desired object trajectory
  (:class:`~multiarm_pin.trajectories.MinimumJerkTrajectory`; default: hold the pose of the
  first call) and PD on the object pose give a desired acceleration
  ``a_d = a_ref + K_d (v_ref - v_o) + K_p [p_ref - p; log(R_ref Rᵀ)]``. The internal forces
  come from :func:`multiarm_pin.dynamics.force_distribution.distribute_forces` (every
  unilateral contact pushes with at least ``margin``, forces as small as possible). The
  secondary objective holds every tool at its first-call pose *relative to the object* (the
  relative motion ``T_i α_i`` of thesis Sec 3.5, Eq 3.5-3.6): a PD on the tool's placement in
  the object frame gives a desired relative acceleration, the tool's desired classical
  acceleration is that of the object-fixed frame at the tool under ``a_d`` plus this
  correction (:func:`tool_acceleration_from_object`), and the desired joint accelerations are
  its least-squares solution through the tool Jacobian, with a joint-space PD on the
  Jacobian's null space for redundant arms. The inverse dynamics
  (:func:`~multiarm_pin.dynamics.inverse_dynamics.inverse_dynamics`, Eq 3.10) keeps of them
  what the constraint rows leave free and gives the torques. With these torques the forward
  dynamics returns exactly ``a_d`` and those multipliers, and frictionless fingertips do not
  slide along their faces.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar

import numpy as np
import pinocchio as pin

from multiarm_pin.dynamics.force_distribution import distribute_forces
from multiarm_pin.dynamics.inverse_dynamics import InverseDynamicsResult, inverse_dynamics
from multiarm_pin.exceptions import InputError
from multiarm_pin.spatial import as_array, cross
from multiarm_pin.system import Evaluation, MultiArmSystem, SystemState
from multiarm_pin.trajectories import MinimumJerkTrajectory, pose_error


class Controller:
    """Base class: ``controller(t, state, evaluation) -> tau (nv,)`` [N m].

    Args:
        system: the system it controls.
    """

    name: ClassVar[str] = "controller"

    def __init__(self, system: MultiArmSystem):
        if not isinstance(system, MultiArmSystem):
            raise InputError(f"system: expected a MultiArmSystem, got {type(system).__name__}")
        self.system = system

    def __call__(self, t: float, state: SystemState, evaluation: Evaluation) -> np.ndarray:
        """Joint torques (nv,) [N m] at time ``t`` [s]."""
        raise NotImplementedError


class ZeroTorque(Controller):
    """``τ = 0``."""

    name = "none"

    def __call__(self, t, state, evaluation) -> np.ndarray:
        """(nv,) zeros."""
        return np.zeros(self.system.nv)


class GravityCompensation(Controller):
    """``τ = g(q)``: the arms' own gravity torques (not the object's weight)."""

    name = "gravity_compensation"

    def __call__(self, t, state, evaluation) -> np.ndarray:
        """(nv,) gravity torques [N m]."""
        return self.system.gravity_torques(state.q)


def _gain(value, size: int, name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        arr = np.full(size, float(arr))
    if arr.shape != (size,) or not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise InputError(f"{name}: expected a gain >= 0 or {size} of them, got {value!r}")
    return arr


class JointPD(Controller):
    """``τ = g(q) + K_p (q_ref ⊖ q) - K_d v``.

    Args:
        system: the system.
        kp: stiffness [N m/rad], scalar or (nv,).
        kd: damping [N m s/rad], scalar or (nv,).
        q_ref: (nq,) reference configuration; the configuration at the first call if None.
    """

    name = "joint_pd"

    def __init__(self, system: MultiArmSystem, kp=100.0, kd=20.0, q_ref=None):
        super().__init__(system)
        self.kp = _gain(kp, system.nv, "joint_pd kp")
        self.kd = _gain(kd, system.nv, "joint_pd kd")
        self.q_ref = None
        if q_ref is not None:
            q = np.asarray(q_ref, dtype=float)
            if q.shape != (system.nq,) or not np.all(np.isfinite(q)):
                raise InputError(f"joint_pd q_ref: expected ({system.nq},) numbers, got {q_ref!r}")
            self.q_ref = q

    def __call__(self, t, state, evaluation) -> np.ndarray:
        """(nv,) torques [N m]."""
        if self.q_ref is None:
            self.q_ref = np.array(state.q, dtype=float)
        model = self.system.arm_set.model
        err = pin.difference(model, state.q, self.q_ref)
        return self.system.gravity_torques(state.q) + self.kp * err - self.kd * state.v


def tool_acceleration_from_object(offset, object_twist, object_acceleration,
                                  relative_twist=None, relative_acceleration=None) -> np.ndarray:
    """Classical accelerations of frames that move relative to the object (thesis Eq 3.6).

    A frame (a tool) at ``p = x_o + r`` with orientation ``R = R_o R_rel`` moves relative to
    the object frame (COM ``x_o``, orientation ``R_o``, twist ``[ẋ_o; ω_o]``) with relative
    twist ``[ṗ_rel; ω_rel]`` and relative acceleration ``[a_rel; α_rel]`` (the time derivatives
    of its coordinates in the object frame, rotated to world axes). Its classical acceleration
    is the transport of the object's plus the relative motion::

        p̈ = ẍ_o + ω̇_o × r + ω_o × (ω_o × r) + 2 ω_o × ṗ_rel + a_rel
        ω̇ = ω̇_o + ω_o × ω_rel + α_rel

    With zero relative twist and acceleration this is the acceleration of the object-fixed
    frame at ``p``.

    Args:
        offset: (n, 3) ``r = p - x_o``, world axes [m].
        object_twist: (6,) ``[ẋ_o; ω_o]`` world axes at the COM [m/s, rad/s].
        object_acceleration: (6,) classical ``[ẍ_o; ω̇_o]`` world axes at the COM
            [m/s², rad/s²].
        relative_twist: (n, 6) ``[ṗ_rel; ω_rel] = [ṗ - ẋ_o - ω_o × r; ω - ω_o]``, world axes
            [m/s, rad/s] (``R_o`` times the rates of the frame's coordinates in the object
            frame); zero if None.
        relative_acceleration: (n, 6) ``R_o`` times the second derivatives of those
            coordinates, ``[R_o d²(R_oᵀ r)/dt²; R_o d(R_oᵀ ω_rel)/dt]``, world axes
            [m/s², rad/s²]; zero if None.

    Returns:
        (n, 6) classical accelerations ``[p̈; ω̇]`` of the frames, world axes (LWA).

    Raises:
        InputError: wrong shapes or NaN.
    """
    r = as_array(offset, (None, 3), "offset (n, 3)")
    n = len(r)
    v_o = as_array(object_twist, (6,), "object_twist")
    a_o = as_array(object_acceleration, (6,), "object_acceleration")
    rel_v = (np.zeros((n, 6)) if relative_twist is None
             else as_array(relative_twist, (n, 6), f"relative_twist ({n}, 6)"))
    rel_a = (np.zeros((n, 6)) if relative_acceleration is None
             else as_array(relative_acceleration, (n, 6), f"relative_acceleration ({n}, 6)"))
    return _transport(r, v_o, a_o, rel_v, rel_a)


def _transport(r, v_o, a_o, rel_v, rel_a) -> np.ndarray:
    """:func:`tool_acceleration_from_object` without the checks (hot path)."""
    w = v_o[3:]
    out = np.empty((len(r), 6))
    out[:, :3] = (a_o[:3] + cross(a_o[3:], r) + cross(w, cross(w, r))
                  + 2.0 * cross(w, rel_v[:, :3]) + rel_a[:, :3])
    out[:, 3:] = a_o[3:] + cross(w, rel_v[:, 3:]) + rel_a[:, 3:]
    return out


JACOBIAN_DAMPING = 1e-8
"""Damping ``ε`` of ``object_pd``'s tool-Jacobian pseudo-inverse ``Jᵀ (J Jᵀ + ε I)⁻¹``,
relative to the mean eigenvalue of ``J Jᵀ`` (keeps it finite at singular poses and for arms
with fewer than six joints; changes regular arms' solutions by about ``ε/σ²_min``)."""

_EYE6 = np.eye(6)


class ObjectPD(Controller):
    """Object-level computed torque on the inverse dynamics with force distribution.

    Primary objective: the object follows ``trajectory`` (PD on its pose). Secondary
    objective (the relative motion ``T_i α_i`` of thesis Sec 3.5): every tool keeps its
    placement *in the object frame* at the first call, so that grasps (frictionless
    fingertips that could slide along their faces, revolute handles that could turn) stay
    where they were. Per arm i, with ``r_i = p_i - x_o``:

    1. hold error, world axes: ``e_i = [x_o + R_o p_i,ref - p_i; log(R_o R_i,ref R_iᵀ)]``
       (``p_i,ref``, ``R_i,ref`` the tool placement in the object frame at the first call);
       relative twist ``ν_i = [ṗ_i - ẋ_o - ω_o × r_i; ω_i - ω_o]``;
    2. desired relative acceleration ``α_i = hold_kp e_i - hold_kd ν_i`` (a PD on the tool's
       coordinates in the object frame);
    3. desired tool acceleration ``a_i`` = :func:`tool_acceleration_from_object` of ``a_d``,
       ``ν_i`` and ``α_i``;
    4. ``q̈_i = J_i⁺ (a_i - J̇q̇_i) + (I - J_i⁺ J_i) z_i``, ``z_i = null_kp (q_ref ⊖ q)_i -
       null_kd v_i`` (least squares through the LWA tool Jacobian, damped by
       :data:`JACOBIAN_DAMPING`; the second term moves only redundant arms' self-motion);
    5. :func:`~multiarm_pin.dynamics.inverse_dynamics.inverse_dynamics` takes the ``q̈_i``
       closest to these that satisfy the constraint rows, and returns the torques.

    Args:
        system: the system.
        trajectory: desired object pose over time (a :class:`MinimumJerkTrajectory`, or a
            mapping ``{"times", "positions", "quaternions"}``); hold the first call's pose if
            None.
        kp: pose stiffness [1/s²], scalar or (6,) ``[x y z, rx ry rz]``.
        kd: pose damping [1/s], scalar or (6,).
        margin: least push [N] of every unilateral contact.
        null_kp: stiffness [1/s²] of the joint-space PD toward the first call's ``q``, acting
            only in the null space of each tool Jacobian (self-motion of redundant arms; no
            effect on 6-joint arms). Before the relative hold existed it acted on all the
            joints' free motions, which let tools slide along the object; that role is now
            ``hold_kp``'s.
        null_kd: its damping [1/s].
        hold_kp: stiffness [1/s²] of the tools' pose relative to the object (step 2).
        hold_kd: its damping [1/s].

    Attributes:
        last: the :class:`~multiarm_pin.dynamics.inverse_dynamics.InverseDynamicsResult` of
            the last call (its ``mu`` are the planned forces).
        hold_position: (n, 3) tool positions in the object frame held (first call) [m], or
            None before the first call.
        hold_rotation: (n, 3, 3) tool orientations in the object frame held (tool axes ->
            object axes), or None before the first call.
        last_tool_acceleration: (n, 6) the desired tool accelerations ``a_i`` of the last
            call, world axes [m/s², rad/s²].
    """

    name = "object_pd"

    def __init__(self, system: MultiArmSystem, trajectory=None, kp=100.0, kd=20.0,
                 margin: float = 1.0, null_kp: float = 25.0, null_kd: float = 10.0,
                 hold_kp: float = 100.0, hold_kd: float = 20.0):
        super().__init__(system)
        if trajectory is not None and not isinstance(trajectory, MinimumJerkTrajectory):
            try:
                trajectory = MinimumJerkTrajectory(**dict(trajectory))
            except TypeError as exc:
                raise InputError(
                    "object_pd trajectory: expected a MinimumJerkTrajectory or a mapping with "
                    f"times, positions and quaternions, got {trajectory!r}"
                ) from exc
        self.trajectory = trajectory
        self.kp = _gain(kp, 6, "object_pd kp")
        self.kd = _gain(kd, 6, "object_pd kd")
        self.null_kp = float(_gain(null_kp, 1, "object_pd null_kp")[0])
        self.null_kd = float(_gain(null_kd, 1, "object_pd null_kd")[0])
        self.hold_kp = float(_gain(hold_kp, 1, "object_pd hold_kp")[0])
        self.hold_kd = float(_gain(hold_kd, 1, "object_pd hold_kd")[0])
        if not (np.isfinite(margin) and margin >= 0):
            raise InputError(f"object_pd margin: expected a force >= 0 [N], got {margin!r}")
        self.margin = float(margin)
        self.q_ref: np.ndarray | None = None
        self.hold_position: np.ndarray | None = None
        self.hold_rotation: np.ndarray | None = None
        self.last: InverseDynamicsResult | None = None
        self.last_tool_acceleration: np.ndarray | None = None

    def desired_acceleration(self, t: float, state: SystemState) -> np.ndarray:
        """(6,) ``a_d = a_ref + K_d (v_ref - v_o) + K_p e`` [m/s², rad/s²], world at the COM."""
        o = state.obj
        if self.trajectory is None:
            self.trajectory = MinimumJerkTrajectory.hold(o.position, o.quaternion)
        ref = self.trajectory(t)
        e = pose_error(ref.position, ref.rotation, o.position, o.rotation)
        return ref.acceleration + self.kd * (ref.twist - o.twist) + self.kp * e

    def hold_error(self, state: SystemState, evaluation: Evaluation
                   ) -> tuple[np.ndarray, np.ndarray]:
        """Tools' pose errors and twists relative to the object (steps 1 of the class doc).

        The first call fixes the held placements (``hold_position``, ``hold_rotation``).

        Args:
            state: the system state.
            evaluation: its evaluation (tool kinematics from ``evaluation.arms.tools``).

        Returns:
            ``(e, nu)``, both (n, 6) world axes: ``e`` the pose error ``[m; rad]`` from the
            tool to its held placement, ``nu`` the relative twist ``[ṗ - ẋ_o - ω_o × r;
            ω - ω_o]`` [m/s; rad/s].
        """
        o = state.obj
        tools = evaluation.arms.tools
        R_o = o.rotation
        r = tools.position - o.position
        if self.hold_position is None:
            self.hold_position = r @ R_o
            self.hold_rotation = np.einsum("ji,njk->nik", R_o, tools.rotation)
        e = np.empty((len(r), 6))
        e[:, :3] = self.hold_position @ R_o.T - r
        R_des = np.einsum("ij,njk->nik", R_o, self.hold_rotation)
        for i in range(len(r)):  # a few arms: log3 per arm
            e[i, 3:] = pin.log3(R_des[i] @ tools.rotation[i].T)
        w = o.twist[3:]
        nu = tools.twist - o.twist
        nu[:, :3] -= cross(w, r)
        return e, nu

    def __call__(self, t, state, evaluation) -> np.ndarray:
        """(nv,) torques [N m]."""
        s = self.system
        b = evaluation.blocks
        arms = evaluation.arms
        if self.q_ref is None:
            self.q_ref = np.array(state.q, dtype=float)
        a_d = self.desired_acceleration(t, state)
        fd = distribute_forces(b, b.M_o @ a_d - b.h_o, s.unilateral, self.margin)
        e, nu = self.hold_error(state, evaluation)
        a_tool = _transport(arms.tools.position - state.obj.position, state.obj.twist, a_d,
                            nu, self.hold_kp * e - self.hold_kd * nu)
        self.last_tool_acceleration = a_tool
        # q̈ = z + J⁺ (a - J̇q̇ - J z), z the joint-space PD; J⁺ = Jᵀ (J Jᵀ + ε I)⁻¹ (one
        # batched 6 x 6 solve per call; padded columns of J are zero).
        J = arms.J
        Jt = J.transpose(0, 2, 1)
        JJt = J @ Jt
        JJt += (JACOBIAN_DAMPING / 6.0 * np.trace(JJt, axis1=1, axis2=2))[:, None, None] * _EYE6
        err = pin.difference(s.arm_set.model, state.q, self.q_ref)
        z = s.pad(self.null_kp * err - self.null_kd * state.v)
        rhs = a_tool - arms.Jdot_qdot - (J @ z[:, :, None])[:, :, 0]
        qdd_desired = z + (Jt @ np.linalg.solve(JJt, rhs[:, :, None]))[:, :, 0]
        self.last = inverse_dynamics(b, a_d, qdd_desired, fd.mu_I, fd.basis)
        return s.unpad(self.last.tau)


CONTROLLERS: dict[str, type[Controller]] = {
    c.name: c for c in (ZeroTorque, GravityCompensation, JointPD, ObjectPD)
}
"""Controller classes by type name."""


def make_controller(kind: str, system: MultiArmSystem, **params) -> Controller:
    """Build a controller by type name.

    Args:
        kind: one of ``CONTROLLERS`` (``none``, ``gravity_compensation``, ``joint_pd``,
            ``object_pd``).
        system: the system to control.
        **params: the keyword arguments of that controller.

    Raises:
        InputError: unknown type (lists the known ones) or bad parameters.
    """
    if kind not in CONTROLLERS:
        raise InputError(
            f"unknown controller type {kind!r}; known types: {', '.join(sorted(CONTROLLERS))}"
        )
    try:
        return CONTROLLERS[kind](system, **params)
    except TypeError as exc:
        raise InputError(f"controller {kind!r}: bad parameters {sorted(params)}: {exc}") from exc


ControllerFunction = Callable[[float, SystemState, Evaluation], np.ndarray]

__all__ = [
    "CONTROLLERS",
    "Controller",
    "ControllerFunction",
    "GravityCompensation",
    "JointPD",
    "ObjectPD",
    "ZeroTorque",
    "make_controller",
    "tool_acceleration_from_object",
]
