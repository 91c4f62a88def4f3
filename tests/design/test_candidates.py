"""Candidates: faces and points offered, determinism of sampling, weld placements."""

import dataclasses

import numpy as np
import pytest

from multiarm_pin.design import load_design, parse_design
from multiarm_pin.design.assessment import DesignProblem, candidate_from_scenario, weld_placement
from multiarm_pin.design.candidates import (
    BRANCHES,
    MIN_BASE_DISTANCE,
    approach,
    branch_of,
    candidate_rng,
    face_edge_margin,
    perturb,
    point_allowed,
    random_seed_configuration,
    reseed,
    sample_candidate,
    sample_face_point,
    slide,
    turn,
    weld_faces,
)
from multiarm_pin.exceptions import UnreachableError
from multiarm_pin.model.ik import PoseTarget, solve_ik
from multiarm_pin.model.polyhedron import box
from tests.design.design_cases import TWO_UR5_SCENARIO, TWO_UR5_SPEC, spec_data


def test_edge_margin_of_a_box_face_is_the_distance_to_its_nearest_edge():
    poly = box([0.8, 0.4, 0.3])
    f = poly.face_index("+y")
    p = np.array([0.3, 0.2, -0.1])
    assert face_edge_margin(poly, f, p) == pytest.approx(min(0.4 - 0.3, 0.15 - 0.1), abs=1e-12)
    assert face_edge_margin(poly, f, np.array([0.5, 0.2, 0.0])) == pytest.approx(-0.1)


def test_sampled_points_keep_the_margin(rng):
    poly = box([0.8, 0.4, 0.3])
    for f in range(6):
        for _ in range(20):
            p = sample_face_point(poly, f, 0.05, rng)
            assert abs(poly.signed_distance_to_face(p, f)) < 1e-12
            assert face_edge_margin(poly, f, p) >= 0.05


def test_welds_never_take_a_supported_or_downward_face():
    d = spec_data()
    d["object"]["pose"]["position"] = [0.5, 0.0, 0.15]
    d["supports"] = [{"name": "table", "plane": {"point": [0, 0, 0], "normal": [0, 0, 1]},
                      "points": "vertices"}]
    spec = parse_design(d, "s.yaml")
    poly = box(spec.object.size)
    faces = [poly.face_names[f] for f in weld_faces(spec, poly)]
    assert faces == ["+x", "-x", "+y", "-y", "+z"]
    # a stand smaller than the bottom face leaves its overhang to fingertips
    d["supports"][0]["points"] = [[0.2, 0.1, -0.15], [-0.2, 0.1, -0.15], [0.2, -0.1, -0.15],
                                  [-0.2, -0.1, -0.15]]
    spec = parse_design(d, "s.yaml")
    bottom = poly.face_index("-z")
    assert not point_allowed(spec, poly, bottom, np.array([0.0, 0.0, -0.15]), 0.01)
    assert point_allowed(spec, poly, bottom, np.array([0.35, 0.15, -0.15]), 0.01)


def test_a_candidate_depends_only_on_the_seed_and_its_index():
    spec = load_design(TWO_UR5_SPEC)
    problem = DesignProblem(spec)
    a, b = sample_candidate(problem, 7), sample_candidate(problem, 7)
    for x, y in zip(a.arms, b.arms, strict=True):
        np.testing.assert_array_equal(x.base, y.base)
        np.testing.assert_array_equal(x.q_seed, y.q_seed)
    other = DesignProblem(dataclasses.replace(spec, search=dataclasses.replace(spec.search,
                                                                              seed=1)))
    assert not np.array_equal(sample_candidate(other, 7).arms[0].base, a.arms[0].base)
    # bases in the region; neighbours stay in it, on their parents' faces
    lo, hi = spec.bases.lower, spec.bases.upper
    for i in range(10):
        c = sample_candidate(problem, i)
        n = perturb(problem, c, [x.q_seed for x in c.arms], 100 + i, 0.5)
        for x, y in zip(c.arms, n.arms, strict=True):
            assert np.all(y.base[:3] >= lo - 1e-12) and np.all(y.base[:3] <= hi + 1e-12)
            assert x.faces == y.faces
            assert face_edge_margin(problem.poly, y.faces[0], y.points[0]) >= \
                spec.search.face_margin - 1e-12


def test_polishing_moves_change_one_arm_only():
    """``approach`` moves one base horizontally along the line to its grasp, by at most the
    step (toward it for a positive step, away for a negative one); ``reseed`` changes one arm's
    IK seed only. Every other arm keeps its base, grasp and (given) configuration."""
    spec = load_design(TWO_UR5_SPEC)
    problem = DesignProblem(spec)
    oMo = problem.object_placement
    moved = 0
    for i in range(10):
        c = sample_candidate(problem, i)
        q0s = [x.q_seed + 0.01 for x in c.arms]
        for arm in range(len(c.arms)):
            for step in (0.05, -0.05):
                n = approach(problem, c, q0s, 200 + i, arm, step)
                a, b = c.arms[arm], n.arms[arm]
                g = oMo.act(a.points.mean(axis=0))
                d_before = np.linalg.norm(g[:2] - a.base[:2])
                d_after = np.linalg.norm(g[:2] - b.base[:2])
                delta = b.base - a.base
                assert delta[2] == 0.0 and delta[3] == 0.0
                # along the horizontal line to the grasp
                u = g[:2] - a.base[:2]
                assert abs(delta[0] * u[1] - delta[1] * u[0]) < 1e-9
                assert np.all(b.base[:3] >= spec.bases.lower) and \
                    np.all(b.base[:3] <= spec.bases.upper)
                assert np.linalg.norm(delta[:2]) <= abs(step) + 1e-12
                assert (d_after <= d_before + 1e-12) if step > 0 else \
                    (d_after >= d_before - 1e-12)
                assert problem.footprint_distance(b.base[:3]) >= MIN_BASE_DISTANCE or \
                    np.array_equal(a.base, b.base)
                moved += int(not np.array_equal(a.base, b.base))
                for k, (x, y) in enumerate(zip(c.arms, n.arms, strict=True)):
                    np.testing.assert_array_equal(y.q_seed, q0s[k])
                    np.testing.assert_array_equal(y.points, x.points)
                    if k != arm:
                        np.testing.assert_array_equal(y.base, x.base)
            r = reseed(problem, c, q0s, 300 + i, arm)
            for k, (x, y) in enumerate(zip(c.arms, r.arms, strict=True)):
                np.testing.assert_array_equal(y.base, x.base)
                np.testing.assert_array_equal(y.points, x.points)
                assert np.array_equal(y.q_seed, q0s[k]) == (k != arm)
    assert moved > 0


def test_moving_every_base_turning_and_sliding_a_weld():
    """``approach`` with no arm moves every base along its own horizontal line to its grasp by
    the same distance; ``turn`` turns one weld's tool about its face normal (the same point,
    the tool's z axis kept) by at most the step, ``slide`` moves one weld's point on its face
    (inside it by the margin); each changes nothing else."""
    import pinocchio as pin

    problem = DesignProblem(load_design(TWO_UR5_SPEC))
    spec_margin = problem.spec.search.face_margin
    oMo = problem.object_placement
    together = 0
    for i in range(6):
        c = sample_candidate(problem, i)
        q0s = [x.q_seed + 0.01 for x in c.arms]
        n = approach(problem, c, q0s, 400 + i, None, 0.05)
        moved = []
        for a, b in zip(c.arms, n.arms, strict=True):
            g = oMo.act(a.points.mean(axis=0))
            delta = b.base - a.base
            u = g[:2] - a.base[:2]
            assert delta[2] == delta[3] == 0.0
            assert abs(delta[0] * u[1] - delta[1] * u[0]) < 1e-9 and delta[:2] @ u >= 0.0
            if np.any(delta):
                moved.append(float(np.linalg.norm(delta[:2])))
        assert all(0.0 < d <= 0.05 for d in moved)
        if len(moved) == len(c.arms):
            together += 1
            assert np.ptp(moved) < 1e-12
        for arm in range(len(c.arms)):
            t = turn(problem, c, q0s, 500 + i, arm, 0.5)
            for k, (x, y) in enumerate(zip(c.arms, t.arms, strict=True)):
                np.testing.assert_array_equal(y.base, x.base)
                np.testing.assert_array_equal(y.q_seed, q0s[k])
                M0 = weld_placement(problem.poly, x.faces[0], x.points[0], x.roll)
                M1 = weld_placement(problem.poly, y.faces[0], y.points[0], y.roll)
                np.testing.assert_allclose(M1.translation, M0.translation, atol=1e-15)
                R = M0.rotation.T @ M1.rotation  # a rotation about the tool's z axis
                np.testing.assert_allclose(R[:, 2], [0.0, 0.0, 1.0], atol=1e-12)
                angle = float(np.linalg.norm(pin.log3(R)))
                assert (0.0 < angle <= 0.5 + 1e-12) if k == arm else angle < 1e-12
            sl = slide(problem, c, q0s, 600 + i, arm, 0.03)
            for k, (x, y) in enumerate(zip(c.arms, sl.arms, strict=True)):
                np.testing.assert_array_equal(y.base, x.base)
                np.testing.assert_array_equal(y.q_seed, q0s[k])
                assert y.roll == x.roll and y.faces == x.faces
                d = y.points[0] - x.points[0]
                n = problem.poly.normals[x.faces[0]]
                assert abs(d @ n) < 1e-12  # on the face's plane
                assert face_edge_margin(problem.poly, y.faces[0], y.points[0]) >= \
                    spec_margin - 1e-12
                assert np.any(d != 0.0) == (k == arm)
    assert together > 0


def test_weld_tool_points_into_its_face():
    poly = box([0.8, 0.4, 0.3])
    for f in range(6):
        M = weld_placement(poly, f, poly.face_frame(f)[0], 0.7)
        np.testing.assert_allclose(M.rotation[:, 2], -poly.normals[f], atol=1e-12)
        np.testing.assert_allclose(M.rotation.T @ M.rotation, np.eye(3), atol=1e-12)
        assert np.linalg.det(M.rotation) == pytest.approx(1.0)


def test_branch_seeds_reach_the_ur5_branches_of_a_weld_pose():
    """Seeds on each of the 8 branches (shoulder toward/away, elbow and wrist signs) of the
    demo's UR5s at their shipped weld poses: each seed lies on its branch, and inverse
    kinematics from them finds configurations on most branches (a UR5 has 8 at a generic
    pose), each holding the weld pose (forward kinematics, below 1e-6 m and rad)."""
    import pinocchio as pin

    problem = DesignProblem(load_design(TWO_UR5_SPEC))
    cand = candidate_from_scenario(problem, TWO_UR5_SCENARIO)
    for i, a in enumerate(cand.arms):
        arm = problem.arm(i, a.base)
        M = problem.object_placement * weld_placement(problem.poly, a.faces[0], a.points[0],
                                                      a.roll)
        tool = arm.model.frames[arm.tool_frame_id].name
        grasp = problem.object_placement.act(a.points.mean(axis=0))
        rng = candidate_rng(0, 7)
        found = set()
        for b in range(BRANCHES):
            for _ in range(3):
                q = random_seed_configuration(problem, i, a.base, grasp, rng, b)
                assert branch_of(problem, i, a.base, grasp, q) == b
                try:
                    ik = solve_ik(arm.model, [PoseTarget(tool, M)], q, max_iter=40, restarts=0)
                except UnreachableError:
                    continue
                pin.framesForwardKinematics(arm.model, arm.data, ik.q)
                err = arm.data.oMf[arm.tool_frame_id].actInv(M)
                assert np.linalg.norm(err.translation) < 1e-6
                assert np.linalg.norm(pin.log3(err.rotation)) < 1e-6
                found.add(branch_of(problem, i, a.base, grasp, ik.q))
        assert len(found) >= 5, (i, found)
