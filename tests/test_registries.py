"""Every registry walked: the scenario reader accepts exactly its names, and every entry works.

Registries: joint types (:data:`multiarm_pin.constraints.JOINT_TYPES`), robots
(:data:`multiarm_pin.model.robots.ROBOTS`; each robot is loaded and runs a weld in
``test_robots.py``), solvers (:data:`multiarm_pin.dynamics.SOLVERS`), controllers
(:data:`multiarm_pin.sim.controllers.CONTROLLERS`) and integrators
(:data:`multiarm_pin.sim.simulation.INTEGRATORS`).
"""

from __future__ import annotations

import copy
import dataclasses
import re
import types
import warnings

import numpy as np
import pinocchio as pin
import pytest
from system_builders import FINGERTIP_CONTACTS, build_system, moving_state

from multiarm_pin.app.scenario import build_scenario, parse_scenario
from multiarm_pin.constraints import JOINT_TYPES, make_joint, make_joint_from_placements
from multiarm_pin.dynamics import SOLVERS, solve, solve_auto
from multiarm_pin.exceptions import InputError, RobotNotFoundError, ScenarioError
from multiarm_pin.model.arm import Arm
from multiarm_pin.model.polyhedron import box
from multiarm_pin.model.robots import ROBOTS, robot_entry
from multiarm_pin.sim.contact_loop import ContactLoop, unsupported_joints_note
from multiarm_pin.sim.controllers import (
    CONTROLLER_KERNELS,
    CONTROLLERS,
    ObjectPD,
    controller_kernel,
    make_controller,
)
from multiarm_pin.sim.simulation import INTEGRATORS, REFERENCE_NOTE, simulate
from multiarm_pin.sim.stepper import Stepper
from multiarm_pin.sim.trajectories import MinimumJerkTrajectory

HALF_PI = float(np.pi / 2)
Q_UR5 = [0.0, -1.2, 1.6, -0.4, 1.57, 0.0]
SCENARIO = {
    "name": "registry",
    "object": {"shape": {"type": "box", "size": [0.8, 0.4, 0.3]}, "mass": 4.0,
               "pose": {"position": [0.5, 0.0, 0.35], "quaternion": [0, 0, 0, 1]}},
    "arms": [{"name": "a", "robot": "ur5", "base": {"position": [0.0, 0.55, 0.0]}, "q0": Q_UR5,
              "joint": {"type": "weld"}}],
    "controller": {"type": "none"},
    "simulation": {"duration": 0.02, "dt": 0.01},
}


def _data(**changes) -> dict:
    """A copy of :data:`SCENARIO`; ``changes`` maps "a.b.c" key paths to values."""
    d = copy.deepcopy(SCENARIO)
    for path, value in changes.items():
        *head, last = path.split(".")
        node = d
        for k in head:
            node = node[int(k)] if k.isdigit() else node[k]
        node[last] = value
    return d


def _listed(err: ScenarioError, intro: str) -> set[str]:
    """The names a reader's error lists after ``intro`` (e.g. ``"expected one of "``)."""
    text = str(err).split(intro, 1)[1]
    return {w.strip() for w in re.split(r"[,;(]", text.split(" (")[0]) if w.strip()}


def _rejected(data: dict) -> ScenarioError:
    with pytest.raises(ScenarioError) as info:
        parse_scenario(data, "r.yaml")
    return info.value


# ----------------------------------------------------------------------------- joint types
FINGERTIP_JOINT = {"type": "fingertips", "tip_radius": 0.01,
                   "contacts": [{"tip": "tool0", "face": "+z", "point": [0.0, 0.0, 0.15]}]}


def test_scenario_joint_types_are_the_placeable_registry_entries():
    placeable = {k for k, e in JOINT_TYPES.items() if e.placeable}
    assert placeable == set(JOINT_TYPES) - {"custom"}  # custom needs explicit surfaces
    err = _rejected(_data(**{"arms.0.joint": {"type": "hinge"}}))
    assert err.key == "arms[0].joint.type"
    assert _listed(err, "expected one of ") == placeable | {"contacts"}  # + deprecated alias
    for name in sorted(placeable):
        joint = FINGERTIP_JOINT if JOINT_TYPES[name].from_contacts else {"type": name}
        sc = parse_scenario(_data(**{"arms.0.joint": joint}), "r.yaml")
        assert sc.arms[0].joint.type == name


def test_contacts_is_a_deprecated_alias_of_fingertips():
    joint = dict(FINGERTIP_JOINT, type="contacts")
    with pytest.warns(FutureWarning, match=r"r\.yaml: arms\[0\]\.joint\.type: 'contacts' is "
                                           r"deprecated; write 'fingertips'"):
        sc = parse_scenario(_data(**{"arms.0.joint": joint}), "r.yaml")
    assert sc.arms[0].joint.type == "fingertips"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the new name reads silently
        parse_scenario(_data(**{"arms.0.joint": FINGERTIP_JOINT}), "r.yaml")


@pytest.mark.parametrize("name", sorted(JOINT_TYPES))
def test_every_joint_type_builds_with_its_registered_dof_and_unilateral_default(name):
    entry = JOINT_TYPES[name]
    rng = np.random.default_rng(4)
    tool = pin.SE3(pin.exp3(rng.normal(size=3)), rng.normal(size=3))
    obj = pin.SE3(pin.exp3(rng.normal(size=3)), rng.normal(size=3))
    if entry.from_contacts:
        joint = make_joint_from_placements(name, tool, obj, polyhedron=box((0.4, 0.3, 0.2)),
                                           contacts=FINGERTIP_CONTACTS, radius=0.01)
    elif entry.placeable:
        joint = make_joint_from_placements(name, tool, obj)
    else:  # custom: a ball joint's three contacts, written out
        ball = {"type": "sphere", "center": [0, 0, 0], "radius": 0.05}
        joint = make_joint(name, joint_in_object=obj, contacts=[
            {"point": 0.05 * np.eye(3)[k], "surface": ball} for k in range(3)])
    assert joint.kind == name
    assert joint.dof == (entry.dof if entry.dof is not None else joint.dof)
    assert entry.dof is not None or name in ("fingertips", "custom")
    assert joint.unilateral.tolist() == [entry.unilateral] * len(joint.unilateral)
    assert len(joint.unilateral) == joint.n_constraints
    assert "name" in entry.parameters and entry.description


def test_corner_gripper_from_a_scenario_holds_a_box_corner():
    """Placed by inverse kinematics at the corner (-0.4, 0.2, 0.15) of the box, J's axes along
    the corner's outward normals (-x, +y, +z of the object: J = Rz(π/2)); the tool's z axis
    points down into the top face (J in the tool: Rx(π)). A second arm welds the other side
    (one 2-DOF grasp alone cannot make every object wrench)."""
    joint = {"type": "corner_gripper", "size": 0.05,
             "placement_in_object": {"position": [-0.4, 0.2, 0.15], "rpy": [0, 0, HALF_PI]},
             "placement_in_tool": {"position": [0, 0, 0], "rpy": [float(np.pi), 0, 0]}}
    arm = {k: v for k, v in SCENARIO["arms"][0].items() if k != "q0"}
    arm |= {"q_seed": Q_UR5, "joint": joint}
    weld = dict(SCENARIO["arms"][0], name="b", base={"position": [0.0, -0.55, 0.0]})
    data = _data(**{"arms": [arm, weld], "controller": {"type": "object_pd"}})
    built = build_scenario(parse_scenario(data, "r.yaml"))
    j = built.system.joints[0]
    assert (j.kind, j.dof, j.n_contacts) == ("corner_gripper", 2, 4) and j.unilateral.all()
    res = simulate(built.system, built.initial_state, make_controller("object_pd", built.system),
                   0.02, 0.01)
    assert not res.events and res.constraint_violation.max() < 1e-8
    err = _rejected(_data(**{"arms.0.joint": dict(joint, points_on="tool")}))
    assert err.key == "arms[0].joint.points_on" and "'corner_gripper'" in str(err)


# ----------------------------------------------------------------------------- robots
def test_robot_registry_entries_are_typed_and_looked_up_with_a_suggestion():
    assert all(e.name == k and e.tool_frame for k, e in ROBOTS.items())
    with pytest.raises(RobotNotFoundError, match=r"'ur55'.*did you mean 'ur5'"):
        robot_entry("ur55")


def test_ur3_loads_the_ur3_model_not_the_ur5():
    """example-robot-data 5.0.0 registers ur3 with its UR5 loader; the entry corrects it.

    Shoulder offsets of the two URDFs (``shoulder_lift_joint`` origin, y) [m]: UR3 0.1198,
    UR5 0.13585.
    """
    offsets = {}
    for robot in ("ur3", "ur5"):
        model = Arm.from_robot_name(robot, load_visuals=False).model
        offsets[robot] = model.jointPlacements[model.getJointId("shoulder_lift_joint")].translation
    assert offsets["ur3"][1] == pytest.approx(0.1198, abs=1e-9)
    assert offsets["ur5"][1] == pytest.approx(0.13585, abs=1e-9)


def test_kinova_needs_nine_numbers_in_q0_and_says_so():
    arm = Arm.from_robot_name("kinova", load_visuals=False)
    assert (arm.nq, arm.nv) == (9, 6)
    assert "nq = 9" in ROBOTS["kinova"].description
    from multiarm_pin.model import robots

    assert "9 numbers" in robots.__doc__


# ----------------------------------------------------------------------------- solvers
@pytest.fixture(scope="module")
def two_arms():
    """Two UR5s (weld and spherical joints) holding the box, moving."""
    system, state = build_system(["ur5", "ur5"], ["weld", "spherical"])
    return system, moving_state(system, state, np.random.default_rng(3), 0.5)


def test_scenario_solvers_are_the_registry(two_arms):
    err = _rejected(_data(**{"simulation.solver": "fastest"}))
    assert err.key == "simulation.solver" and _listed(err, "expected one of ") == set(SOLVERS)
    for name in SOLVERS:
        assert parse_scenario(_data(**{"simulation.solver": name}), "r.yaml").simulation.solver \
            == name


def test_every_solver_solves_a_small_system_and_agrees_with_the_dense_kkt(two_arms):
    system, state = two_arms
    tau = np.random.default_rng(5).normal(size=system.nv)
    blocks = system.blocks(state, tau).blocks
    ref = solve(blocks, "dense_kkt")
    for name, entry in SOLVERS.items():
        for sol in (solve(blocks, name), system.forward_dynamics(state, tau, name)[0]):
            np.testing.assert_allclose(sol.a_o, ref.a_o, rtol=1e-8, atol=1e-8, err_msg=name)
            np.testing.assert_allclose(sol.mu, ref.mu, rtol=1e-8, atol=1e-6, err_msg=name)
        if entry.compiled:  # its numpy reference (what decides the compiled path's doubts)
            sol = entry.function(blocks, compiled=False)
            np.testing.assert_allclose(sol.a_o, ref.a_o, rtol=1e-8, atol=1e-8, err_msg=name)
    assert {n for n, e in SOLVERS.items() if e.accepts_singular_arms} == {"singular"}
    assert solve_auto(blocks).solver == "object_first"  # regular arms: no switch
    with pytest.raises(InputError, match=r"unknown solver 'dense_kt'; known solvers: .*dense_kkt.*"
                                         r"did you mean 'dense_kkt'"):
        solve(blocks, "dense_kt")


# ----------------------------------------------------------------------------- controllers
def test_scenario_controllers_and_their_keys_are_the_registry():
    err = _rejected(_data(**{"controller": {"type": "pid"}}))
    assert err.key == "controller.type"
    assert _listed(err, "expected one of ") == set(CONTROLLERS)
    for name, entry in CONTROLLERS.items():
        err = _rejected(_data(**{"controller": {"type": name, "gain": 1.0}}))
        assert _listed(err, "expected keys: ") == {"type", *entry.parameters}
        assert ("waypoints" in entry.parameters) == entry.follows_trajectory


@pytest.mark.parametrize("name", sorted(CONTROLLERS))
def test_every_controller_steps(two_arms, name):
    system, state = two_arms
    ctrl = make_controller(name, system)
    assert isinstance(ctrl, CONTROLLERS[name].cls)
    tau = ctrl(0.0, state, system.blocks(state))
    assert tau.shape == (system.nv,) and np.all(np.isfinite(tau))
    res = simulate(system, state, make_controller(name, system), 0.02, 0.01)
    assert np.all(np.isfinite(res.q)) and len(res.t) == 3
    with pytest.raises(InputError, match=rf"controller '{name}': bad parameters \['gain'\]; "
                                         "accepted: "):
        make_controller(name, system, gain=1.0)


def test_object_pd_waypoints_through_make_controller(two_arms):
    """``waypoints`` (README) give the trajectory the scenario reader builds from them: the
    pose of the first call prepended at t = 0 when the first waypoint is later."""
    system, state = two_arms
    o = state.obj
    goal = o.position + [0.0, 0.05, 0.1]
    waypoints = [{"t": 0.5, "position": goal.tolist(), "rpy": [0.0, 0.0, 0.2]}]
    ctrl = make_controller("object_pd", system, waypoints=waypoints)
    q_goal = pin.Quaternion(pin.rpy.rpyToMatrix(0.0, 0.0, 0.2)).coeffs()
    same = make_controller("object_pd", system, trajectory={
        "times": [0.0, 0.5], "positions": [o.position, goal], "quaternions": [o.quaternion,
                                                                              q_goal]})
    hold = make_controller("object_pd", system)
    a = ctrl.desired_acceleration(0.2, state)
    np.testing.assert_allclose(a, same.desired_acceleration(0.2, state), rtol=1e-12, atol=1e-12)
    assert np.linalg.norm(a - hold.desired_acceleration(0.2, state)) > 0.1  # it moves
    ev = system.blocks(state)
    np.testing.assert_allclose(ctrl(0.2, state, ev), same(0.2, state, ev), rtol=1e-9, atol=1e-9)
    # the scenario reader's trajectory of the same waypoints (object pose = the start)
    data = _data(**{"object.pose": {"position": o.position.tolist(),
                                    "quaternion": o.quaternion.tolist()},
                    "controller": {"type": "object_pd", "waypoints": waypoints}})
    traj = MinimumJerkTrajectory(**parse_scenario(data, "r.yaml").controller.params["trajectory"])
    for t in (0.1, 0.3, 0.6):
        np.testing.assert_allclose(traj(t).acceleration, ctrl.trajectory(t).acceleration,
                                   atol=1e-12)
    at_zero = make_controller("object_pd", system, waypoints=[dict(waypoints[0], t=0.0)])
    assert at_zero.trajectory is not None and len(at_zero.trajectory.times) == 1
    with pytest.raises(InputError, match="either waypoints or trajectory"):
        ObjectPD(system, trajectory=same.trajectory, waypoints=waypoints)
    with pytest.raises(InputError, match="waypoint 0: expected a mapping with t, position"):
        make_controller("object_pd", system, waypoints=[{"time": 1.0, "position": goal}])


def test_every_controller_kernel_is_one_the_loops_know():
    for entry in CONTROLLERS.values():
        assert entry.kernel is None or entry.kernel in CONTROLLER_KERNELS, entry.name
    assert set(ContactLoop.CONTROLLER_KERNELS) == set(CONTROLLER_KERNELS)


def test_the_loops_read_the_controller_registry(two_arms, monkeypatch):
    """Which kernel serves a controller is its registry entry's: with the entry of
    ``object_pd`` saying none, the loop takes no ``ObjectPD`` run, and the reason names it."""
    system, _ = two_arms
    pd = make_controller("object_pd", system)
    assert controller_kernel(None) == ("zero_torque", "")
    assert controller_kernel(make_controller("none", system)) == ("zero_torque", "")
    assert controller_kernel(pd) == ("object_pd", "")
    assert controller_kernel(make_controller("joint_pd", system)) == (
        None, "controller 'joint_pd' has no compiled kernel")
    assert controller_kernel(ObjectPD(system, compiled=False)) == (
        None, "controller 'object_pd' was built with compiled=False")

    class Mine(ObjectPD):  # a subclass may compute something else: not its parent's kernel
        pass

    assert controller_kernel(Mine(system))[0] is None
    assert "Mine is not a type of the registry" in controller_kernel(Mine(system))[1]
    stepper = Stepper(system, pd, "object_first", None)
    assert ContactLoop.declines(stepper, "rk4") is None
    monkeypatch.setitem(CONTROLLERS, "object_pd",
                        dataclasses.replace(CONTROLLERS["object_pd"], kernel=None))
    assert ContactLoop.for_run(stepper, "rk4") is None
    assert ContactLoop.declines(stepper, "rk4") == "controller 'object_pd' has no compiled kernel"


def test_a_run_no_kernel_serves_says_so_once_and_runs_on_the_stepper(two_arms, monkeypatch):
    system, state = two_arms
    kernel_calls = []
    run = ContactLoop.run
    monkeypatch.setattr(ContactLoop, "run",
                        lambda self, *a: kernel_calls.append(a[3]) or run(self, *a))

    def notes(r):
        return [w for w in r.warnings if "reference (numpy) stepper" in w]

    r = simulate(system, state, make_controller("joint_pd", system), 0.02, 0.01)
    assert notes(r) == [REFERENCE_NOTE.format(why="controller 'joint_pd' has no compiled "
                                                  "kernel")] and not kernel_calls
    r = simulate(system, state, make_controller("object_pd", system), 0.02, 0.01,
                 integrator="rk45")
    assert notes(r) == [REFERENCE_NOTE.format(why="integrator 'rk45' has no compiled loop (RK4 "
                                                  "and semi-implicit Euler only)")]
    assert not kernel_calls
    for integrator in ("semi_implicit", "rk4"):
        r = simulate(system, state, make_controller("object_pd", system), 0.02, 0.01,
                     integrator=integrator)
        assert notes(r) == [] and kernel_calls  # the compiled loop took it
        kernel_calls.clear()


def test_the_note_names_a_joint_kind_the_compiled_pass_lacks():
    model = pin.Model()
    j = model.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), "shoulder")
    model.addJoint(j, pin.JointModelSpherical(), pin.SE3.Identity(), "wrist")
    system = types.SimpleNamespace(arm_set=types.SimpleNamespace(model=model))
    assert unsupported_joints_note(system) == (
        "joint 'wrist' is of kind JointModelSpherical, which the compiled rigid-body pass does "
        "not support")


# ----------------------------------------------------------------------------- integrators
def test_scenario_integrators_are_the_registry():
    err = _rejected(_data(**{"simulation.integrator": "euler"}))
    assert err.key == "simulation.integrator"
    assert _listed(err, "expected one of ") == set(INTEGRATORS)
    for name in INTEGRATORS:
        sc = parse_scenario(_data(**{"simulation.integrator": name}), "r.yaml")
        assert sc.simulation.integrator == name


def test_every_integrator_integrates_with_its_registered_order(two_arms):
    """Fixed-step schemes: the error at T = 0.2 s against rk4 at dt = T/256 falls by 2^order
    when dt halves (measured: rk4 15.9, semi_implicit 2.00); rk45 meets its tolerances."""
    system, state = two_arms
    T = 0.2

    def final(name, dt, **kw):
        r = simulate(system, state, None, T, dt, integrator=name, **kw)
        return np.concatenate([r.q[-1], r.object_position[-1]])

    ref = final("rk4", T / 256)
    for name, entry in INTEGRATORS.items():
        if entry.adaptive:
            assert np.linalg.norm(final(name, T / 16, rtol=1e-9, atol=1e-11) - ref) < 1e-8
            continue
        e1, e2 = (np.linalg.norm(final(name, T / n) - ref) for n in (16, 32))
        assert abs(np.log2(e1 / e2) - entry.order) < 0.3, (name, e1, e2)
    with pytest.raises(InputError, match=r"unknown integrator 'rk5'; known integrators: "
                                         r"rk4, rk45, semi_implicit; did you mean"):
        simulate(system, state, None, T, 0.01, integrator="rk5")
