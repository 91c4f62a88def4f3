"""Controllers: registry, formulas, object-level control realised exactly by the forward
dynamics, impossible grasps, object trajectory tracking."""

import numpy as np
import pinocchio as pin
import pytest
from system_builders import build_system, moving_state

from multiarm_pin.exceptions import DynamicsError, InputError
from multiarm_pin.sim.controllers import CONTROLLERS, make_controller
from multiarm_pin.sim.simulation import simulate
from multiarm_pin.sim.trajectories import MinimumJerkTrajectory


@pytest.fixture(scope="module")
def two_arms():
    rng = np.random.default_rng(11)
    system, state = build_system(["ur5", "panda"], ["weld", "revolute"], rng,
                                 gravity=(0.2, 0.0, -9.81))
    return system, moving_state(system, state, rng, 0.5)


def test_registry_errors(two_arms):
    system, _ = two_arms
    assert set(CONTROLLERS) == {"none", "gravity_compensation", "joint_pd", "object_pd",
                                "phased_pd"}
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


# ---------------------------------------------------------------- holding the tools on the object
def _rotation_path(t, w0, w1):
    """A smooth rotation exp(w0 t + w1 t²) R0 (no closed-form angular velocity needed)."""
    R0 = pin.exp3(np.array([0.3, -0.2, 0.5]))
    return pin.exp3(w0 * t + w1 * t * t) @ R0


def _angular_velocity(R_of_t, t, h=1e-5):
    """World angular velocity vee(Ṙ Rᵀ) by a central difference (error ~h²)."""
    return pin.log3(R_of_t(t + h) @ R_of_t(t - h).T) / (2 * h)


def test_tool_acceleration_from_object_matches_finite_differences():
    """Eq 3.6 (transport of the object's acceleration plus relative motion, with the
    ω×(ω×r), 2ω×ṗ_rel and ω×ω_rel terms) against second differences of a composed motion
    x_t = x_o + R_o p_rel(t), R_t = R_o R_rel(t)."""
    from multiarm_pin.sim.controllers import tool_acceleration_from_object

    rng = np.random.default_rng(5)
    c = rng.normal(size=(9, 3))

    def x_o(t):
        return c[0] + c[1] * t + c[2] * t * t + c[3] * np.sin(2 * t)

    def R_o(t):
        return _rotation_path(t, c[4], c[5])

    def p_rel(t):  # tool position in the object frame
        return np.array([0.4, -0.1, 0.2]) + 0.3 * c[6] * t + 0.5 * c[7] * t * t

    def R_rel(t):  # tool orientation in the object frame
        return pin.exp3(0.7 * c[8] * t * t + 0.2 * c[6] * t)

    def x_t(t):
        return x_o(t) + R_o(t) @ p_rel(t)

    def R_t(t):
        return R_o(t) @ R_rel(t)

    t, h, H = 0.37, 1e-5, 1e-3
    R = R_o(t)
    v_o = np.concatenate([(x_o(t + h) - x_o(t - h)) / (2 * h), _angular_velocity(R_o, t)])
    a_o = np.concatenate([(x_o(t + H) - 2 * x_o(t) + x_o(t - H)) / H**2,
                          (_angular_velocity(R_o, t + H) - _angular_velocity(R_o, t - H))
                          / (2 * H)])
    # relative motion: rates of the object-frame coordinates, rotated to world axes
    dp = (p_rel(t + h) - p_rel(t - h)) / (2 * h)
    ddp = (p_rel(t + H) - 2 * p_rel(t) + p_rel(t - H)) / H**2

    def w_rel_obj(s):  # angular velocity of R_rel in object axes
        return _angular_velocity(R_rel, s)

    rel_v = np.concatenate([R @ dp, R @ w_rel_obj(t)])
    rel_a = np.concatenate([R @ ddp, R @ (w_rel_obj(t + H) - w_rel_obj(t - H)) / (2 * H)])
    r = x_t(t) - x_o(t)
    got = tool_acceleration_from_object(r[None], v_o, a_o, rel_v[None], rel_a[None])[0]
    expected = np.concatenate([(x_t(t + H) - 2 * x_t(t) + x_t(t - H)) / H**2,
                               (_angular_velocity(R_t, t + H) - _angular_velocity(R_t, t - H))
                               / (2 * H)])
    assert np.abs(expected).min() > 0.05  # every component exercised
    np.testing.assert_allclose(got, expected, atol=2e-5 * np.abs(expected).max())
    # the relative velocity also checks out: ṗ_t - ẋ_o - ω_o × r and ω_t - ω_o
    v_t = np.concatenate([(x_t(t + h) - x_t(t - h)) / (2 * h), _angular_velocity(R_t, t)])
    np.testing.assert_allclose(v_t - v_o - np.concatenate([np.cross(v_o[3:], r), np.zeros(3)]),
                               rel_v, atol=1e-8)
    # rigid attachment: the object-fixed frame's acceleration (defaults: no relative motion)
    rigid = tool_acceleration_from_object(r[None], v_o, a_o)[0]
    w = v_o[3:]
    np.testing.assert_allclose(rigid[:3], a_o[:3] + np.cross(a_o[3:], r)
                               + np.cross(w, np.cross(w, r)), atol=1e-12)
    np.testing.assert_allclose(rigid[3:], a_o[3:])


def test_tool_acceleration_from_object_rejects_bad_shapes():
    from multiarm_pin.sim.controllers import tool_acceleration_from_object

    with pytest.raises(InputError, match="offset"):
        tool_acceleration_from_object(np.zeros(3), np.zeros(6), np.zeros(6))
    with pytest.raises(InputError, match="object_acceleration"):
        tool_acceleration_from_object(np.zeros((2, 3)), np.zeros(6), np.zeros(5))
    with pytest.raises(InputError, match=r"relative_twist \(2, 6\)"):
        tool_acceleration_from_object(np.zeros((2, 3)), np.zeros(6), np.zeros(6), np.zeros((1, 6)))


@pytest.mark.parametrize("name", ["hold_kp", "hold_kd", "null_kp"])
def test_object_pd_rejects_negative_hold_gains(two_arms, name):
    system, _ = two_arms
    with pytest.raises(InputError, match=f"object_pd {name}"):
        make_controller("object_pd", system, **{name: -1.0})


def _rigidly_moving_state(system, state, rng):
    """Object with a random twist, every tool moving with it (no relative motion)."""
    o = state.obj
    tw = rng.normal(size=6)
    tools = system.arm_set.tool_kinematics(state.q)
    J = system.blocks(state).arms.J
    v = np.zeros((system.n_arms, J.shape[2]))
    for i in range(system.n_arms):
        r = tools.position[i] - o.position
        tool_twist = np.concatenate([tw[:3] + np.cross(tw[3:], r), tw[3:]])
        v[i] = np.linalg.lstsq(J[i], tool_twist, rcond=None)[0]
    moving = system.state(state.q, system.unpad(v), o.position, o.quaternion, tw)
    np.testing.assert_allclose(system.project_velocities(moving).v, moving.v, atol=1e-9)
    return moving


def test_object_pd_moves_the_held_points_with_the_object():
    """Tools moving rigidly with the object, fingertip and revolute grasps (which leave the
    tool free to slide or turn): the forward dynamics under the controller's torques gives
    every held tip centre the acceleration of the object's material point there (from
    Pinocchio's frame acceleration of the realised q̈, independent of the controller), so
    nothing slides."""
    rng = np.random.default_rng(3)
    system, state = build_system(["ur5", "panda"], ["fingertips", "revolute"], rng)
    state = _rigidly_moving_state(system, state, rng)
    o = state.obj
    target = MinimumJerkTrajectory.hold(o.position + [0.02, -0.01, 0.03], o.quaternion)
    ctrl = make_controller("object_pd", system, trajectory=target, margin=1.0)
    tau = ctrl(0.0, state, system.blocks(state))
    sol, _ = system.forward_dynamics(state, tau)
    a_d = ctrl.desired_acceleration(0.0, state)
    np.testing.assert_allclose(sol.a_o, a_d, atol=1e-8)
    model = system.arm_set.model
    data = model.createData()
    pin.forwardKinematics(model, data, state.q, state.v, system.unpad(sol.qdd))
    pin.updateFramePlacements(model, data)
    LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    w = o.twist[3:]
    for i, fid in enumerate(system.arm_set.tool_frame_ids):
        joint = system.joints[i]
        assert ctrl.hold_mask[i].sum() == len(joint.contacts) >= 3
        oMt = data.oMf[int(fid)]
        acc = pin.getFrameClassicalAcceleration(model, data, int(fid), LWA).vector
        wt = pin.getFrameVelocity(model, data, int(fid), LWA).angular
        for k, c in enumerate(joint.contacts):
            centre = (oMt.act(c.point) if c.point_on == "tool"
                      else o.position + o.rotation @ c.point)
            np.testing.assert_allclose(ctrl.hold_points_in_object[i, k],
                                       (centre - o.position) @ o.rotation, atol=1e-12)
            d = centre - oMt.translation
            got = acc[:3] + np.cross(acc[3:], d) + np.cross(wt, np.cross(wt, d))
            r = centre - o.position
            rigid = a_d[:3] + np.cross(a_d[3:], r) + np.cross(w, np.cross(w, r))
            np.testing.assert_allclose(got, rigid, atol=1e-6 * np.abs(rigid).max())
            np.testing.assert_allclose(ctrl.last_point_acceleration[i, k], rigid, atol=1e-9)


def test_object_pd_null_gains_move_only_a_redundant_arms_self_motion():
    """A Panda (7 joints) welded to the object: the weld fixes J q̈, and q̈'s part in the
    null space of J is the joint PD's (null_kp (q_ref ⊖ q) - null_kd v) projected there."""
    rng = np.random.default_rng(8)
    system, state = build_system(["panda"], ["weld"], rng)
    state = moving_state(system, state, rng, 0.5)
    ctrl = make_controller("object_pd", system, null_kp=30.0, null_kd=7.0)
    ctrl(0.0, state, system.blocks(state))  # fixes q_ref and the held placements
    q1 = pin.integrate(system.arm_set.model, state.q, 0.05 * rng.normal(size=system.nv))
    moved = system.state(q1, state.v, state.obj.position, state.obj.quaternion,
                         state.obj.twist)
    ev = system.blocks(moved)
    tau = ctrl(0.1, moved, ev)
    sol, _ = system.forward_dynamics(moved, tau)
    J = ev.arms.J[0]
    P = np.eye(7) - np.linalg.pinv(J) @ J  # the self-motion projector
    assert np.linalg.matrix_rank(P, 1e-8) == 1
    z = 30.0 * pin.difference(system.arm_set.model, q1, state.q) - 7.0 * moved.v
    assert np.linalg.norm(P @ z) > 0.1
    np.testing.assert_allclose(P @ system.unpad(sol.qdd), P @ z, atol=1e-6)
    # without the null gains there is no self-motion acceleration from them
    still = make_controller("object_pd", system, null_kp=0.0, null_kd=0.0)
    still(0.0, state, system.blocks(state))
    sol0, _ = system.forward_dynamics(moved, still(0.1, moved, ev))
    np.testing.assert_allclose(P @ system.unpad(sol0.qdd), 0.0, atol=1e-6)


@pytest.mark.parametrize("scenario, slid_before", [("two_gripper_form_closure", 23.7),
                                                   ("fingertips_form_closure", 70.3)])
def test_fingertips_stay_put_on_the_moving_box(scenario, slid_before):
    """Form-closure scenarios over their whole motion (lift 5 cm, then shift and turn
    0.1 rad; dt coarsened to 4 ms): every frictionless fingertip stays where it touched the
    box (object frame), so the grasp keeps its form-closure margin. Holding joint angles
    instead let tips slide ``slid_before`` mm (two grippers: margin 0.048 -> 0.0086). In
    fingertips_form_closure one arm holds a single tip: holding its whole tool pose would
    drag it into a singularity, holding the tip leaves its other motions free."""
    from pathlib import Path

    from multiarm_pin.app.runner import scenario_controller
    from multiarm_pin.app.scenario import build_scenario, load_scenario
    from multiarm_pin.grasp import form_closure, wrench_matrix
    from multiarm_pin.spatial import quaternion_to_rotation

    path = Path(__file__).resolve().parents[1] / "scenarios" / f"{scenario}.yaml"
    built = build_scenario(load_scenario(path))
    sim = built.scenario.simulation
    ctrl = scenario_controller(built)
    r = simulate(built.system, built.initial_state, ctrl, sim.duration, 0.004, sim.integrator,
                 sim.solver, sim.baumgarte)
    mask = built.system.constraint_set.mask
    assert mask.sum() == 7
    R = np.array([quaternion_to_rotation(q) for q in r.object_quaternion])
    points = np.einsum("tkj,tji->tki", r.contact_points[:, mask] - r.object_position[:, None], R)
    normals = np.einsum("tkj,tji->tki", r.normals[:, mask], R)
    # real motion: the box rises 5 cm, shifts 5 cm and turns 0.1 rad
    assert np.ptp(r.object_position[:, 2]) > 0.049 and np.ptp(r.object_position[:, 0]) > 0.049
    assert np.linalg.norm(pin.log3(R[-1] @ R[0].T)) > 0.099
    slide = np.linalg.norm(points - points[0], axis=2).max()
    assert slide < 1e-4, f"a fingertip slid {slide * 1e3:.3g} mm on its face (limit 0.1 mm)"
    margin0 = form_closure(wrench_matrix(points[0], normals[0])).margin
    assert margin0 > 0.04
    for k in range(0, len(r.t), 50):
        res = form_closure(wrench_matrix(points[k], normals[k]))
        assert res.form_closure and res.margin >= 0.8 * margin0, (r.t[k], res.margin)
    push = built.scenario.controller.params["margin"]
    assert r.mu[:, mask].min() >= push - 1e-6
    traj = ctrl.trajectory
    ref = np.array([traj(t).position for t in r.t])
    assert np.abs(r.object_position - ref).max() < 1e-6
    turn = [np.linalg.norm(pin.log3(traj(t).rotation @ R[k].T)) for k, t in enumerate(r.t)]
    assert max(turn) < 1e-6
    assert np.abs(r.phi[:, mask]).max() < 1e-6
