"""Joints: rates and accelerations by finite differences, Eq 3.11, reciprocity, T and Ṫ."""

import numpy as np
import pinocchio as pin
import pytest

from multiarm_pin.constraints import TWIST_NAMES, Contact, Joint, Plane
from multiarm_pin.exceptions import ConstraintError, InputError
from multiarm_pin.model.kinematics import BodyKinematics
from multiarm_pin.spatial import wrench_transform

from .cases import KINDS, random_joint, trajectories


def _setup(kind, seed, points_on="tool"):
    rng = np.random.default_rng(seed)
    joint, oMt, oMo = random_joint(kind, rng, points_on)
    tool, obj = trajectories(rng, oMt, oMo)
    return joint, tool, obj


def _eval(joint, tool, obj, t):
    return joint.evaluate(tool.kinematics(t), obj.kinematics(t))


@pytest.mark.parametrize("points_on", ["tool", "object"])
@pytest.mark.parametrize("kind", KINDS)
def test_rates_and_acceleration_constraint_match_finite_differences(kind, points_on):
    joint, tool, obj = _setup(kind, 10, points_on)
    assert np.allclose(_eval(joint, tool, obj, 0.0).phi, 0.0, atol=1e-9)  # assembled at t = 0
    t = 0.15
    terms = _eval(joint, tool, obj, t)
    assert np.max(np.abs(terms.phi)) > 1e-3  # the trajectory does not respect the joint
    h = 1e-5
    fd1 = (_eval(joint, tool, obj, t + h).phi - _eval(joint, tool, obj, t - h).phi) / (2 * h)
    assert np.allclose(fd1, terms.phi_dot, atol=1e-7)
    a_tool, a_obj = tool.state(t)[3], obj.state(t)[3]
    phi_ddot = terms.G_tool @ a_tool + terms.G_object @ a_obj + terms.kappa
    err = []
    for h in (2e-3, 1e-3, 5e-4):
        fd2 = (_eval(joint, tool, obj, t + h).phi - 2 * terms.phi
               + _eval(joint, tool, obj, t - h).phi) / h**2
        err.append(np.max(np.abs(fd2 - phi_ddot)))
    assert err[2] < 1e-3
    assert err[2] < 0.35 * err[1] + 1e-9 and err[1] < 0.35 * err[0] + 1e-9


@pytest.mark.parametrize("kind", KINDS)
def test_eq_3_11_reciprocity_and_motion_space(kind):
    joint, tool, obj = _setup(kind, 11)
    t = 0.1
    kt, ko = tool.kinematics(t), obj.kinematics(t)
    terms = joint.evaluate(kt, ko)
    Rt, Ro = kt.rotation[0], ko.rotation[0]
    R = Ro.T @ Rt
    x = Ro.T @ (kt.position[0] - ko.position[0])
    assert np.allclose(terms.W_oi, -wrench_transform(R, x) @ terms.W_mi, atol=1e-12)
    H = np.kron(np.eye(2), R)
    assert np.allclose(terms.W_mi_o, H @ terms.W_mi, atol=1e-12)
    k = joint.dof
    assert terms.T.shape == (6, k)
    assert np.allclose(terms.W_mi_o.T @ terms.T, 0.0, atol=1e-10)
    assert np.allclose(terms.T[list(joint.alpha_rows)], np.eye(k))
    if k:
        assert np.linalg.matrix_rank(terms.T) == k
    # a tool twist in the motion space moves no contact: φ̇ = 0, and α reads it back
    rng = np.random.default_rng(0)
    alpha = rng.normal(size=k)
    v_o = ko.twist[0]
    rel_world = np.kron(np.eye(2), Ro) @ (terms.T @ alpha)
    v_t = np.concatenate([v_o[:3] + np.cross(v_o[3:], kt.position[0] - ko.position[0]), v_o[3:]])
    v_t = v_t + rel_world
    moved = joint.evaluate(BodyKinematics(kt.position, kt.rotation, v_t[None]), ko)
    assert np.allclose(moved.phi_dot, 0.0, atol=1e-12)
    assert np.allclose(moved.alpha, alpha)
    assert np.allclose(moved.relative_twist, terms.T @ alpha)


@pytest.mark.parametrize("kind", KINDS)
def test_T_dot_and_W_dot_match_finite_differences(kind):
    joint, tool, obj = _setup(kind, 12)
    t, h = 0.1, 1e-6
    terms = _eval(joint, tool, obj, t)
    p, m = _eval(joint, tool, obj, t + h), _eval(joint, tool, obj, t - h)
    assert np.allclose((p.W_mi_o - m.W_mi_o) / (2 * h), terms.W_mi_o_dot, atol=1e-6)
    scale = max(1.0, float(np.abs(terms.T).max(initial=0.0)))
    assert np.allclose((p.T - m.T) / (2 * h), terms.T_dot, atol=1e-5 * scale)
    if joint.kind == "prismatic":
        # its motion is a translation along an axis fixed in the object: T is constant
        assert np.allclose(terms.T_dot, 0.0, atol=1e-12)
    elif joint.dof:
        assert np.abs(terms.T_dot).max() > 1e-3  # the check is not vacuous


def test_dropped_contacts_are_combinations_of_kept_ones():
    rng = np.random.default_rng(5)
    joint, oMt, oMo = random_joint("prismatic", rng)
    assert joint.n_contacts == 6 and joint.rank == 5 and joint.dropped == (5,)
    tool, obj = trajectories(rng, oMt, oMo)
    states = joint.contact_states(tool.kinematics(0), obj.kinematics(0), active_only=False)
    every = np.array([s.G_object for s in states])
    assert np.linalg.matrix_rank(every, tol=1e-9) == 5
    kept = every[list(joint.kept)]
    coef, *_ = np.linalg.lstsq(kept.T, every[5], rcond=None)
    assert np.allclose(kept.T @ coef, every[5])


def test_joint_space_blocks_and_baumgarte():
    joint, tool, obj = _setup("revolute", 13)
    terms = _eval(joint, tool, obj, 0.2)
    J = np.random.default_rng(1).normal(size=(6, 7))
    assert np.allclose(terms.W_bar(J), J.T @ terms.G_tool.T)
    assert np.allclose(terms.W_bar_o, terms.G_object.T)
    b = np.arange(6.0)
    c = terms.drift(b)
    assert np.allclose(c, -terms.G_tool @ b - terms.kappa)
    expected = c - 4.0 * terms.phi_dot - 9.0 * terms.phi
    assert np.allclose(terms.drift_baumgarte(b, 2.0, 3.0), expected)
    with pytest.raises(InputError, match=r"\(6, nv\)"):
        terms.W_bar(np.zeros((5, 7)))


def test_initial_violation_names_contact_gap_and_tolerance():
    joint, tool, obj = _setup("spherical", 14)
    joint.check_initial(tool.kinematics(0.0), obj.kinematics(0.0))
    with pytest.raises(ConstraintError, match=r"arm 3: joint 'spherical'.*contact \d.*gap .* "
                                              r"tolerance 1e-06"):
        joint.check_initial(tool.kinematics(0.2), obj.kinematics(0.2), arm=3)


def test_bad_joint_definitions_raise():
    plane = Plane([0, 0, 0], [0, 0, 1])
    with pytest.raises(ConstraintError, match="at least one contact"):
        Joint([], pin.SE3.Identity())
    # a point off its surface at the reference placement
    with pytest.raises(ConstraintError, match=r"not on its surface.*gap 0.1 m"):
        Joint([Contact([0, 0, 0.1], plane)], pin.SE3.Identity())
    # three collinear contacts on one plane cannot give 3 constraints
    collinear = [Contact([x, 0, 0], plane) for x in (0.0, 0.1, 0.2)]
    with pytest.raises(ConstraintError, match=r"2 independent constraints \(4 DOF\), expected 3"):
        Joint(collinear, pin.SE3.Identity(), expected_dof=3)
    j = Joint(collinear, pin.SE3.Identity())
    assert (j.rank, j.dof, j.dropped) == (2, 4, (2,))
    with pytest.raises(ConstraintError, match="alpha_rows must name 4 distinct"):
        Joint(collinear, pin.SE3.Identity(), alpha_rows=["vx"])
    with pytest.raises(ConstraintError, match="cannot parametrise"):
        Joint(collinear, pin.SE3.Identity(), alpha_rows=["vx", "vy", "vz", "wz"])
    with pytest.raises(ConstraintError, match="not one of"):
        Joint(collinear, pin.SE3.Identity(), alpha_rows=["vx", "vy", "wz", "spin"])
    with pytest.raises(ConstraintError, match="pin.SE3"):
        Joint(collinear, np.eye(4))
    j = Joint(collinear, pin.SE3.Identity(), alpha_rows=["vx", "vy", "wz", "wx"])
    assert j.alpha_names == ("vx", "vy", "wz", "wx")
    assert j.alpha_rows == tuple(TWIST_NAMES.index(r) for r in j.alpha_names)


def test_contact_columns_agree_with_joint_matrices_and_frames():
    joint, tool, obj = _setup("cylindrical", 15)
    kt, ko = tool.kinematics(0.1), obj.kinematics(0.1)
    terms = joint.evaluate(kt, ko)
    Rt, Ro = kt.rotation[0], ko.rotation[0]
    for k, s in enumerate(joint.contact_states(kt, ko)):
        assert np.allclose(terms.W_mi[:, k], s.W_mi) and np.allclose(terms.W_oi[:, k], s.W_oi)
        # the W_mi column is the zero-pitch wrench [n; p × n] in the tool frame
        n_t, p_t = s.normal_in_tool, s.point_in_tool
        assert np.allclose(s.W_mi, np.concatenate([n_t, np.cross(p_t, n_t)]))
        n_o, p_o = s.normal_in_object, s.point_in_object
        assert np.allclose(s.W_oi, -np.concatenate([n_o, np.cross(p_o, n_o)]))
        assert np.allclose(Rt @ p_t + kt.position[0], s.point)
        assert np.allclose(Ro @ n_o, s.normal)


def test_motion_coordinates_that_stop_parametrising_raise_singularity():
    from multiarm_pin.constraints import spherical
    from multiarm_pin.exceptions import SingularityError

    L = 0.05
    joint = spherical(pin.SE3.Identity(), size=L)
    assert joint.alpha_names == ("wx", "wy", "wz")
    # moving the tool puts the ball's centre in the plane of the three tips: their normals
    # become coplanar and the rotation rates no longer fix the translation rows of T
    shifted = BodyKinematics.single(-L / 3 * np.ones(3), np.eye(3), np.zeros(6))
    rest = BodyKinematics.single(np.zeros(3), np.eye(3), np.zeros(6))
    with pytest.raises(SingularityError, match="W_mi_o.*spherical"):
        joint.evaluate(shifted, rest)
