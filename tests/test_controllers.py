"""Controllers: registry, formulas, force distribution optimality, inverse dynamics round trip
through the forward dynamics, object trajectory tracking."""

import numpy as np
import pinocchio as pin
import pytest
from test_system import build_system, moving_state

from multiarm_pin.controllers import (
    CONTROLLERS,
    distribute_forces,
    inverse_dynamics,
    make_controller,
)
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


def test_force_distribution_is_the_constrained_least_norm(rng):
    W = rng.normal(size=(6, 9))
    uni = np.array([True] * 6 + [False] * 3)
    w = W @ np.concatenate([rng.uniform(1, 5, 6), rng.normal(size=3)])  # feasible
    margin = 0.5
    assert (np.linalg.pinv(W) @ w)[uni].min() < margin  # the bounds are active
    fd = distribute_forces(W, w, uni, margin)
    mu = fd.mu
    assert fd.residual < 1e-9 and mu[uni].min() >= margin - 1e-9
    # KKT: 2 mu = Wᵀ y + λ with λ >= 0 supported on the active bounds
    active = uni & (mu < margin + 1e-7)
    A = np.hstack([W.T, np.eye(9)[:, active]])
    sol, *_ = np.linalg.lstsq(A, 2 * mu, rcond=None)
    assert np.linalg.norm(A @ sol - 2 * mu) < 1e-6 * np.linalg.norm(mu)
    assert np.all(sol[6:] >= -1e-6)
    # without unilateral contacts: the least-norm solution
    free = distribute_forces(W, w, np.zeros(9, bool))
    np.testing.assert_allclose(free.mu, np.linalg.pinv(W) @ w, atol=1e-10)


def test_force_distribution_reports_impossible_grasps():
    # three contacts all pushing up cannot pull the object down
    W = np.array([[0, 0, 1, y, -x, 0] for x, y in [(0.1, 0), (-0.1, 0.1), (0, -0.1)]]).T
    with pytest.raises(DynamicsError, match="no contact forces produce the wrench"):
        distribute_forces(np.hstack([W, W]), np.array([0, 0, -10.0, 0, 0, 0]), np.ones(6, bool))


@pytest.mark.parametrize("kinds", [["weld", "spherical", "fingertips"],
                                   ["revolute", "universal"]])
def test_inverse_dynamics_round_trips_through_forward_dynamics(kinds):
    rng = np.random.default_rng(len(kinds))
    robots = ["ur5", "panda", "ur5"][: len(kinds)]
    system, state = build_system(robots, kinds, rng)
    state = moving_state(system, state, rng, 0.5)
    b = system.blocks(state).blocks
    a_d = rng.normal(size=6)
    uni = system.unilateral[b.constraint_mask]
    fd = distribute_forces(b.stacked_W_o(), b.M_o @ a_d - b.h_o, uni, 1.0)
    sec = system.pad(rng.normal(size=system.nv))
    inv = inverse_dynamics(system, b, a_d, b.unflatten_mu(fd.mu), sec)
    sol, _ = system.forward_dynamics(state, inv.tau)
    np.testing.assert_allclose(sol.a_o, a_d, atol=1e-8)
    np.testing.assert_allclose(sol.mu, inv.mu, atol=1e-6)
    np.testing.assert_allclose(sol.qdd, inv.qdd, atol=1e-7)


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
