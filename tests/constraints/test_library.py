"""Joint library: degrees of freedom, finite joint motions, Example 3.1, definitions, errors."""

import numpy as np
import pinocchio as pin
import pytest

from multiarm_pin.constraints import (
    JOINT_TYPES,
    as_placement,
    corner_gripper,
    fingertips_from_placements,
    fingertips_on_faces,
    make_joint,
    make_joint_from_placements,
    weld_from_placements,
)
from multiarm_pin.exceptions import ConstraintError
from multiarm_pin.model.kinematics import BodyKinematics
from multiarm_pin.model.polyhedron import box

from .cases import random_placement


def _at_rest(M: pin.SE3) -> BodyKinematics:
    return BodyKinematics.single(M.translation, M.rotation, np.zeros(6))


def _all_gaps(joint, tool_in_object: pin.SE3) -> np.ndarray:
    states = joint.contact_states(_at_rest(tool_in_object), _at_rest(pin.SE3.Identity()),
                                  active_only=False)
    return np.array([s.phi for s in states])


EXPECTED_DOF = {"weld": 0, "revolute": 1, "prismatic": 1, "cylindrical": 2, "universal": 2,
                "spherical": 3, "corner_gripper": 2}


@pytest.mark.parametrize("kind", sorted(EXPECTED_DOF))
def test_degrees_of_freedom(kind):
    rng = np.random.default_rng(20)
    assert JOINT_TYPES[kind].dof == EXPECTED_DOF[kind]
    for points_on in ("tool", "object"):
        params = {"joint_in_object": random_placement(rng), "joint_in_tool": random_placement(rng)}
        if kind != "corner_gripper":
            params |= {"points_on": points_on, "tip_radius": 0.005}
        joint = make_joint(kind, **params)
        assert joint.dof == EXPECTED_DOF[kind]
        assert joint.rank == joint.n_constraints == 6 - joint.dof
        assert len(joint.kept) + len(joint.dropped) == joint.n_contacts
    assert make_joint("prismatic", joint_in_object=pin.SE3.Identity()).dropped == (5,)


def _rot(axis, angle):
    return pin.exp3(angle * np.eye(3)[axis])


# finite relative motions of the joint frame J (tool side) that each joint allows
ALLOWED = {
    "revolute": lambda a, b, c: pin.SE3(_rot(2, a), np.zeros(3)),
    "prismatic": lambda a, b, c: pin.SE3(np.eye(3), np.array([0, 0, a])),
    "cylindrical": lambda a, b, c: pin.SE3(_rot(2, a), np.array([0, 0, b])),
    "universal": lambda a, b, c: pin.SE3(_rot(1, b) @ _rot(0, a), np.zeros(3)),
    "spherical": lambda a, b, c: pin.SE3(pin.exp3(np.array([a, b, c])), np.zeros(3)),
}


@pytest.mark.parametrize("kind", sorted(ALLOWED))
def test_finite_joint_motions_keep_every_contact_closed(kind):
    """The contact model is the joint: its motions keep every gap (dropped ones too) zero."""
    rng = np.random.default_rng(21)
    J_o, J_t = random_placement(rng), random_placement(rng)
    joint = make_joint(kind, joint_in_object=J_o, joint_in_tool=J_t, size=0.07, tip_radius=0.01)
    for _ in range(5):
        motion = ALLOWED[kind](*rng.uniform(-0.6, 0.6, size=3))
        moved = J_o * motion * J_t.inverse()
        assert np.allclose(_all_gaps(joint, moved), 0.0, atol=1e-12)
    # a small motion outside the joint's motion space opens a gap
    blocked = J_o * pin.exp6(pin.Motion(rng.normal(size=6) * 0.01)) * J_t.inverse()
    assert np.abs(_all_gaps(joint, blocked)).max() > 1e-4


def _corner_points(rng):
    """Random Example 3.1 contacts in the corner frame (box in the negative octant)."""
    x1, y1, x3, y3 = -rng.uniform(0.01, 0.1, size=4)
    x2, z2, y4, z4 = -rng.uniform(0.01, 0.1, size=4)
    return np.array([[x1, y1, 0], [x2, 0, z2], [x3, y3, 0], [0, y4, z4]])


def test_example_3_1_closed_form_T():
    rng = np.random.default_rng(22)
    for _ in range(5):
        pts = _corner_points(rng)
        (x1, y1, z1), (x2, y2, z2), (x3, y3, z3), (x4, y4, z4) = pts
        a, b, c, d, e, f = z2 - z1, x1 - x2, y1 - y3, x3 - x1, z1 - z4, y4 - y1
        D = a * d * f + b * c * e
        # object axes along the corner's edges, gripper frame at contact 1 with the same axes
        corner = pin.SE3(np.eye(3), rng.normal(size=3) * 0.2)
        joint = corner_gripper(corner, pin.SE3(np.eye(3), -pts[0]), points=pts,
                               alpha_rows=["vx", "vy"])
        assert joint.dof == 2
        terms = joint.evaluate(*joint.reference_kinematics())
        W_thesis = np.array([
            [0, 0, 0, -1],
            [0, -1, 0, 0],
            [-1, 0, -1, 0],
            [0, a, c, 0],
            [0, 0, d, e],
            [0, b, 0, f],
        ])
        assert np.allclose(terms.W_mi_o, W_thesis, atol=1e-12)
        T_thesis = np.array([
            [1, 0],
            [0, 1],
            [0, 0],
            [-b * d / D, d * f / D],
            [b * c / D, -c * f / D],
            [a * d / D, c * e / D],
        ])
        assert np.allclose(terms.T, T_thesis, atol=1e-9)


def test_example_3_1_degenerate_letters_refuse_vx_vy():
    # a = z2 - z1 = 0 and b = x1 - x2 = 0 make adf + bce = 0: x, y no longer parametrise
    pts = np.array([[-0.05, -0.03, 0], [-0.05, 0, 0], [-0.02, -0.07, 0], [0, -0.04, -0.06]])
    at_contact_1 = pin.SE3(np.eye(3), -pts[0])  # the gripper frame of Example 3.1
    j = corner_gripper(pin.SE3.Identity(), at_contact_1, points=pts)  # still 2 DOF
    assert j.dof == 2 and j.alpha_names != ("vx", "vy")
    with pytest.raises(ConstraintError, match="cannot parametrise"):
        corner_gripper(pin.SE3.Identity(), at_contact_1, points=pts, alpha_rows=["vx", "vy"])


def test_corner_gripper_bad_points():
    pts = _corner_points(np.random.default_rng(23))
    off = pts.copy()
    off[1, 1] = -0.01  # contact 2 off the face y = 0
    with pytest.raises(ConstraintError, match="contact 2 .* face y = 0"):
        corner_gripper(pin.SE3.Identity(), points=off)
    same = pts.copy()
    same[2] = same[0]  # contacts 1 and 3 coincide: rank 3
    with pytest.raises(ConstraintError, match=r"3 independent constraints \(3 DOF\), expected 4"):
        corner_gripper(pin.SE3.Identity(), points=same)


def test_weld_from_placements_holds_the_tool_where_it_is():
    rng = np.random.default_rng(24)
    oMt, oMo = random_placement(rng), random_placement(rng)
    joint = weld_from_placements(oMt, oMo, size=0.1)
    assert joint.dof == 0 and joint.kind == "weld"
    assert np.allclose(joint.tool_in_object, oMo.actInv(oMt))
    from multiarm_pin.constraints import ConstraintSet
    cs = ConstraintSet([joint])
    cs.check_initial(_at_rest(oMt), _at_rest(oMo))
    moved = oMt * pin.exp6(pin.Motion(np.r_[0.002, 0, 0, 0, 0, 0]))
    with pytest.raises(ConstraintError, match=r"arm 0: joint 'weld'"):
        cs.check_initial(_at_rest(moved), _at_rest(oMo))
    # same result from the registry and from a YAML-like mapping and a 4x4 matrix
    yaml_like = {"position": oMt.translation.tolist(), "rotation": oMt.rotation.tolist()}
    j2 = make_joint_from_placements("weld", yaml_like, oMo.homogeneous, size=0.1)
    assert np.allclose(j2.tool_in_object, joint.tool_in_object)


def test_fingertips_form_closure_grasp_drops_the_seventh():
    shape = box([0.4, 0.3, 0.2])
    contacts = [("+x", [0.2, 0.05, 0.03]), ("-x", [-0.2, -0.1, 0.0]), ("+z", [0.1, 0.1, 0.1]),
                ("+z", [-0.1, 0.05, 0.1]), ("+y", [0.0, 0.15, -0.05]), ("-y", [0.1, -0.15, 0.0]),
                ("-z", [0.0, 0.0, -0.1])]
    rng = np.random.default_rng(25)
    oMo, oMt = random_placement(rng), random_placement(rng)
    joint = fingertips_from_placements(shape, contacts, 0.01, oMt, oMo)
    assert (joint.n_contacts, joint.rank, joint.dof, joint.dropped) == (7, 6, 0, (6,))
    terms = joint.evaluate(_at_rest(oMt), _at_rest(oMo))
    assert np.allclose(terms.phi, 0.0, atol=1e-12)
    # each contact pushes the object along its face's inward normal
    face_normals = np.array([shape.normals[shape.face_index(f)] for f, _ in contacts[:6]])
    assert np.allclose(terms.normals, -(face_normals @ oMo.rotation.T))
    # the same joint from tips given in the tool frame (placement fitted)
    tips = np.array([oMt.actInv(oMo.act(p + 0.01 * n))
                     for (_, p), n in zip(contacts, shape.normals[[0, 1, 4, 4, 2, 3, 5]],
                                          strict=True)])
    again = fingertips_on_faces(shape, contacts, 0.01, tips)
    assert np.allclose(again.tool_in_object, joint.tool_in_object, atol=1e-9)
    yaml_like = [(face, list(p)) for face, p in contacts]
    third = make_joint_from_placements("fingertips", oMt, oMo, polyhedron=shape,
                                       contacts=yaml_like, radius=0.01)
    assert np.allclose(third.evaluate(_at_rest(oMt), _at_rest(oMo)).G_object, terms.G_object)
    # errors: a point off its face, tips that no rigid placement matches, count mismatch
    with pytest.raises(ConstraintError, match=r"contact 1: point .* not on face '-x'"):
        fingertips_on_faces(shape, [("+x", [0.2, 0, 0]), ("-x", [-0.1, 0, 0])], 0.01,
                            tips[:2])
    bad = tips.copy()
    bad[0] += [0.0, 0.0, 0.03]
    with pytest.raises(ConstraintError, match="not on its surface"):
        fingertips_on_faces(shape, contacts, 0.01, bad)
    with pytest.raises(ConstraintError, match="7 contacts but 6 tip points"):
        fingertips_on_faces(shape, contacts, 0.01, tips[:6])


def test_registry_and_placement_errors():
    with pytest.raises(ConstraintError, match=r"unknown joint type 'hinge'; known types: .*weld"):
        make_joint("hinge", joint_in_object=pin.SE3.Identity())
    with pytest.raises(ConstraintError, match="bad parameters"):
        make_joint("revolute", joint_in_object=pin.SE3.Identity(), axis=[0, 0, 1])
    with pytest.raises(ConstraintError, match="positive length"):
        make_joint("revolute", joint_in_object=pin.SE3.Identity(), size=0.0)
    with pytest.raises(ConstraintError, match="points_on"):
        make_joint("spherical", joint_in_object=pin.SE3.Identity(), points_on="nowhere")
    with pytest.raises(ConstraintError, match="unknown joint type 'custom'; known types: .*fing"):
        make_joint_from_placements("custom", pin.SE3.Identity(), pin.SE3.Identity())
    with pytest.raises(ConstraintError, match="joint 'fingertips': bad parameters"):
        make_joint_from_placements("fingertips", pin.SE3.Identity(), pin.SE3.Identity())
    with pytest.raises(ConstraintError, match="unit quaternion"):
        as_placement({"position": [0, 0, 0], "quaternion": [0, 0, 0, 2]})
    with pytest.raises(ConstraintError, match="unknown keys"):
        as_placement({"position": [0, 0, 0], "euler": [0, 0, 0]})
    with pytest.raises(ConstraintError, match="4x4"):
        as_placement([1, 2, 3])
    M = as_placement({"position": [1, 2, 3], "rpy": [0.1, 0.2, 0.3]})
    assert np.allclose(M.translation, [1, 2, 3])
    assert np.allclose(M.rotation, pin.rpy.rpyToMatrix(0.1, 0.2, 0.3))
    with pytest.raises(ConstraintError, match="unknown surface type 'cone'"):
        make_joint("custom", contacts=[{"point": [0, 0, 0], "surface": {"type": "cone"}}],
                   joint_in_object=pin.SE3.Identity())
    with pytest.raises(ConstraintError, match="expected point and surface"):
        make_joint("custom", contacts=[{"point": [0, 0, 0]}], joint_in_object=pin.SE3.Identity())
