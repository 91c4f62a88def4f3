"""Every name exported in an ``__all__`` must exist (a stale export is a defect); the top
level is the curated user API, with ``pin.SE3`` placements and one argument order."""

import importlib

import pytest

PACKAGES = [
    "multiarm_pin",
    "multiarm_pin.constraints",
    "multiarm_pin.dynamics",
    "multiarm_pin.grasp",
    "multiarm_pin.study",
    "multiarm_pin.study.spec",
    "multiarm_pin.study.metrics",
    "multiarm_pin.study.case",
    "multiarm_pin.study.execution",
    "multiarm_pin.study.store",
    "multiarm_pin.study.report",
    "multiarm_pin.design",
    "multiarm_pin.design.spec",
    "multiarm_pin.design.candidates",
    "multiarm_pin.design.assessment",
    "multiarm_pin.design.scoring",
    "multiarm_pin.design.search",
    "multiarm_pin.design.report",
]


@pytest.mark.parametrize("name", PACKAGES)
def test_all_names_exist(name):
    module = importlib.import_module(name)
    assert module.__all__, f"{name} exports nothing"
    missing = [n for n in module.__all__ if not hasattr(module, n)]
    assert not missing, f"{name}.__all__ names missing attributes: {missing}"


def test_version_matches_package_metadata():
    from importlib.metadata import version

    import multiarm_pin

    assert multiarm_pin.__version__ == version("multiarm_pin")


# ----------------------------------------------------------------------------- top level
def test_top_level_is_the_curated_user_api():
    """About 20 names for the user's story, the four errors a user catches, the version;
    every one imports from the top level and has a docstring."""
    import multiarm_pin

    names = [n for n in multiarm_pin.__all__ if n != "__version__"]
    errors = {"MultiArmError", "InputError", "UnreachableError", "DynamicsError"}
    assert errors <= set(names)
    assert 15 <= len(set(names) - errors) <= 24, sorted(names)
    assert len(names) == len(set(names))
    namespace: dict = {}
    exec(f"from multiarm_pin import {', '.join(multiarm_pin.__all__)}", namespace)
    for n in names:
        doc = getattr(namespace[n], "__doc__", None)
        assert doc and doc.strip(), f"multiarm_pin.{n} has no docstring"
    assert isinstance(namespace["__version__"], str)


def test_top_level_errors_are_those_of_the_exceptions_module():
    import multiarm_pin
    import multiarm_pin.exceptions as exc
    from multiarm_pin.model import ik

    for n in ("MultiArmError", "InputError", "UnreachableError", "DynamicsError"):
        assert getattr(multiarm_pin, n) is getattr(exc, n)
        assert issubclass(getattr(exc, n), exc.MultiArmError)
    assert ik.UnreachableError is exc.UnreachableError  # still importable where it was


def test_solver_names_stay_importable_from_their_layers():
    """Names that left the top level live on in their subpackages."""
    from multiarm_pin.constraints import ConstraintSet, Joint, make_joint_from_placements
    from multiarm_pin.dynamics import Solution, SystemBlocks, solve
    from multiarm_pin.model.arm_set import ArmSet, ArmSetTerms
    from multiarm_pin.model.polyhedron import Polyhedron, box, from_vertices
    from multiarm_pin.model.rigid_object import ObjectState

    assert all((ConstraintSet, Joint, make_joint_from_placements, Solution, SystemBlocks, solve,
                ArmSet, ArmSetTerms, Polyhedron, box, from_vertices, ObjectState))


# ----------------------------------------------------------------------------- placements
def _two_welded_ur5s():
    """Two UR5s (no meshes) and a box, with q0 and the box placement of a consistent grasp."""
    import numpy as np
    import pinocchio as pin

    import multiarm_pin as mp

    arms = [mp.load_arm("ur5", name=f"a{i}", load_visuals=False,
                        base=pin.SE3(pin.rpy.rpyToMatrix(0, 0, np.pi * i),
                                     np.array([0.0, 0.55 * (1 - 2 * i), 0.0])))
            for i in range(2)]
    q0 = [np.array([0.0, -1.2, 1.5, -1.9, -1.57, 0.0])] * 2
    placement = pin.SE3(pin.rpy.rpyToMatrix(0.1, -0.2, 0.3), np.array([0.4, 0.1, 0.35]))
    return arms, mp.RigidObject.box([0.4, 0.3, 0.2], 2.0), q0, placement


def test_load_arm_base_is_a_placement():
    import numpy as np
    import pinocchio as pin

    import multiarm_pin as mp
    from multiarm_pin.model.arm import Arm

    base = pin.SE3(pin.rpy.rpyToMatrix(0.1, -0.2, 0.7), np.array([0.3, -0.4, 0.2]))
    arm = mp.load_arm("ur5", name="u", base=base, load_visuals=False)
    ref = Arm.from_robot_name("ur5", name="u", base_placement=base, load_visuals=False)
    q = np.array([0.3, -1.0, 1.2, -0.5, 0.8, 0.1])
    assert arm.name == "u" and arm.base_placement.isApprox(base, 1e-14)
    assert arm.tool_placement(q).isApprox(ref.tool_placement(q), 1e-12)
    # the base is baked into the model: the tool is base * (the arm at the origin's tool)
    at_origin = mp.load_arm("ur5", load_visuals=False)
    assert arm.tool_placement(q).isApprox(base * at_origin.tool_placement(q), 1e-12)
    for bad in ((np.zeros(3), np.array([0, 0, 0, 1.0])), np.eye(4), {"position": [0, 0, 0]}):
        with pytest.raises(mp.InputError, match="load_arm base: expected a pinocchio.SE3"):
            mp.load_arm("ur5", base=bad)
    skew = pin.SE3(np.diag([1.0, 1.0, 2.0]), np.zeros(3))
    with pytest.raises(mp.InputError, match="not a rotation matrix"):
        mp.load_arm("ur5", base=skew)
    with pytest.raises(mp.InputError, match="package_dirs is for URDF arms only"):
        mp.load_arm("ur5", package_dirs=["."])


def test_from_initial_state_and_joints_take_one_order_and_a_placement():
    """``(arms, obj, specs, q0, object_placement)`` for both; the state holds the placement."""
    import numpy as np

    import multiarm_pin as mp
    from multiarm_pin.system import joints_from_initial_state

    arms, box, q0, placement = _two_welded_ur5s()
    joints = joints_from_initial_state(arms, box, ["weld", "revolute"], q0, placement)
    system, state = mp.MultiArmSystem.from_initial_state(arms, box, ["weld", "revolute"], q0,
                                                         placement)
    # the joints hold each tool where it is, relative to the object at that placement
    for i, (arm, joint) in enumerate(zip(arms, joints, strict=True)):
        assert joint.tool_in_object.isApprox(placement.actInv(arm.tool_placement(q0[i])), 1e-12)
        assert system.joints[i].tool_in_object.isApprox(joint.tool_in_object, 1e-12)
    np.testing.assert_allclose(state.obj.position, placement.translation, atol=1e-15)
    np.testing.assert_allclose(state.obj.rotation, placement.rotation, atol=1e-12)
    system.check_initial_state(state)  # every joint at zero gap at that state
    with pytest.raises(mp.InputError, match="object_placement: expected a pinocchio.SE3"):
        mp.MultiArmSystem.from_initial_state(arms, box, ["weld"] * 2, q0,
                                             placement.translation)
    with pytest.raises(mp.InputError, match="object_placement: expected a pinocchio.SE3"):
        joints_from_initial_state(arms, box, ["weld"] * 2, q0,
                                  (placement.translation, np.array([0, 0, 0, 1.0])))


def test_trajectory_through_placements():
    import numpy as np
    import pinocchio as pin

    import multiarm_pin as mp

    a = pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, 0.0), np.array([0.5, 0.0, 0.35]))
    b = pin.SE3(pin.rpy.rpyToMatrix(0.2, -0.1, 2.9), np.array([0.4, 0.1, 0.5]))
    traj = mp.MinimumJerkTrajectory.through([0.0, 1.0], [a, b])
    for t, M in ((0.0, a), (1.0, b)):
        s = traj.sample(t)
        assert pin.SE3(s.rotation, s.position).isApprox(M, 1e-12)
        np.testing.assert_allclose(s.twist, 0.0, atol=1e-12)
    with pytest.raises(mp.InputError, match="trajectory placement 1: expected a pinocchio.SE3"):
        mp.MinimumJerkTrajectory.through([0.0, 1.0], [a, b.translation])
    with pytest.raises(mp.InputError, match="at least one placement"):
        mp.MinimumJerkTrajectory.through([], [])


def test_write_replay_refuses_a_result_of_another_system(tmp_path):
    import numpy as np

    import multiarm_pin as mp

    arms, box, q0, placement = _two_welded_ur5s()
    system, state = mp.MultiArmSystem.from_initial_state(arms, box, ["weld"] * 2, q0, placement)
    one, one_state = mp.MultiArmSystem.from_initial_state(arms[:1], box, ["weld"], q0[:1],
                                                          placement)
    result = mp.simulate(one, one_state, None, 0.004, 0.002)
    with pytest.raises(mp.InputError, match=r"q of shape \(T, 12\).*got SimulationResult "
                                            r"with q \(3, 6\)"):
        mp.write_replay(result, system, tmp_path / "replay.html")
    with pytest.raises(mp.InputError, match="expected the SimulationResult of this system"):
        mp.write_replay({"q": np.zeros((3, 12))}, system, tmp_path / "replay.html")
    assert not (tmp_path / "replay.html").exists()


def test_every_arm_loader_loads_the_meshes_by_default():
    """One default (True) for ``load_arm``, ``Arm.from_robot_name``, ``Arm.from_urdf``,
    the scenario's ``build_arm`` and ``build_scenario``."""
    import inspect

    from multiarm_pin.app.scenario import build_arm, build_scenario
    from multiarm_pin.model.arm import Arm, load_arm

    for f in (load_arm, Arm.from_robot_name, Arm.from_urdf, build_arm, build_scenario):
        assert inspect.signature(f).parameters["load_visuals"].default is True, f.__qualname__


def test_design_is_the_callable_design_package():
    """``multiarm_pin.design(spec)`` designs; ``multiarm_pin.design.load_design`` reads specs,
    whichever of the two is reached first."""
    import multiarm_pin
    import multiarm_pin.design.cli  # noqa: F401 (the subpackage imported first)

    assert callable(multiarm_pin.design)
    assert multiarm_pin.design.design.__doc__
    assert multiarm_pin.design.load_design is multiarm_pin.design.spec.load_design
