"""multiarm_pin: multi-arm manipulation of large objects through frictionless point contacts.

Three layers, after the thesis it implements: grasp analysis (:mod:`multiarm_pin.grasp`),
the constraint layer (:mod:`multiarm_pin.constraints`) and the dynamics
(:mod:`multiarm_pin.dynamics`, :mod:`multiarm_pin.system`, :mod:`multiarm_pin.sim.simulation`),
with arms loaded into Pinocchio (:mod:`multiarm_pin.model.arm`). Conventions (units, frames, signs):
``docs/ARCHITECTURE.md``.
"""

from multiarm_pin.app.scenario import build_scenario, load_scenario
from multiarm_pin.constraints import ConstraintSet, Joint, make_joint, make_joint_from_placements
from multiarm_pin.dynamics import Solution, SystemBlocks, solve
from multiarm_pin.exceptions import (
    ConstraintError,
    DynamicsError,
    FrameNotFoundError,
    GraspError,
    InputError,
    MultiArmError,
    RobotNotFoundError,
    ScenarioError,
    SingularityError,
    URDFError,
)
from multiarm_pin.model.arm import Arm, ArmTerms, available_robots, load_arm
from multiarm_pin.model.arm_set import ArmSet, ArmSetTerms
from multiarm_pin.model.kinematics import BodyKinematics
from multiarm_pin.model.polyhedron import Polyhedron, box, from_vertices
from multiarm_pin.model.rigid_object import ObjectState, RigidObject
from multiarm_pin.sim.controllers import make_controller
from multiarm_pin.sim.simulation import SimulationResult, simulate
from multiarm_pin.system import MultiArmSystem, SystemState

__version__ = "0.1.0"

__all__ = [
    "Arm",
    "ArmSet",
    "ArmSetTerms",
    "ArmTerms",
    "BodyKinematics",
    "ConstraintError",
    "ConstraintSet",
    "DynamicsError",
    "FrameNotFoundError",
    "GraspError",
    "InputError",
    "Joint",
    "MultiArmError",
    "MultiArmSystem",
    "ObjectState",
    "Polyhedron",
    "RigidObject",
    "RobotNotFoundError",
    "ScenarioError",
    "SimulationResult",
    "SingularityError",
    "Solution",
    "SystemBlocks",
    "SystemState",
    "URDFError",
    "__version__",
    "available_robots",
    "box",
    "build_scenario",
    "from_vertices",
    "load_arm",
    "load_scenario",
    "make_controller",
    "make_joint",
    "make_joint_from_placements",
    "simulate",
    "solve",
]
