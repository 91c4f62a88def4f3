"""Inverse kinematics: checked by forward kinematics (an independent computation)."""

import numpy as np
import pinocchio as pin
import pytest

from multiarm_pin.arm import Arm
from multiarm_pin.exceptions import FrameNotFoundError, InputError, MultiArmError
from multiarm_pin.ik import (
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
