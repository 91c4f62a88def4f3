"""Inverse kinematics: checked by forward kinematics (an independent computation)."""

import numpy as np
import pinocchio as pin
import pytest

from multiarm_pin.exceptions import FrameNotFoundError, InputError, MultiArmError
from multiarm_pin.model.arm import Arm
from multiarm_pin.model.ik import (
    PlaneTarget,
    PointTarget,
    PoseTarget,
    UnreachableError,
    ik_frame_points,
    ik_tool_placement,
    solve_ik,
)

MP6 = "robots/mp6/mp6.urdf"
TIPS = ["fingertip_1", "fingertip_2", "fingertip_3"]


@pytest.fixture(scope="module")
def ur5():
    return Arm.from_robot_name("ur5", load_visuals=False,
                               base_placement=pin.SE3(pin.rpy.rpyToMatrix(0, 0, 0.4),
                                                      np.array([0.1, 0.5, 0.0])))


@pytest.fixture(scope="module")
def mp6():
    return Arm.from_urdf(MP6, "tool0", load_visuals=False)


def test_tool_placement_reached_from_nearby_seed(ur5):
    rng = np.random.default_rng(0)
    for _ in range(5):
        q_true = rng.uniform(-2.0, 2.0, 6)
        target = ur5.tool_placement(q_true)
        res = ik_tool_placement(ur5, target, q_true + rng.uniform(-0.3, 0.3, 6))
        reached = ur5.tool_placement(res.q)
        assert np.allclose(reached.translation, target.translation, atol=1e-9)
        assert np.allclose(reached.rotation, target.rotation, atol=1e-9)
        assert res.residual < 1e-9


def test_several_fingertips_at_points(mp6):
    rng = np.random.default_rng(1)
    q_true = rng.uniform(-1.0, 1.0, 6)
    pts = np.array([mp6.frame_placement(q_true, f).translation for f in TIPS])
    res = ik_frame_points(mp6, TIPS, pts, q_true + 0.2)
    got = np.array([mp6.frame_placement(res.q, f).translation for f in TIPS])
    assert np.abs(got - pts).max() < 1e-9
    # three points of a rigid gripper fix its placement: the tool lands where it was
    assert np.allclose(mp6.tool_placement(res.q).translation,
                       mp6.tool_placement(q_true).translation, atol=1e-8)


def test_joint_limits_respected(mp6):
    # a target needing joints beyond their limits from the seed: result stays inside
    lo, hi = mp6.model.lowerPositionLimit, mp6.model.upperPositionLimit
    q_true = np.array([0.3, 1.9, 2.5, 0.0, 2.0, 0.0])  # near upper limits
    target = mp6.tool_placement(q_true)
    res = ik_tool_placement(mp6, target, q_true - 0.1)
    assert np.all(res.q >= lo - 1e-12) and np.all(res.q <= hi + 1e-12)
    assert np.allclose(mp6.tool_placement(res.q).translation, target.translation, atol=1e-9)


def test_plane_primary_point_secondary(mp6):
    # fingertip 1 on the plane z = 0.5 exactly, as near as possible to a point off the plane
    q0 = np.array([0.0, 0.5, 1.0, 0.0, 0.5, 0.0])
    targets = [PlaneTarget("fingertip_1", [0, 0, 1], 0.5),
               PointTarget("fingertip_1", [0.6, 0.1, 0.6], primary=False)]
    res = solve_ik(mp6.model, targets, q0)
    p = mp6.frame_placement(res.q, "fingertip_1").translation
    assert abs(p[2] - 0.5) < 1e-9
    # the best reachable point on the plane is the projection of the preferred point
    assert np.allclose(p[:2], [0.6, 0.1], atol=1e-4)
    assert res.secondary_residual == pytest.approx(0.1, abs=1e-4)


def test_out_of_reach_reports_residual(ur5):
    far = pin.SE3(np.eye(3), np.array([3.1, 0.5, 0.3]))
    with pytest.raises(UnreachableError) as info:
        ik_tool_placement(ur5, far, np.zeros(6), restarts=2)
    err = info.value
    assert isinstance(err, MultiArmError)
    # the UR5 reaches about 0.95 m from its shoulder: at least ~2 m must be left
    assert 1.5 < err.residual < 3.5
    assert "out of reach" in str(err) and "position error" in str(err)
    assert err.q.shape == (6,)


def test_bad_inputs(ur5):
    with pytest.raises(FrameNotFoundError):
        solve_ik(ur5.model, [PointTarget("no_such_frame", np.zeros(3))])
    with pytest.raises(InputError, match="q_seed"):
        ik_tool_placement(ur5, pin.SE3.Identity(), np.zeros(5))
    with pytest.raises(InputError, match="no IK targets"):
        solve_ik(ur5.model, [])
    with pytest.raises(InputError, match="plane normal"):
        solve_ik(ur5.model, [PlaneTarget("tool0", np.zeros(3), 0.0)])
    with pytest.raises(InputError, match="PoseTarget"):
        solve_ik(ur5.model, ["tool0"])
    with pytest.raises(InputError, match="point"):
        solve_ik(ur5.model, [PointTarget("tool0", [1.0, 2.0])])
    assert PoseTarget("tool0", pin.SE3.Identity()).primary


# ----------------------------------------------------------------------------- issue 13
# IK targets only what the joint constrains, near the seed, symmetric for symmetric seeds.
def _fd_jacobian(problem, q, eps=1e-7):
    e0 = problem.evaluate(q, True, 0.0)[0]
    J = np.zeros((len(e0), problem.model.nv))
    for k in range(problem.model.nv):
        dq = np.zeros(problem.model.nv)
        dq[k] = eps
        J[:, k] = (problem.evaluate(pin.integrate(problem.model, q, dq), True, 0.0)[0] - e0) / eps
    return J


def test_offset_point_plane_and_axis_jacobians_match_finite_differences(ur5):
    from multiarm_pin.model.ik import AxisTarget, _Problem

    tool = ur5.model.frames[ur5.tool_frame_id].name
    off = np.array([0.05, -0.02, 0.1])
    targets = [PointTarget(tool, [0.4, 0.2, 0.3], offset=off),
               PlaneTarget(tool, [0.2, -0.5, 0.8], 0.3, point=off),
               AxisTarget(tool, [0.0, 0.6, 0.8], [1.0, 0.0, 0.0])]
    problem = _Problem(ur5.model, targets)
    q = np.array([0.3, -1.1, 1.4, -0.5, 1.2, 0.4])
    e, J = problem.evaluate(q, True, 0.0)[:2]
    np.testing.assert_allclose(J, _fd_jacobian(problem, q), atol=2e-6)
    # the residuals themselves, from forward kinematics (an independent computation)
    M = ur5.tool_placement(q)
    p = M.translation + M.rotation @ off
    np.testing.assert_allclose(e[:3], p - [0.4, 0.2, 0.3], atol=1e-12)
    n = np.array([0.2, -0.5, 0.8])
    assert e[3] == pytest.approx((n @ p - 0.3) / np.linalg.norm(n), abs=1e-12)
    np.testing.assert_allclose(e[4:], M.rotation @ [0.0, 0.6, 0.8] - [1, 0, 0], atol=1e-12)


def test_revolute_and_spherical_targets_leave_the_free_rotation_at_the_seed(ur5):
    from multiarm_pin.model.ik import AxisTarget, PostureTarget

    tool = ur5.model.frames[ur5.tool_frame_id].name
    q_seed = np.array([0.2, -1.0, 1.3, -0.6, 1.1, 0.3])
    M = ur5.tool_placement(q_seed)
    # the joint frame turned by 1 rad about its z axis: a revolute joint is already met at
    # the seed, a weld (full pose) is not
    J_o = M * pin.SE3(pin.exp3(np.array([0.0, 0.0, 1.0])), np.zeros(3))
    rev = solve_ik(ur5.model, [PointTarget(tool, J_o.translation),
                               AxisTarget(tool, [0, 0, 1], J_o.rotation[:, 2]),
                               PostureTarget(q_seed)], q_seed)
    np.testing.assert_allclose(rev.q, q_seed, atol=1e-9)
    weld = ik_tool_placement(ur5, J_o, q_seed)
    assert np.linalg.norm(weld.q - q_seed) > 0.5  # the weld had to turn the wrist
    # spherical: any orientation; from a seed 5 cm away the point is met near the seed
    sph = solve_ik(ur5.model, [PointTarget(tool, M.translation + [0.05, 0, 0]),
                               PostureTarget(q_seed)], q_seed)
    assert np.linalg.norm(ur5.tool_placement(sph.q).translation - M.translation
                          - [0.05, 0, 0]) < 1e-10
    assert np.linalg.norm(sph.q - q_seed) < 0.2


def test_three_joint_arm_reaches_a_point_but_not_a_pose():
    # the case: a 3-joint arm (UR5, wrist locked) for a spherical joint
    arm = Arm.from_robot_name("ur5", locked_joints=("wrist_1_joint", "wrist_2_joint",
                                                    "wrist_3_joint"), load_visuals=False)
    assert arm.nv == 3
    tool = arm.model.frames[arm.tool_frame_id].name
    target = arm.tool_placement(np.array([0.5, -1.0, 1.2]))
    other = pin.SE3(pin.exp3(np.array([0.4, 0.0, 0.0])) @ target.rotation, target.translation)
    seed = np.array([0.3, -0.8, 1.0])
    res = solve_ik(arm.model, [PointTarget(tool, other.translation)], seed)
    assert np.linalg.norm(arm.tool_placement(res.q).translation - other.translation) < 1e-10
    with pytest.raises(UnreachableError):  # the full pose is over-determined for 3 joints
        solve_ik(arm.model, [PoseTarget(tool, other)], seed, restarts=0)


def test_revolute_coordinates_turned_to_the_seed_within_limits(ur5):
    from multiarm_pin.model.ik import _nearest_turn, _Problem

    problem = _Problem(ur5.model, [PointTarget("tool0", np.zeros(3))])
    assert problem.revolute == list(range(6))
    q = np.array([0.1, -1.2, 1.5, -0.4, 1.3, -0.3])
    ref = np.array([0.1, -1.2, 1.5 - 2 * np.pi, -0.4, 1.3, 5.9])
    out = _nearest_turn(problem, q, ref)
    # wrist 3 (limits ±2π) turns by +2π towards the reference; the elbow (limits ±π) cannot
    np.testing.assert_allclose(out, q + [0, 0, 0, 0, 0, 2 * np.pi], atol=1e-15)
    np.testing.assert_allclose(ur5.tool_placement(out).homogeneous,
                               ur5.tool_placement(q).homogeneous, atol=1e-12)
    assert np.all(out <= ur5.model.upperPositionLimit) and np.all(
        out >= ur5.model.lowerPositionLimit)


def _sorted_rows(P):
    return P[np.lexsort(np.round(P, 9).T)]


def _frame_points(arm, q):
    """(F, 3) positions of every frame of the arm [m]."""
    return np.array([arm.frame_placement(q, f.name).translation for f in arm.model.frames])


def _mirror_signs(arm_left, arm_right, S):
    """Joint signs s with {frames of right at s q} = mirror({frames of left at q}).

    Found by trying every sign pattern on random configurations, with forward kinematics
    of every frame (fingertips included, so the last joint's sign is fixed too).
    """
    import itertools

    rng = np.random.default_rng(3)
    qs = rng.uniform(-1.0, 1.0, (3, arm_left.nq))
    for s in itertools.product([1.0, -1.0], repeat=arm_left.nq):
        s = np.array(s)
        if all(np.allclose(_sorted_rows(_frame_points(arm_right, s * q)),
                           _sorted_rows(_frame_points(arm_left, q) @ S), atol=1e-9)
               for q in qs):
            return s
    return None


def test_mirror_symmetric_pair_gets_mirror_symmetric_branches():
    from multiarm_pin.app.scenario import build_scenario, load_scenario

    built = build_scenario(load_scenario("scenarios/mp6_pair_box.yaml"))
    left, right = built.arms
    S = np.diag([1.0, -1.0, 1.0])  # the pair is mirrored in the plane y = 0
    s = _mirror_signs(left, right, S)
    assert s is not None, "mp6 is mirror symmetric: a joint sign pattern must exist"
    seeds = [a.q_seed for a in built.scenario.arms]
    np.testing.assert_allclose(seeds[1], s * seeds[0])  # the seeds are mirrored
    np.testing.assert_allclose(built.q0[1], s * built.q0[0], atol=1e-8)
    assert all(ik.residual < 1e-10 for ik in built.ik)
