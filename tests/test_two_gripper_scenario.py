"""The two-gripper 7-contact form-closure scenario (issue 6): grasp analysis and a short run.

``scenarios/two_gripper_form_closure.yaml``: an ``mp6_4f`` arm (four fingertips at one box
corner, thesis Sec 2.2.3.1) and an ``mp6`` arm (three fingertips at the opposite corner).
Checked against the grasp layer (form closure from the simulated contacts, and the thesis's
two-corner layout built independently by ``two_corner_box_grasp``), forward kinematics
(every sphere touches its face), and a short simulation (gaps, forces, Newton's law).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from multiarm_pin.app.runner import run_scenario
from multiarm_pin.app.scenario import build_scenario, load_scenario
from multiarm_pin.grasp import form_closure, two_corner_box_grasp, wrench_matrix
from multiarm_pin.spatial import quaternion_to_rotation

PATH = Path(__file__).resolve().parents[1] / "scenarios" / "two_gripper_form_closure.yaml"
TIP_RADIUS = 0.015
# mp6_4f's corner layout (robots/README.md): A, E, D [m]
A, E, D = 0.05, 0.02, 0.15
RUN_DURATION = 0.25


@pytest.fixture(scope="module")
def built():
    return build_scenario(load_scenario(PATH))


@pytest.fixture(scope="module")
def contacts(built):
    """(7, 3) contact points (object frame about the COM) and (7, 3) inward normals, t = 0."""
    ct = built.system.blocks(built.initial_state).constraints
    mask = ct.mask
    com = built.initial_state.obj.position
    R = built.scenario.object.placement.rotation
    return (ct.contact_points[mask] - com) @ R, ct.normals[mask] @ R


def test_scenario_is_two_arms_placed_by_ik_with_4_plus_3_fingertips(built):
    sc = built.scenario
    assert [Path(a.urdf).name for a in sc.arms] == ["mp6_4f.urdf", "mp6.urdf"]
    assert all(a.q0 is None for a in sc.arms), "arms are placed by inverse kinematics"
    assert [len(a.joint.contacts) for a in sc.arms] == [4, 3]
    assert built.system.unilateral.sum() == 7
    for ik in built.ik:
        assert ik.residual < 1e-9 and not ik.at_limit.any()
    assert 0.6 <= max(sc.object.size) <= 1.0  # a large box next to 0.2 m grippers
    assert sc.controller.type == "object_pd"
    assert len(sc.controller.params["trajectory"]["times"]) >= 3  # start + 2 waypoints


def test_every_fingertip_sphere_touches_its_face(built):
    """FK of each tip frame: centre exactly one radius outside its face, inside the face."""
    obj = built.obj.shape
    oMo = built.scenario.object.placement
    for spec, arm, q in zip(built.scenario.arms, built.arms, built.q0, strict=True):
        for c in spec.joint.contacts:
            centre = oMo.actInv(arm.frame_placement(q, c.tip).translation)
            assert obj.signed_distance_to_face(centre, c.face) == pytest.approx(
                TIP_RADIUS, abs=1e-9), (spec.name, c.tip)
            f = obj.face_index(c.face)
            assert obj.point_on_face(centre - TIP_RADIUS * obj.normals[f], f, 1e-9)


def test_four_finger_gripper_sits_exactly_on_the_thesis_layout(built, contacts):
    """The 4f tips touch the Example 2.1 points (A, E, D) at the +corner of the box."""
    points, _ = contacts
    size = built.scenario.object.size
    ref = two_corner_box_grasp(size, A, E, D)  # contacts p1 (+x), p2 (+y), p3 (+z), ..., p7
    expected = np.array([ref.contacts[k].point for k in (0, 1, 2, 6)])
    np.testing.assert_allclose(points[:4], expected, atol=1e-8)


def test_grasp_is_form_closure_and_neither_gripper_alone_is(contacts):
    points, normals = contacts
    W = wrench_matrix(points, normals)
    res = form_closure(W)
    assert res.form_closure and res.rank == 6
    assert res.margin > 0.03 and res.ferrari_canny > 0
    assert np.all(res.coefficients > 0)
    for cols in (slice(0, 4), slice(4, 7)):
        alone = form_closure(W[:, cols], allow_fewer=True)
        assert not alone.form_closure and alone.margin == 0.0
    # every contact is needed: removing any one loses closure (7 = the minimum)
    for k in range(7):
        assert not form_closure(np.delete(W, k, axis=1), allow_fewer=True).form_closure
    # the mirrored thesis layout (second gripper exactly at -p1, -p2, -p3) closes too
    assert form_closure(two_corner_box_grasp([0.8, 0.6, 0.4], A, E, D)).form_closure


def test_short_run_holds_the_grasp(tmp_path):
    res = run_scenario(PATH, tmp_path, duration=RUN_DURATION, html=False, plots=False)
    s, tr, built = res.summary, res.trajectory, res.built
    margin = built.scenario.controller.params["margin"]
    assert s["finite"] and s["warnings"] == []
    assert s["max_constraint_violation"] < 1e-6
    phi = np.concatenate([tr["phi_four_finger"], tr["phi_three_finger"]], axis=1)
    assert phi.shape[1] == 7 and np.abs(phi).max() < 1e-6
    mu = np.concatenate([tr["mu_four_finger"], tr["mu_three_finger"]], axis=1)
    assert mu.min() >= margin - 1e-6, mu.min(axis=0)
    assert s["min_unilateral_contact_force"] >= margin - 1e-6
    # the margin is active: the distribution pushes some tip with exactly the margin
    assert mu.min() == pytest.approx(margin, abs=1e-3)
    # Newton: the seven contact forces carry the box's weight and accelerate it
    m = built.obj.mass
    f = tr["contact_forces"].sum(axis=1)
    acc = res.result.object_acceleration[:, :3]
    np.testing.assert_allclose(f, m * (acc - built.scenario.gravity), atol=1e-6 * np.abs(f).max())
    # it follows the first waypoint's minimum-jerk lift (upwards, no jump)
    z = tr["object_position"][:, 2]
    assert np.all(np.diff(z) > -1e-9) and 0 < z[-1] - z[0] < 0.05
    # the grasp is still form closure where the (frictionless) tips are at the end: they
    # may slide along their faces, which the closure margin bounds
    R = quaternion_to_rotation(tr["object_quaternion"][-1])
    p_end = (tr["contact_points"][-1] - tr["object_position"][-1]) @ R
    n_end = tr["contact_forces"][-1] @ R
    n_end /= np.linalg.norm(n_end, axis=1, keepdims=True)
    assert form_closure(wrench_matrix(p_end, n_end)).margin > 0.03
    # torques within the arms' effort limits
    for arm in built.arms:
        assert np.all(np.abs(tr[f"tau_{arm.name}"]) <= arm.model.effortLimit)
