"""Fingertip designs (the shipped mp6 hands): rigid grips, closure re-checked independently."""

import numpy as np
import pinocchio as pin
import pytest
from scipy.spatial import ConvexHull

from multiarm_pin.app.precheck import static_torques
from multiarm_pin.app.scenario import build_scenario
from multiarm_pin.app.scenario.schema import parse_scenario
from multiarm_pin.data import data_path
from multiarm_pin.design import load_design, run_design
from multiarm_pin.design.candidates import corner_assignments, fit_gripper
from multiarm_pin.design.evaluation import DesignProblem, candidate_from_scenario, evaluate
from multiarm_pin.feasibility import CollisionScene
from multiarm_pin.grasp.form_closure import form_closure
from tests.design.design_cases import coal_clearance, rnea_static_torques, small

SPEC = data_path("scenarios", "designs", "two_gripper_form_closure.yaml")


@pytest.fixture(scope="module")
def searched():
    spec = small(load_design(SPEC), candidates=24, refine=1)
    return spec, run_design(spec)


def test_a_fitted_grip_puts_every_rigid_tip_on_its_face():
    spec = load_design(SPEC)
    problem = DesignProblem(spec)
    rng = np.random.default_rng(3)
    slot = spec.arms[1]  # three fingers: every order of the corner's faces fits by symmetry
    fits = [fit_gripper(problem, slot, np.array([-1.0, 1.0, -1.0]), axes, rng)
            for axes, _ in corner_assignments(3)]
    assert sum(f is not None for f in fits) >= 3
    tips = problem.tips_in_tool[1]
    for faces, points, tool in (f for f in fits if f is not None):
        M = pin.XYZQUATToSE3(tool)
        for t, f, p in zip(tips, faces, points, strict=True):
            n, d = problem.poly.normals[f], problem.poly.offsets[f]
            centre = M.act(t)
            assert n @ centre - d == pytest.approx(slot.tip_radius, abs=1e-8)
            np.testing.assert_allclose(p, centre - slot.tip_radius * n, atol=1e-12)


def test_the_shipped_design_is_scored_with_every_fingertip_score():
    problem = DesignProblem(load_design(SPEC))
    e = evaluate(problem, candidate_from_scenario(
        problem, data_path("scenarios", "two_gripper_form_closure.yaml")))
    assert e.ok, (e.condition, e.detail)
    assert e.scores["lp_margin"] == pytest.approx(0.0479, abs=5e-4)  # the scenario's comment
    assert e.scores["ferrari_canny"] > 0 and e.scores["stability"] > 0


def test_fingertip_designs_pass_independent_rechecks(searched):
    spec, result = searched
    assert result.designs
    problem = DesignProblem(spec)
    L = float(np.max(np.linalg.norm(problem.poly.vertices, axis=1)))
    for d in result.designs:
        built = build_scenario(parse_scenario(d.scenario, spec.file), load_visuals=False)
        system = built.system
        # the contacts as the scenario states them (object frame), all on faces
        pts, normals = [], []
        for a in built.scenario.arms:
            for c in a.joint.contacts:
                f = problem.poly.face_index(c.face)
                assert abs(problem.poly.signed_distance_to_face(c.point, f)) < 1e-9
                pts.append(c.point)
                normals.append(-problem.poly.normals[f])
        W = np.array([np.concatenate([n, np.cross(p, n) / L])
                      for p, n in zip(pts, normals, strict=True)]).T
        # closure by the LP and by a qhull epsilon of our own
        assert form_closure(W).form_closure
        hull = ConvexHull(W.T)
        assert np.all(hull.equations[:, -1] < 0)  # the origin strictly inside the hull
        eps = float(-hull.equations[:, -1].max())
        # the designer measured the tips where they touch; the file rounds them to 1e-10 m
        assert d.scores["ferrari_canny"] == pytest.approx(eps, rel=1e-6)
        # each tip stays on its face along the task (tool rigid to the object)
        scene = CollisionScene(system, built.initial_state, 0.0)
        oMo0 = problem.object_placement
        tips_obj = []
        for i, arm in enumerate(system.arms):
            q0 = built.initial_state.q[system.arm_set.q_slices[i]]
            tips_obj.append([oMo0.actInv(arm.frame_placement(q0, c.tip).translation)
                             for c in built.scenario.arms[i].joint.contacts])
        for k, (M, q) in enumerate(zip(problem.path_placements, d.evaluation.path_q,
                                       strict=True)):
            for i, arm in enumerate(system.arms):
                qi = q[system.arm_set.q_slices[i]]
                for c, t in zip(built.scenario.arms[i].joint.contacts, tips_obj[i],
                                strict=True):
                    err = np.linalg.norm(arm.frame_placement(qi, c.tip).translation - M.act(t))
                    assert err < 1e-6, (d.rank, k, c.tip, err)
                assert np.all(qi >= arm.model.lowerPositionLimit - 1e-12)
                assert np.all(qi <= arm.model.upperPositionLimit + 1e-12)
            q_scene = np.concatenate([q, M.translation, pin.Quaternion(M.rotation).coeffs()])
            assert coal_clearance(scene, q_scene) >= spec.search.clearance - 1e-9
            st = system.state(q, None, M.translation, pin.Quaternion(M.rotation).coeffs())
            tau, mu, b = rnea_static_torques(system, st)
            np.testing.assert_allclose(tau, static_torques(system, st)[0], atol=1e-8)
            assert np.all(mu[system.unilateral] >= -1e-9)  # every fingertip pushes
            effort = np.concatenate([a.model.effortLimit for a in system.arms])
            assert np.all(np.abs(tau) <= effort)
