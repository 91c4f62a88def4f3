"""ConstraintSet: vectorised evaluation vs per-joint evaluation, joint-space check on a UR5."""

import numpy as np
import pinocchio as pin
import pytest

from multiarm_pin.constraints import ConstraintSet, ConstraintTerms, make_joint_from_placements
from multiarm_pin.exceptions import ConstraintError, InputError
from multiarm_pin.model.kinematics import BodyKinematics
from multiarm_pin.model.polyhedron import box

from .cases import KINDS, random_joint, trajectories
from .trajectories import RigidTrajectory, stack


def _random_system(rng, n, kinds=KINDS):
    joints, tool_trajs = [], []
    obj_placement = pin.SE3.Random()
    obj = RigidTrajectory(rng, obj_placement.translation, obj_placement.rotation)
    for _ in range(n):
        kind = kinds[rng.integers(len(kinds))]
        joint, oMt, oMo = random_joint(kind, rng, ("tool", "object")[rng.integers(2)])
        # re-anchor the tool on the shared object placement
        oMt = obj_placement * oMo.actInv(oMt)
        joints.append(joint)
        tool_trajs.append(trajectories(rng, oMt, obj_placement)[0])
    return joints, tool_trajs, obj


@pytest.mark.parametrize(
    ("seed", "kinds"),
    [(0, KINDS), (1, KINDS), (2, KINDS), (3, ["revolute"]), (4, ["weld", "fingertips"])],
)
def test_vectorised_evaluate_matches_per_joint_evaluation(seed, kinds):
    rng = np.random.default_rng(seed)
    n = 12
    joints, tool_trajs, obj = _random_system(rng, n, kinds)
    cs = ConstraintSet(joints)
    # systems whose arms all have N_max constraints take the no-scatter path
    assert cs._dense == (len(kinds) == 1 or kinds == ["weld", "fingertips"])
    assert cs.n_arms == n and cs.N_max == max(j.n_constraints for j in joints)
    t = 0.1
    tools = stack([tr.kinematics(t) for tr in tool_trajs])
    ko = obj.kinematics(t)
    terms = cs.evaluate(tools, ko)
    assert isinstance(terms, ConstraintTerms)
    assert terms.G_tool.shape == (n, cs.N_max, 6) and terms.phi.shape == (n, cs.N_max)
    for i, joint in enumerate(joints):
        ref = joint.evaluate(tools.take([i]), ko)
        N = joint.n_constraints
        assert terms.N[i] == N and terms.mask[i].sum() == N and terms.mask[i, :N].all()
        for name in ("phi", "phi_dot", "G_tool", "G_object", "kappa", "contact_points", "normals"):
            got = getattr(terms, name)[i]
            assert np.allclose(got[:N], getattr(ref, name), atol=1e-12, rtol=1e-10), name
            assert np.all(got[N:] == 0.0), name  # padding
    assert np.abs(terms.phi[terms.mask]).max() > 1e-3  # states are not all trivial


def test_evaluate_rejects_wrong_sizes_and_check_initial_names_the_arm():
    rng = np.random.default_rng(3)
    joints, tool_trajs, obj = _random_system(rng, 3)
    cs = ConstraintSet(joints)
    tools0 = stack([tr.kinematics(0.0) for tr in tool_trajs])
    cs.check_initial(tools0, obj.kinematics(0.0))
    with pytest.raises(InputError, match="expected 3 tools and 1 object, got 2 tools"):
        cs.evaluate(tools0.take([0, 1]), obj.kinematics(0.0))
    # move arm 2's tool by 1 cm along a direction its joint blocks
    G = cs.evaluate(tools0, obj.kinematics(0.0)).G_tool[2, 0]
    shifted = tools0.position.copy()
    shifted[2] += 0.01 * G[:3] / np.linalg.norm(G[:3])
    moved = BodyKinematics(shifted, tools0.rotation, tools0.twist)
    message = r"arm 2: joint .* contact \d+ .*gap .* tolerance 1e-06"
    with pytest.raises(ConstraintError, match=message):
        cs.check_initial(moved, obj.kinematics(0.0))
    with pytest.raises(ConstraintError, match="at least one joint"):
        ConstraintSet([])
    with pytest.raises(ConstraintError, match=r"joints\[0\] is a str"):
        ConstraintSet(["weld"])


@pytest.fixture(scope="module")
def ur5():
    import example_robot_data as erd

    robot = erd.load("ur5")
    return robot.model, robot.model.getFrameId("tool0")


def _arm_state(model, data, fid, q, v, a):
    """Tool placement, LWA twist, classical LWA acceleration, Jacobian, J̇q̇ (a = 0)."""
    lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    pin.forwardKinematics(model, data, q, v, np.zeros(model.nv))
    pin.updateFramePlacements(model, data)
    bias = pin.getFrameClassicalAcceleration(model, data, fid, lwa).vector.copy()
    pin.forwardKinematics(model, data, q, v, a)
    pin.updateFramePlacements(model, data)
    M = data.oMf[fid].copy()
    twist = pin.getFrameVelocity(model, data, fid, lwa).vector.copy()
    acc = pin.getFrameClassicalAcceleration(model, data, fid, lwa).vector.copy()
    J = pin.computeFrameJacobian(model, data, q, fid, lwa)
    return M, twist, acc, J, bias


UR5_KINDS = ["weld", "revolute", "prismatic", "cylindrical", "universal", "spherical",
             "corner_gripper", "fingertips"]


@pytest.mark.parametrize("kind", UR5_KINDS)
def test_joint_space_acceleration_constraint_on_a_ur5(ur5, kind):
    """φ̈ = W_oiᵀ q̈_o + W_iᵀ q̈_i - c_i along a random arm and object trajectory."""
    model, fid = ur5
    data = model.createData()
    rng = np.random.default_rng(4)
    pin.seed(4)  # randomConfiguration draws from Pinocchio's own generator
    q0 = pin.randomConfiguration(model)
    dq, ddq, dddq = rng.normal(size=(3, model.nv)) * [[1.0], [2.0], [3.0]]

    def arm(t):
        q = q0 + dq * t + ddq * t**2 / 2 + dddq * t**3 / 6
        return q, dq + ddq * t + dddq * t**2 / 2, ddq + dddq * t

    M0 = _arm_state(model, data, fid, *arm(0.0))[0]
    obj_M0 = M0 * pin.SE3(pin.exp3(rng.normal(size=3)), rng.normal(size=3) * 0.2)
    obj = RigidTrajectory(rng, obj_M0.translation, obj_M0.rotation, speed=0.3, spin=1.0)
    if kind == "fingertips":
        params = {"polyhedron": box([0.4, 0.3, 0.2]), "radius": 0.01,
                  "contacts": [("+x", [0.2, 0.05, 0.03]), ("-x", [-0.2, -0.1, 0.0]),
                               ("+z", [0.1, 0.1, 0.1])]}
    else:
        params = {"size": 0.06}
    joint = make_joint_from_placements(kind, M0, obj_M0, **params)
    cs = ConstraintSet([joint])

    def terms_at(t):
        M, twist, acc, J, bias = _arm_state(model, data, fid, *arm(t))
        tool = BodyKinematics.single(M.translation, M.rotation, twist)
        return cs.evaluate(tool, obj.kinematics(t)), joint.evaluate(tool, obj.kinematics(t)), \
            J, bias, acc

    start, *_ = terms_at(0.0)
    assert np.allclose(start.phi, 0.0, atol=1e-12)
    t = 0.2
    terms, jterms, J, bias, acc = terms_at(t)
    N = joint.n_constraints
    G_tool, G_obj = terms.G_tool[0, :N], terms.G_object[0, :N]
    W_i = J.T @ G_tool.T
    W_oi = G_obj.T
    c_i = -G_tool @ bias - terms.kappa[0, :N]
    assert np.allclose(W_i, jterms.W_bar(J)) and np.allclose(c_i, jterms.drift(bias))
    assert np.allclose(acc, J @ arm(t)[2] + bias)  # Pinocchio's own J q̈ + J̇q̇ split
    qdd, a_o = arm(t)[2], obj.state(t)[3]
    predicted = W_oi.T @ a_o + W_i.T @ qdd - c_i
    phi = lambda s: terms_at(s)[0].phi[0, :N]  # noqa: E731
    err = []
    for h in (2e-3, 1e-3, 5e-4):
        err.append(np.abs((phi(t + h) - 2 * phi(t) + phi(t - h)) / h**2 - predicted).max())
    assert err[-1] < 1e-3 * max(1.0, np.abs(predicted).max())
    assert err[2] < 0.35 * err[1] + 1e-9 and err[1] < 0.35 * err[0] + 1e-9
    # and the velocity level: φ̇ = W_oiᵀ v_o + W_iᵀ q̇
    h = 1e-6
    fd = (phi(t + h) - phi(t - h)) / (2 * h)
    assert np.allclose(fd, W_oi.T @ obj.state(t)[2] + W_i.T @ arm(t)[1], atol=1e-7)
    assert np.allclose(fd, terms.phi_dot[0, :N], atol=1e-7)
