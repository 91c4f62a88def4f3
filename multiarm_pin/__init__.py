"""multiarm_pin: multi-arm manipulation of large objects through frictionless point contacts.

The names below are the user's story, in its order (the README's "Python" section runs it):
load arms (:func:`load_arm`), describe the object (:class:`RigidObject`) and the grasp (joint
specs, :func:`make_joint`; contacts on faces, :class:`Grasp`, :func:`contact_on_face`), place
the arms by inverse kinematics (:func:`ik_tool_placement`, :func:`ik_frame_points`), build the
system (:class:`MultiArmSystem`), control (:class:`MinimumJerkTrajectory`,
:func:`make_controller`), simulate (:func:`simulate`), analyse (:class:`SimulationResult`,
:func:`form_closure`; is it physically possible: :func:`check_design` before,
:func:`feasibility_report` after) and replay (:func:`write_replay`); or do it all from a
scenario file (:func:`load_scenario`, :func:`build_scenario`). Or let the package choose the
arms' bases and contacts: :func:`design` (``multiarm_pin.design(spec)``, a callable package)
returns ranked scenarios. Every placement is a ``pin.SE3``.

Everything else stays importable from its layer: :mod:`multiarm_pin.model` (arms, kinematics,
IK), :mod:`multiarm_pin.grasp` (thesis ch. 2), :mod:`multiarm_pin.constraints` (ch. 3),
:mod:`multiarm_pin.dynamics` (ch. 4: blocks and solvers), :mod:`multiarm_pin.sim`,
:mod:`multiarm_pin.app`, :mod:`multiarm_pin.study`, and every exception in
:mod:`multiarm_pin.exceptions` (the four a user catches are here too). Conventions (units,
frames, signs): ``docs/ARCHITECTURE.md``.
"""

from multiarm_pin.exceptions import DynamicsError, InputError, MultiArmError, UnreachableError

# The names above are imported at first use (PEP 562): ``import multiarm_pin`` (and every
# ``import multiarm_pin.<module>``, the command line's included) then costs nothing for the
# layers it does not use (the replay's meshcat, the compiled kernels, the grasp analysis).
_LAZY = {
    "write_replay": "multiarm_pin.app.replay",
    "build_scenario": "multiarm_pin.app.scenario",
    "load_scenario": "multiarm_pin.app.scenario",
    "make_joint": "multiarm_pin.constraints",
    "Grasp": "multiarm_pin.grasp",
    "contact_on_face": "multiarm_pin.grasp",
    "form_closure": "multiarm_pin.grasp",
    "Arm": "multiarm_pin.model.arm",
    "available_robots": "multiarm_pin.model.arm",
    "load_arm": "multiarm_pin.model.arm",
    "ik_frame_points": "multiarm_pin.model.ik",
    "ik_tool_placement": "multiarm_pin.model.ik",
    "RigidObject": "multiarm_pin.model.rigid_object",
    "make_controller": "multiarm_pin.sim.controllers",
    "SimulationResult": "multiarm_pin.sim.simulation",
    "simulate": "multiarm_pin.sim.simulation",
    "MinimumJerkTrajectory": "multiarm_pin.sim.trajectories",
    "MultiArmSystem": "multiarm_pin.system",
    "FeasibilityReport": "multiarm_pin.feasibility",
    "Violation": "multiarm_pin.feasibility",
    "check_design": "multiarm_pin.feasibility",
    "feasibility_report": "multiarm_pin.feasibility",
    "SystemState": "multiarm_pin.system",
    "design": "multiarm_pin.design",
}


def __getattr__(name: str):
    """Import a top-level name of :data:`_LAZY` from its module at first use."""
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'multiarm_pin' has no attribute {name!r}")
    import importlib

    value = importlib.import_module(module)
    if module != f"{__name__}.{name}":  # a subpackage that is its own name: design
        value = getattr(value, name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


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
    "check_design",
    "feasibility_report",
    "FeasibilityReport",
    "Violation",
    "write_replay",
    # design: where the arms and the contacts go
    "design",
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
