"""The controller protocol, the base class of the built-in controllers, and the simple ones.

A controller is anything with ``controller(t, state, evaluation) -> tau (nv,)`` [N m]
(:class:`ControllerFunction`): the one protocol that :func:`~multiarm_pin.sim.simulation.simulate`
and the closed loop call. The built-in controllers derive from :class:`Controller`, which
checks the system and names the type; an object may also offer the optional fused path
``closed_loop(t, state, evaluation, solve)`` and a numpy ``reference(t, state, evaluation)``
(:class:`~multiarm_pin.sim.controllers.object_pd.ObjectPD` does), which
:func:`~multiarm_pin.sim.closed_loop.closed_loop_evaluation` uses when present.
"""

from __future__ import annotations

from typing import ClassVar, Protocol

import numpy as np
import pinocchio as pin

from multiarm_pin.exceptions import InputError
from multiarm_pin.system import Evaluation, MultiArmSystem, SystemState


class ControllerFunction(Protocol):
    """``controller(t, state, evaluation) -> tau (nv,)`` [N m].

    ``t`` [s]; ``evaluation`` (:class:`~multiarm_pin.system.Evaluation`) holds the blocks at
    zero torque (``h = -nle``).
    """

    def __call__(self, t: float, state: SystemState, evaluation: Evaluation) -> np.ndarray:
        """Joint torques (nv,) [N m] at time ``t`` [s]."""
        ...


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


def gain(value, size: int, name: str) -> np.ndarray:
    """A gain vector (size,) from a scalar or ``size`` numbers, all finite and >= 0.

    Raises:
        InputError: anything else (the message names ``name``).
    """
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
        self.kp = gain(kp, system.nv, "joint_pd kp")
        self.kd = gain(kd, system.nv, "joint_pd kd")
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


__all__ = ["Controller", "ControllerFunction", "GravityCompensation", "JointPD", "ZeroTorque",
           "gain"]
