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
  unilateral contact pushes with at least ``margin``, forces as small as possible), the joint
  accelerations closest to a joint-space PD that satisfy the constraint rows (so the PD acts
  on the joints' relative motion and on redundancy) and the torques from
  :func:`multiarm_pin.dynamics.inverse_dynamics.inverse_dynamics` (Eq 3.10). With these
  torques the forward dynamics returns exactly ``a_d`` and those multipliers.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar

import numpy as np
import pinocchio as pin

from multiarm_pin.dynamics.force_distribution import distribute_forces
from multiarm_pin.dynamics.inverse_dynamics import InverseDynamicsResult, inverse_dynamics
from multiarm_pin.exceptions import InputError
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


class ObjectPD(Controller):
    """Object-level computed torque on the inverse dynamics with force distribution.

    Args:
        system: the system.
        trajectory: desired object pose over time (a :class:`MinimumJerkTrajectory`, or a
            mapping ``{"times", "positions", "quaternions"}``); hold the first call's pose if
            None.
        kp: pose stiffness [1/s²], scalar or (6,) ``[x y z, rx ry rz]``.
        kd: pose damping [1/s], scalar or (6,).
        margin: least push [N] of every unilateral contact.
        null_kp: stiffness [1/s²] of the joint-space PD in the constraints' null space (keeps
            the joints' relative motion and redundant arms near the first call's ``q``).
        null_kd: its damping [1/s].

    Attributes:
        last: the :class:`~multiarm_pin.dynamics.inverse_dynamics.InverseDynamicsResult` of
            the last call (its ``mu`` are the planned forces).
    """

    name = "object_pd"

    def __init__(self, system: MultiArmSystem, trajectory=None, kp=100.0, kd=20.0,
                 margin: float = 1.0, null_kp: float = 25.0, null_kd: float = 10.0):
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
        if not (np.isfinite(margin) and margin >= 0):
            raise InputError(f"object_pd margin: expected a force >= 0 [N], got {margin!r}")
        self.margin = float(margin)
        self.q_ref: np.ndarray | None = None
        self.last: InverseDynamicsResult | None = None

    def desired_acceleration(self, t: float, state: SystemState) -> np.ndarray:
        """(6,) ``a_d = a_ref + K_d (v_ref - v_o) + K_p e`` [m/s², rad/s²], world at the COM."""
        o = state.obj
        if self.trajectory is None:
            self.trajectory = MinimumJerkTrajectory.hold(o.position, o.quaternion)
        ref = self.trajectory(t)
        e = pose_error(ref.position, ref.rotation, o.position, o.rotation)
        return ref.acceleration + self.kd * (ref.twist - o.twist) + self.kp * e

    def __call__(self, t, state, evaluation) -> np.ndarray:
        """(nv,) torques [N m]."""
        s = self.system
        b = evaluation.blocks
        if self.q_ref is None:
            self.q_ref = np.array(state.q, dtype=float)
        a_d = self.desired_acceleration(t, state)
        fd = distribute_forces(b, b.M_o @ a_d - b.h_o, s.unilateral, self.margin)
        err = pin.difference(s.arm_set.model, state.q, self.q_ref)
        qdd_desired = s.pad(self.null_kp * err - self.null_kd * state.v)
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
]
