import example_robot_data as erd
import numpy as np
import pinocchio as pin
import pytest

from multiarm_pin.exceptions import (
    FrameNotFoundError,
    InputError,
    MultiArmError,
    RobotNotFoundError,
    SingularityError,
    URDFError,
)
from multiarm_pin.model.arm import (
    Arm,
    available_robots,
    inverse_operational_space_inertia,
    load_arm,
)

UR5_SINGULAR_ELBOW = np.array([0.3, -1.0, 0.0, 0.4, 0.8, 0.2])  # elbow joint straight


def test_lambda_inv_matches_independent_formula(ur5, rng):
    q = rng.uniform(-2, 2, 6)
    t = ur5.terms(q, rng.normal(size=6))
    ref = t.J @ np.linalg.inv(t.M) @ t.J.T
    assert np.allclose(t.Lambda_inv, ref, rtol=1e-10, atol=1e-12)
    assert t.has_operational_space_inertia
    assert np.allclose(t.Lambda @ ref, np.eye(6), atol=1e-8)


def test_lambda_at_singular_configuration(ur5):
    t = ur5.terms(UR5_SINGULAR_ELBOW)
    assert np.linalg.matrix_rank(t.J, tol=1e-9) == 5  # really singular
    assert np.all(np.isfinite(t.Lambda_inv))
    assert np.allclose(t.Lambda_inv, t.J @ np.linalg.solve(t.M, t.J.T), atol=1e-12)
    assert not t.has_operational_space_inertia
    with pytest.raises(SingularityError, match="operational-space inertia does not exist"):
        _ = t.Lambda


def test_lambda_of_redundant_and_deficient_jacobians():
    M = np.diag([1.0, 2.0, 3.0])
    J = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    Li, cond = inverse_operational_space_inertia(M, J)
    assert np.allclose(Li, np.diag([1.0, 0.5]))
    assert cond == pytest.approx(2.0)


def test_jdot_qdot_matches_finite_difference(ur5, panda, rng):
    for arm in (ur5, panda):
        q = rng.uniform(-1.5, 1.5, arm.nq)
        v = rng.normal(size=arm.nv)
        t = arm.terms(q, v)
        errs = []
        for eps in (1e-3, 1e-4):
            jp = arm.terms(pin.integrate(arm.model, q, eps * v), v).J @ v
            jm = arm.terms(pin.integrate(arm.model, q, -eps * v), v).J @ v
            errs.append(np.abs((jp - jm) / (2 * eps) - t.Jdot_qdot).max())
        assert errs[1] < 1e-6 and errs[1] < errs[0]


def test_equations_of_motion_match_rnea(ur5, rng):
    q, v, a = rng.uniform(-2, 2, 6), rng.normal(size=6), rng.normal(size=6)
    t = ur5.terms(q, v)
    tau = pin.rnea(ur5.model, ur5.model.createData(), q, v, a)
    assert np.allclose(t.M @ a + t.nle, tau, atol=1e-10)
    tau_g = pin.rnea(ur5.model, ur5.model.createData(), q, np.zeros(6), np.zeros(6))
    assert np.allclose(t.gravity, tau_g, atol=1e-12)


def test_gravity_direction_respects_base_rotation():
    # an arm mounted upside down feels gravity reversed in its own frame
    up = Arm.from_robot_name("ur5", load_visuals=False)
    down = Arm.from_robot_name(
        "ur5",
        load_visuals=False,
        base_placement=pin.SE3(pin.rpy.rpyToMatrix(np.pi, 0, 0), np.zeros(3)),
    )
    q = np.array([0.0, -1.0, 0.5, 0.0, 0.0, 0.0])
    g_up, g_down = up.terms(q).gravity, down.terms(q).gravity
    assert np.abs(g_up[1]) > 1.0
    assert np.allclose(g_up, -g_down, atol=1e-9)


def test_tool_placement_is_base_times_forward_kinematics(ur5, rng):
    raw = erd.load("ur5").model
    data = raw.createData()
    q = rng.uniform(-2, 2, 6)
    pin.framesForwardKinematics(raw, data, q)
    expected = ur5.base_placement * data.oMf[raw.getFrameId("tool0")]
    got = ur5.terms(q).tool_placement
    assert np.allclose(got.homogeneous, expected.homogeneous, atol=1e-12)


def test_tool_position_known_configuration():
    # UR5 at q = 0 (URDF of example-robot-data): tool0 at x = a2 + a3 = 0.425 + 0.39225,
    # y = shoulder offset - elbow offset + d4 + d6 = 0.13585 - 0.1197 + 0.093 + 0.0823,
    # z = d1 - d5 = 0.089159 - 0.09465 (links stretched along x)
    arm = Arm.from_robot_name(
        "ur5", load_visuals=False, base_placement=pin.SE3(np.eye(3), np.array([1.0, 2.0, 3.0]))
    )
    p = arm.tool_placement(np.zeros(6)).translation
    assert np.allclose(p, [1.0 + 0.81725, 2.0 + 0.19145, 3.0 - 0.005491], atol=1e-6)


def test_tool_offset_and_twist(ur5, rng):
    offset = pin.SE3(pin.rpy.rpyToMatrix(0.3, 0.1, -0.2), np.array([0.0, 0.0, 0.12]))
    arm = Arm.from_robot_name(
        "ur5", load_visuals=False, base_placement=ur5.base_placement, tool_offset=offset
    )
    q, v = rng.uniform(-2, 2, 6), rng.normal(size=6)
    assert np.allclose(
        arm.tool_placement(q).homogeneous, (ur5.tool_placement(q) * offset).homogeneous
    )
    t = arm.terms(q, v)
    eps = 1e-6
    p_plus = arm.tool_placement(q + eps * v).translation
    p_minus = arm.tool_placement(q - eps * v).translation
    assert np.allclose(t.tool_twist[:3], (p_plus - p_minus) / (2 * eps), atol=1e-7)
    assert np.allclose(t.tool_twist, t.J @ v)
    assert np.allclose(t.J_local, np.kron(np.eye(2), t.tool_rotation.T) @ t.J, atol=1e-12)


def test_panda_fingers_are_locked(panda):
    assert panda.nq == 7 and panda.nv == 7
    assert panda.tool_frame == "panda_hand_tcp"


@pytest.mark.parametrize("name", ["ur5", "ur10", "panda"])
def test_required_robots_load(name):
    arm = Arm.from_robot_name(name, load_visuals=False)
    assert arm.nv in (6, 7)
    assert np.all(np.isfinite(arm.terms(arm.neutral()).M))


def test_unknown_robot_lists_available():
    with pytest.raises(RobotNotFoundError) as err:
        Arm.from_robot_name("ur55")
    assert "ur55" in str(err.value) and "ur5" in str(err.value) and "panda" in str(err.value)
    assert err.value.available == available_robots()
    assert isinstance(err.value, MultiArmError)


def test_missing_tool_frame_lists_frames():
    with pytest.raises(FrameNotFoundError) as err:
        Arm.from_robot_name("ur5", "gripper_tip")
    assert "gripper_tip" in str(err.value) and "tool0" in str(err.value)
    assert "ur5" in str(err.value)


def test_urdf_errors_name_the_file(tmp_path):
    missing = tmp_path / "nope.urdf"
    with pytest.raises(URDFError, match="nope.urdf: file not found"):
        Arm.from_urdf(missing, "tool0")
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot name='x'><link name='a'></robot")
    with pytest.raises(URDFError, match="bad.urdf: malformed URDF"):
        Arm.from_urdf(bad, "tool0")
    good = tmp_path / "two.urdf"
    good.write_text(
        """<robot name="two">
  <link name="base"/>
  <link name="l1"><inertial><mass value="1"/><origin xyz="0.1 0 0"/>
    <inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="10" velocity="1"/></joint>
</robot>"""
    )
    with pytest.raises(FrameNotFoundError) as err:
        Arm.from_urdf(good, "tool0")
    assert "two.urdf" in str(err.value) and "l1" in str(err.value)
    arm = Arm.from_urdf(good, "l1")
    assert arm.nv == 1 and arm.name == "two"


def test_state_validation_messages(ur5):
    with pytest.raises(InputError, match=r"ur5: q: expected shape \(6,\), got shape \(5,\)"):
        ur5.terms(np.zeros(5))
    with pytest.raises(InputError, match="NaN"):
        ur5.terms(np.full(6, np.nan))
    with pytest.raises(InputError, match="exactly one of robot"):
        load_arm()
