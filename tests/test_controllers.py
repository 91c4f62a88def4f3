"""Controllers: registry, formulas, object-level control realised exactly by the forward
dynamics, impossible grasps, object trajectory tracking."""

import numpy as np
import pinocchio as pin
import pytest
from test_system import build_system, moving_state

from multiarm_pin.controllers import CONTROLLERS, make_controller
from multiarm_pin.exceptions import DynamicsError, InputError
from multiarm_pin.simulation import simulate
from multiarm_pin.trajectories import MinimumJerkTrajectory


@pytest.fixture(scope="module")
def two_arms():
    rng = np.random.default_rng(11)
    system, state = build_system(["ur5", "panda"], ["weld", "revolute"], rng,
                                 gravity=(0.2, 0.0, -9.81))
    return system, moving_state(system, state, rng, 0.5)


def test_registry_errors(two_arms):
    system, _ = two_arms
    assert set(CONTROLLERS) == {"none", "gravity_compensation", "joint_pd", "object_pd"}
    with pytest.raises(InputError, match="unknown controller type 'pid'.*gravity_compensation"):
        make_controller("pid", system)
    with pytest.raises(InputError, match="bad parameters"):
        make_controller("joint_pd", system, stiffness=3)
    with pytest.raises(InputError, match="kp"):
        make_controller("joint_pd", system, kp=-1.0)
    with pytest.raises(InputError, match="margin"):
        make_controller("object_pd", system, margin=-1.0)
    with pytest.raises(InputError, match="MultiArmSystem"):
        make_controller("none", object())


def test_simple_controllers(two_arms):
    system, state = two_arms
    ev = system.blocks(state)
    assert np.all(make_controller("none", system)(0.0, state, ev) == 0)
    g = make_controller("gravity_compensation", system)(0.0, state, ev)
    # g(q) equals the nonlinear effects at zero velocity (a different Pinocchio algorithm)
    rest = system.state(state.q, None, state.obj.position, state.obj.quaternion)
    np.testing.assert_allclose(g, system.unpad(-system.blocks(rest).blocks.h), atol=1e-10)
    assert np.abs(g).max() > 1.0
    pd = make_controller("joint_pd", system, kp=10.0, kd=2.0)
    np.testing.assert_allclose(pd(0.0, state, ev), g - 2.0 * state.v, atol=1e-12)  # q_ref = q0
    q1 = state.q + 0.1
    moved = system.state(q1, state.v, state.obj.position, state.obj.quaternion)
    np.testing.assert_allclose(pd(0.1, moved, ev),
                               system.gravity_torques(q1) - 1.0 - 2.0 * state.v, atol=1e-12)


@pytest.mark.parametrize("kinds", [["weld", "spherical", "fingertips"],
                                   ["revolute", "universal"]])
def test_object_pd_torques_realise_its_plan_in_the_forward_dynamics(kinds):
    """The controller's torques, fed to the forward dynamics, give its desired object
    acceleration and its planned multipliers (fingertips pushing >= margin)."""
    rng = np.random.default_rng(len(kinds))
    robots = ["ur5", "panda", "ur5"][: len(kinds)]
    system, state = build_system(robots, kinds, rng)
    state = moving_state(system, state, rng, 0.5)
    o = state.obj
    target = MinimumJerkTrajectory.hold(o.position + [0.01, -0.02, 0.03], o.quaternion)
    ctrl = make_controller("object_pd", system, trajectory=target, margin=1.0)
    tau = ctrl(0.0, state, system.blocks(state))
    a_d = ctrl.desired_acceleration(0.0, state)
    assert np.abs(a_d).max() > 0.5
    sol, _ = system.forward_dynamics(state, tau)
    np.testing.assert_allclose(sol.a_o, a_d, atol=1e-8)
    np.testing.assert_allclose(sol.mu, ctrl.last.mu, atol=1e-6)
    np.testing.assert_allclose(sol.qdd, ctrl.last.qdd, atol=1e-7)
    if system.unilateral.any():
        assert sol.mu[system.unilateral].min() >= 1.0 - 1e-6


def test_object_pd_reports_an_impossible_grasp():
    """Two fingertips on the top face cannot hold the box up."""
    specs = [{"type": "fingertips", "contacts": [("+z", [0.1, 0.0, 0.1]),
                                                 ("+z", [-0.1, 0.05, 0.1])], "radius": 0.01}]
    system, state = build_system(["ur5"], specs, None)
    ctrl = make_controller("object_pd", system)
    with pytest.raises(DynamicsError):
        ctrl(0.0, state, system.blocks(state))


def test_object_pd_tracks_a_minimum_jerk_trajectory(two_arms):
    system, state = two_arms
    state = system.state(state.q, None, state.obj.position, state.obj.quaternion)
    o = state.obj
    turn = pin.Quaternion(pin.exp3(np.array([0.0, 0.0, 0.15])) @ o.rotation).coeffs()
    traj = MinimumJerkTrajectory([0.0, 0.6], [o.position, o.position + [0.03, 0.0, 0.04]],
                                 [o.quaternion, turn])
    ctrl = make_controller("object_pd", system, trajectory=traj)
    r = simulate(system, state, ctrl, 0.8, 0.005, "rk4", baumgarte=(5.0, 5.0))
    ref = np.array([traj(t).position for t in r.t])
    assert np.abs(r.object_position - ref).max() < 1e-5
    assert np.abs(r.object_position[-1] - (o.position + [0.03, 0.0, 0.04])).max() < 1e-5
    R_end = pin.Quaternion(r.object_quaternion[-1]).toRotationMatrix()
    assert np.linalg.norm(pin.log3(R_end.T @ traj(1.0).rotation)) < 1e-5
