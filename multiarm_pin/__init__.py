"""multiarm_pin: multi-arm manipulation of large objects through frictionless point contacts.

The names below are the user's story, in its order (the README's "Python" section runs it):
load arms (:func:`load_arm`), describe the object (:class:`RigidObject`) and the grasp (joint
specs, :func:`make_joint`; contacts on faces, :class:`Grasp`, :func:`contact_on_face`), place
the arms by inverse kinematics (:func:`ik_tool_placement`, :func:`ik_frame_points`), build the
system (:class:`MultiArmSystem`), control (:class:`MinimumJerkTrajectory`,
:func:`make_controller`), simulate (:func:`simulate`), analyse (:class:`SimulationResult`,
:func:`form_closure`) and replay (:func:`write_replay`); or do it all from a scenario file
(:func:`load_scenario`, :func:`build_scenario`). Every placement is a ``pin.SE3``.

Everything else stays importable from its layer: :mod:`multiarm_pin.model` (arms, kinematics,
IK), :mod:`multiarm_pin.grasp` (thesis ch. 2), :mod:`multiarm_pin.constraints` (ch. 3),
:mod:`multiarm_pin.dynamics` (ch. 4: blocks and solvers), :mod:`multiarm_pin.sim`,
:mod:`multiarm_pin.app`, :mod:`multiarm_pin.study`, and every exception in
:mod:`multiarm_pin.exceptions` (the four a user catches are here too). Conventions (units,
frames, signs): ``docs/ARCHITECTURE.md``.
"""

from multiarm_pin.app.replay import write_replay
from multiarm_pin.app.scenario import build_scenario, load_scenario
from multiarm_pin.constraints import make_joint
from multiarm_pin.exceptions import DynamicsError, InputError, MultiArmError, UnreachableError
from multiarm_pin.grasp import Grasp, contact_on_face, form_closure
from multiarm_pin.model.arm import Arm, available_robots, load_arm
from multiarm_pin.model.ik import ik_frame_points, ik_tool_placement
from multiarm_pin.model.rigid_object import RigidObject
from multiarm_pin.sim.controllers import make_controller
from multiarm_pin.sim.simulation import SimulationResult, simulate
from multiarm_pin.sim.trajectories import MinimumJerkTrajectory
from multiarm_pin.system import MultiArmSystem, SystemState

__version__ = "0.1.0"

__all__ = [
    # arms
    "Arm",
    "available_robots",
    "load_arm",
    # object and grasp
    "RigidObject",
    "Grasp",
    "contact_on_face",
    "make_joint",
    # inverse kinematics
    "ik_frame_points",
    "ik_tool_placement",
    # system
    "MultiArmSystem",
    "SystemState",
    # control and simulation
    "MinimumJerkTrajectory",
    "make_controller",
    "simulate",
    "SimulationResult",
    # analysis and replay
    "form_closure",
    "write_replay",
    # scenario files
    "build_scenario",
    "load_scenario",
    # the errors a user catches (all in multiarm_pin.exceptions)
    "MultiArmError",
    "InputError",
    "UnreachableError",
    "DynamicsError",
    "__version__",
]
