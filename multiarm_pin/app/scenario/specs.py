"""The validated content of a scenario file: the names it may use and the spec dataclasses.

:func:`~multiarm_pin.app.scenario.schema.parse_scenario` fills these from a YAML file (the
format is described there); :mod:`multiarm_pin.app.scenario.build` turns them into a system.
Placements are ``pin.SE3``; positions in metres, angles in radians, world axes unless said.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from multiarm_pin.constraints.joint_types import JOINT_TYPES
from multiarm_pin.dynamics import SOLVERS
from multiarm_pin.sim.controllers import CONTROLLERS
from multiarm_pin.sim.simulation import INTEGRATORS

JOINT_TYPE_NAMES = tuple(k for k, e in JOINT_TYPES.items() if e.placeable)
"""Joint types a scenario may name: the placeable entries of the registry (not ``custom``)."""
DEPRECATED_JOINT_TYPES = {"contacts": "fingertips"}
"""Old joint type names still read (with a warning), and the name that replaced them."""
CONTROLLER_TYPES = tuple(CONTROLLERS)
"""Controller types a scenario may name (:data:`multiarm_pin.sim.controllers.CONTROLLERS`)."""
INTEGRATOR_NAMES = tuple(INTEGRATORS)
"""Integrators a scenario may name (:data:`multiarm_pin.sim.simulation.INTEGRATORS`)."""
SOLVER_NAMES = tuple(SOLVERS)
"""Forward-dynamics solvers a scenario may name (:data:`multiarm_pin.dynamics.SOLVERS`)."""


# ----------------------------------------------------------------------------- data
@dataclass(frozen=True)
class ObjectSpec:
    """The object as read from a scenario.

    Attributes:
        shape_type: ``"box"`` or ``"polyhedron"``.
        size: (3,) box edge lengths [m] (box only).
        vertices: (V, 3) vertices in the object (COM) frame [m] (polyhedron only).
        mass: [kg].
        inertia: (3, 3) about the COM in object axes [kg m^2], or None (uniform density).
        position: (3,) initial COM position in the world [m].
        quaternion: (4,) initial orientation ``[x, y, z, w]``.
        twist: (6,) initial ``[ẋ; ω]`` in world axes [m/s, rad/s].
        external_wrench: ``((from, to, wrench (6,)), ...)``: a wrench ``[f; m]`` at the COM
            in world axes [N, N m] for ``from <= t < to`` [s].
    """

    shape_type: str
    size: np.ndarray | None
    vertices: np.ndarray | None
    mass: float
    inertia: np.ndarray | None
    position: np.ndarray
    quaternion: np.ndarray
    twist: np.ndarray
    external_wrench: tuple = ()

    @property
    def placement(self) -> pin.SE3:
        """Initial world placement of the object (COM) frame."""
        return pin.SE3(pin.Quaternion(self.quaternion).toRotationMatrix(), self.position)


@dataclass(frozen=True)
class SupportSpec:
    """A support as read from a scenario.

    Attributes:
        name: unique name. point: (3,) a point of the plane, world [m]. normal: (3,) unit
        normal out of the support, world axes. points: ``"vertices"`` or (P, 3) points in
        the object frame [m]. restitution: Newton's coefficient, 0..1. index: position in
        the file's ``supports`` list. extent: None (an infinite plane) or (2,) ``[lx, ly]``
        [m], the side lengths of the supporting rectangle centred at ``point``. x_axis: None
        (the default axis) or (3,) the world direction of the rectangle's x side (projected
        onto the plane).
    """

    name: str
    point: np.ndarray
    normal: np.ndarray
    points: str | np.ndarray
    restitution: float
    index: int
    extent: np.ndarray | None = None
    x_axis: np.ndarray | None = None


@dataclass(frozen=True)
class ContactSpec:
    """One fingertip contact of a ``fingertips`` joint.

    Attributes:
        tip: the fingertip's name: the frame name of its sphere centre in the arm's model,
            or ``tip<k>`` (k its position in ``contacts``) when ``tip_in_tool`` gives it.
        face: face name (``+x`` ...) or index of the object's polyhedron.
        point: (3,) desired contact point on that face, object frame [m], or None (the
            face's centre is used as a preference).
        tip_in_tool: (3,) the sphere centre in the arm's tool frame [m] (a gripper with no
            frame of its own per tip), or None (the frame ``tip`` gives it).
    """

    tip: str
    face: str | int
    point: np.ndarray | None
    tip_in_tool: np.ndarray | None = None


@dataclass(frozen=True)
class JointSpec:
    """How an arm is joined to the object.

    Attributes:
        type: one of :data:`JOINT_TYPE_NAMES`.
        params: extra parameters of the joint library (``size``, ``tip_radius``, ...).
        placement_in_object: joint frame in the object frame, or None (tool at ``q0``).
        placement_in_tool: joint frame in the tool frame, or None (identity).
        contacts: fingertip contacts (``fingertips`` type only).
    """

    type: str
    params: dict = field(default_factory=dict)
    placement_in_object: pin.SE3 | None = None
    placement_in_tool: pin.SE3 | None = None
    contacts: tuple[ContactSpec, ...] = ()


@dataclass(frozen=True)
class ArmSpec:
    """One arm as read from a scenario.

    Attributes:
        name: unique name.
        robot: ``example_robot_data`` name, or None.
        urdf: absolute URDF path, or None.
        tool_frame: frame the tool is attached to (None: the robot's default).
        tool_offset: tool placement relative to ``tool_frame`` (None: identity).
        base: world placement of the robot's root.
        locked_joints: joints locked at their neutral value (URDF arms).
        q0: (nq,) initial configuration, or None (inverse kinematics).
        q_seed: (nq,) seed of the inverse kinematics, or None (neutral).
        v0: (nv,) initial joint velocities, or None (zero).
        joint: the joint to the object.
        index: position in the file's ``arms`` list.
    """

    name: str
    robot: str | None
    urdf: str | None
    tool_frame: str | None
    tool_offset: pin.SE3 | None
    base: pin.SE3
    locked_joints: tuple[str, ...]
    q0: np.ndarray | None
    q_seed: np.ndarray | None
    v0: np.ndarray | None
    joint: JointSpec
    index: int


@dataclass(frozen=True)
class ControllerSpec:
    """Controller type and its parameters (passed to ``make_controller``)."""

    type: str
    params: dict = field(default_factory=dict)


@dataclass(frozen=True)
class SimulationSpec:
    """Simulation settings.

    Attributes:
        duration: [s]. integrator: one of :data:`INTEGRATOR_NAMES`. dt: step and output sampling
        period [s]. solver: one of :data:`SOLVER_NAMES`. baumgarte: ``(α, β)`` [1/s].
        compiled: False runs every step on the numpy reference path (``simulate(compiled=)``).
    """

    duration: float = 2.0
    integrator: str = "rk4"
    dt: float = 1e-3
    solver: str = "auto"  # object-first, switching to the singular-arm variant when needed
    baumgarte: tuple[float, float] = (5.0, 5.0)
    compiled: bool = True


@dataclass(frozen=True)
class LimitsSpec:
    """What a run does when a limit is exceeded: ``"report"`` or ``"stop"`` per kind.

    ``torque`` may also be ``"saturate"``: the actuators clip the applied torque to their
    URDF effort limits inside the dynamics (``simulate(torque_limit=...)``; the commanded
    torque is recorded beside it), so the torque limit is never exceeded.

    Attributes:
        torque, velocity, position, collision: the policy of each kind
        (:data:`~multiarm_pin.feasibility.POLICIES`; ``torque`` also ``"saturate"``).
    """

    torque: str = "report"
    velocity: str = "report"
    position: str = "report"
    collision: str = "report"

    def stops(self) -> tuple[str, ...]:
        """The kinds whose first violation ends the run."""
        return tuple(k for k in ("torque", "velocity", "position", "collision")
                     if getattr(self, k) == "stop")


@dataclass(frozen=True)
class Scenario:
    """A validated scenario file.

    Attributes:
        name: scenario name. file: where it was read from. description: free text.
        gravity: (3,) [m/s^2] world. object: :class:`ObjectSpec`. arms: the arms.
        controller: :class:`ControllerSpec`. simulation: :class:`SimulationSpec`.
        data: the parsed YAML mapping (URDF paths made absolute), for copying the scenario.
        supports: the supports. limits: :class:`LimitsSpec`. ground: height [m] of the
        ground plane ``z = ground`` (collisions), or None for no ground.
    """

    name: str
    file: str
    description: str
    gravity: np.ndarray
    object: ObjectSpec
    arms: tuple[ArmSpec, ...]
    controller: ControllerSpec
    simulation: SimulationSpec
    data: dict
    supports: tuple[SupportSpec, ...] = ()
    limits: LimitsSpec = LimitsSpec()
    ground: float | None = 0.0


__all__ = [
    "CONTROLLER_TYPES",
    "DEPRECATED_JOINT_TYPES",
    "INTEGRATOR_NAMES",
    "JOINT_TYPE_NAMES",
    "SOLVER_NAMES",
    "ArmSpec",
    "ContactSpec",
    "ControllerSpec",
    "JointSpec",
    "LimitsSpec",
    "ObjectSpec",
    "Scenario",
    "SimulationSpec",
    "SupportSpec",
]
