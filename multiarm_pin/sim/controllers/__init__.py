"""Controllers: joint torques from the time, the state and the blocks of the dynamics.

A controller is a callable ``controller(t, state, evaluation) -> tau (nv,)`` [N m] where
``evaluation`` (:class:`~multiarm_pin.system.Evaluation`) holds the blocks at zero torque
(``h = -nle``), so a controller can use the mass matrices, Jacobians and constraint rows
without recomputing them (the protocol :class:`ControllerFunction`). Build one by name with
:func:`make_controller`, the one dispatch point of the registry :data:`CONTROLLERS`:

- ``none``: zero torque;
- ``gravity_compensation``: ``τ = g(q)``, the arms' own weight only (the object's weight is
  not compensated);
- ``joint_pd``: ``τ = g(q) + K_p (q_ref ⊖ q) - K_d v`` (``q_ref`` defaults to the
  configuration at the first call, i.e. ``q0``);
- ``phased_pd``: ``object_pd`` through phases (:mod:`~multiarm_pin.sim.controllers.phased`:
  tilt about a pivot edge, move, hold), each with the support rows that keep pressing, the
  arms released and the arms' held-point offsets (approach, retract); the supports are in
  its force distribution (compiled: :mod:`multiarm_pin._compiled.phased`);
- ``object_pd``: object-level computed torque. A desired object trajectory
  (:class:`~multiarm_pin.sim.trajectories.MinimumJerkTrajectory`, or ``waypoints``; default:
  hold the pose of the first call) and PD on the object pose give a desired acceleration
  ``a_d = a_ref + K_d (v_ref - v_o) + K_p [p_ref - p; log(R_ref Rᵀ)]``. The internal forces
  come from :func:`multiarm_pin.dynamics.force_distribution.distribute_forces` (every
  unilateral contact pushes with at least ``margin``, forces as small as possible). The
  secondary objective holds every contact's tip centre at its first-call place *relative to
  the object* (the relative motion ``T_i α_i`` of thesis Sec 3.5, Eq 3.5-3.6): a PD on each
  point's position in the object frame gives a desired relative acceleration, the point's
  desired classical acceleration is that of the object's material point there under ``a_d``
  plus this correction (:func:`tool_acceleration_from_object`), and the desired joint
  accelerations are the least-squares solution of these point tasks, with a joint-space PD
  on the motions they leave free. The inverse dynamics
  (:func:`~multiarm_pin.dynamics.inverse_dynamics.inverse_dynamics`, Eq 3.10) keeps of them
  what the constraint rows leave free and gives the torques. With these torques the forward
  dynamics returns exactly ``a_d`` and those multipliers, and frictionless fingertips do not
  slide along their faces.

One module per controller family: :mod:`~multiarm_pin.sim.controllers.base` (the protocol,
the base class and the simple controllers), :mod:`~multiarm_pin.sim.controllers.object_pd`
and :mod:`~multiarm_pin.sim.controllers.relative_motion` (its kinematics).
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass

from multiarm_pin._registry import lookup
from multiarm_pin.exceptions import InputError
from multiarm_pin.sim.controllers.base import (
    Controller,
    ControllerFunction,
    GravityCompensation,
    JointPD,
    ZeroTorque,
)
from multiarm_pin.sim.controllers.object_pd import (
    GRASP_RANK_TOLERANCE,
    JACOBIAN_DAMPING,
    ObjectPD,
    ObjectPDPlan,
    grasp_rank,
)
from multiarm_pin.sim.controllers.phased import PhasedPD
from multiarm_pin.sim.controllers.relative_motion import tool_acceleration_from_object
from multiarm_pin.system import MultiArmSystem


@dataclass(frozen=True)
class ControllerType:
    """One controller type of the registry.

    Attributes:
        name: the type name (the scenario's ``controller.type``).
        cls: the :class:`Controller` subclass, ``cls(system, **params)``.
        follows_trajectory: it takes a desired object motion (``trajectory`` or
            ``waypoints``); the others hold or act in joint space.
        description: one line for humans.
        kernel: the compiled controller that serves it in the compiled loop, a name of
            :data:`CONTROLLER_KERNELS`, or None: runs with it are the reference stepper's
            (and say so once, :func:`controller_kernel`).
    """

    name: str
    cls: type[Controller]
    follows_trajectory: bool
    description: str
    kernel: str | None = None

    @property
    def parameters(self) -> tuple[str, ...]:
        """Keyword parameters the controller accepts (besides ``system``), in order."""
        sig = inspect.signature(self.cls.__init__)
        return tuple(p for p in sig.parameters if p not in ("self", "system"))


CONTROLLER_KERNELS: dict[str, str] = {
    "zero_torque": "zero torque (the compiled loop's control mode CONTROL_NONE)",
    "object_pd": "ObjectPD's compiled path (multiarm_pin._compiled.controller_kernels)",
    "phased_pd": "PhasedPD's compiled path (multiarm_pin._compiled.phased)",
}
"""The compiled controllers, by name: what :attr:`ControllerType.kernel` names. The compiled
loop says which of them it runs (``CONTROLLER_KERNELS`` of
:class:`~multiarm_pin.sim.contact_loop.ContactLoop`)."""

CONTROLLERS: dict[str, ControllerType] = {e.name: e for e in (
    ControllerType("none", ZeroTorque, False, "zero torque", kernel="zero_torque"),
    ControllerType("gravity_compensation", GravityCompensation, False,
                   "the arms' own gravity torques g(q) (not the object's weight)"),
    ControllerType("joint_pd", JointPD, False,
                   "g(q) + K_p (q_ref - q) - K_d v toward the first call's configuration"),
    ControllerType("object_pd", ObjectPD, True,
                   "object-level computed torque with force distribution (waypoints)",
                   kernel="object_pd"),
    ControllerType("phased_pd", PhasedPD, False,
                   "object_pd through phases (tilt, move, hold) with their own contact sets, "
                   "the supports in its force distribution", kernel="phased_pd"),
)}
"""Every controller type, by name (the names :func:`make_controller` and scenarios accept)."""


def controller_kernel(controller) -> tuple[str | None, str]:
    """The compiled controller that serves a run's ``controller``, read from :data:`CONTROLLERS`.

    The entry is the one whose class is exactly the controller's (a subclass may change what
    its instances compute, so it is not served by its parent's kernel).

    Args:
        controller: the run's controller, or None (zero torque).

    Returns:
        ``(kernel, why)``: a name of :data:`CONTROLLER_KERNELS` and ``""``, or None and why
        no kernel serves it (a sentence naming the controller).
    """
    if controller is None:
        return "zero_torque", ""
    entry = next((e for e in CONTROLLERS.values() if type(controller) is e.cls), None)
    if entry is None:
        return None, (f"the controller {type(controller).__name__} is not a type of the "
                      "registry (CONTROLLERS), so no compiled kernel serves it")
    if entry.kernel is None:
        return None, f"controller {entry.name!r} has no compiled kernel"
    if not getattr(controller, "compiled", True):
        return None, f"controller {entry.name!r} was built with compiled=False"
    return entry.kernel, ""


def make_controller(kind: str, system: MultiArmSystem, **params) -> Controller:
    """Build a controller by type name: the one dispatch point of :data:`CONTROLLERS`.

    Args:
        kind: a name of :data:`CONTROLLERS` (``none``, ``gravity_compensation``,
            ``joint_pd``, ``object_pd``).
        system: the system to control.
        **params: the keyword arguments of that controller (:attr:`ControllerType.parameters`;
            e.g. ``kp``, ``kd``, ``waypoints`` for ``object_pd``).

    Raises:
        InputError: unknown type (lists the known ones, with a did-you-mean) or bad
            parameters (lists the accepted ones).
    """
    entry = lookup(CONTROLLERS, kind, "controller type", plural="types")
    unknown = sorted(set(params) - set(entry.parameters))
    if unknown:
        raise InputError(f"controller {kind!r}: bad parameters {unknown}; accepted: "
                         f"{', '.join(entry.parameters) or 'none'}")
    return entry.cls(system, **params)


__all__ = [
    "CONTROLLERS",
    "CONTROLLER_KERNELS",
    "GRASP_RANK_TOLERANCE",
    "JACOBIAN_DAMPING",
    "Controller",
    "ControllerFunction",
    "ControllerType",
    "GravityCompensation",
    "JointPD",
    "ObjectPD",
    "ObjectPDPlan",
    "PhasedPD",
    "ZeroTorque",
    "controller_kernel",
    "grasp_rank",
    "make_controller",
    "tool_acceleration_from_object",
]
