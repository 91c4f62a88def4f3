"""The design search on the demo's box and task (two UR5s, welds).

One search of the shipped spec on a small budget (:data:`BUDGET`) serves the module. Its
designs are re-checked here by independent means (forward kinematics, ``coal.distance``,
``rnea + Jᵀ w``), and compared with the shipped scenario's own design scored by the same
functions.
"""

import numpy as np
import pinocchio as pin
import pytest

from multiarm_pin.app.precheck import static_torques
from multiarm_pin.app.scenario import build_scenario
from multiarm_pin.app.scenario.schema import parse_scenario
from multiarm_pin.design import load_design, run_design
from multiarm_pin.design.assessment import (
    MAX_JOINT_STEP,
    DesignProblem,
    assess,
    candidate_from_scenario,
)
from multiarm_pin.design.scoring import SCORES, at_least_as_good, objective
from multiarm_pin.feasibility import CollisionScene
from tests.design.design_cases import (
    TWO_UR5_SCENARIO,
    TWO_UR5_SPEC,
    coal_clearance,
    rnea_static_torques,
    small,
    tool_pose_errors,
)

BUDGET = {"candidates": 24, "refine": 1, "polish": 1}
"""A small search of the demo's spec (58 candidates instead of its file's 500 or so) that
finds designs at least as good as the shipped one; every spec's own budget is compared in
``benchmarks/results/design.md``."""


@pytest.fixture(scope="module")
def searched():
    spec = small(load_design(TWO_UR5_SPEC), **BUDGET)
    return spec, run_design(spec)


@pytest.fixture(scope="module")
def shipped(searched):
    spec = searched[0]
    problem = DesignProblem(spec)
    return assess(problem, candidate_from_scenario(problem, TWO_UR5_SCENARIO))


def test_the_shipped_design_meets_every_condition_and_is_scored(shipped):
    assert shipped.ok, (shipped.condition, shipped.detail)
    assert set(shipped.scores) == {"torque_ratio", "clearance", "manipulability"}


def test_designs_are_at_least_as_good_as_the_shipped_one(searched, shipped):
    """The best design's objective is at least the shipped one's, and the Pareto front (in
    the report) holds a design at least as good on every score."""
    spec, result = searched
    assert result.designs and len(result.designs) == spec.top
    best = result.designs[0]
    assert best.objective >= objective(shipped.scores, spec.weights)
    assert any(at_least_as_good(d.scores, shipped.scores) for d in result.pareto)
    # ranked by the objective, best first
    objs = [d.objective for d in result.designs]
    assert objs == sorted(objs, reverse=True)


def test_every_returned_design_passes_independent_rechecks(searched):
    spec, result = searched
    margin = spec.search.clearance
    problem = DesignProblem(spec)
    for d in result.designs:
        built = build_scenario(parse_scenario(d.scenario, spec.file), load_visuals=False)
        system = built.system
        tools = [a.joint.placement_in_object for a in built.scenario.arms]
        Q = d.assessment.path_q
        assert Q.shape == (len(problem.path_times), system.nq)
        np.testing.assert_allclose(Q[0], built.initial_state.q, atol=1e-9)
        scene = CollisionScene(system, built.initial_state, 0.0)
        for k, (M, q) in enumerate(zip(problem.path_placements, Q, strict=True)):
            # the welds hold their placements: IK residual below 1e-6 m (and rad)
            err = tool_pose_errors(system, q, M, tools)
            assert err.max() < 1e-6, (d.rank, k, err)
            # joint limits
            for i, arm in enumerate(system.arms):
                qi = q[system.arm_set.q_slices[i]]
                assert np.all(qi >= arm.model.lowerPositionLimit - 1e-12)
                assert np.all(qi <= arm.model.upperPositionLimit + 1e-12)
            # clearance by coal.distance on every pair but the grasps
            q_scene = np.concatenate([q, M.translation, pin.Quaternion(M.rotation).coeffs()])
            assert coal_clearance(scene, q_scene) >= margin - 1e-9
            # static torques: rnea + Jᵀ w, equal to the designer's, within the efforts
            st = system.state(q, None, M.translation, pin.Quaternion(M.rotation).coeffs())
            tau, mu, b = rnea_static_torques(system, st)
            np.testing.assert_allclose(tau, static_torques(system, st)[0], atol=1e-8)
            resultant = b.h_o + sum(b.W_o[i] @ mu[i] for i in range(system.n_arms))
            np.testing.assert_allclose(resultant, 0.0, atol=1e-8)  # the object is held
            effort = np.concatenate([a.model.effortLimit for a in system.arms])
            assert np.all(np.abs(tau) <= effort)
        # one continuous branch
        assert np.abs(np.diff(Q, axis=0)).max() <= MAX_JOINT_STEP
        # the reported torque ratio is the worst along the task
        assert 0.0 < d.scores["torque_ratio"] <= 1.0


def test_the_arms_a_polishing_round_moves_are_those_that_set_the_scores(searched):
    """``torque_arm``: the arm of the joint with the worst torque ratio along the task
    (``rnea + Jᵀ w``), ``manipulability_arm``: the arm of the smallest sqrt(det(J Jᵀ))."""
    spec, result = searched
    problem = DesignProblem(spec)
    for d in result.designs:
        built = build_scenario(parse_scenario(d.scenario, spec.file), load_visuals=False)
        system = built.system
        effort = np.concatenate([a.model.effortLimit for a in system.arms])
        arm_of = np.concatenate([[i] * a.nv for i, a in enumerate(system.arms)])
        worst = (0.0, -1)
        for M, q in zip(problem.path_placements, d.assessment.path_q, strict=True):
            st = system.state(q, None, M.translation, pin.Quaternion(M.rotation).coeffs())
            r = np.abs(rnea_static_torques(system, st)[0]) / effort
            worst = max(worst, (float(r.max()), int(arm_of[int(np.argmax(r))])))
        assert d.scores["torque_ratio"] == pytest.approx(worst[0], rel=1e-9)
        assert d.assessment.torque_arm == worst[1]
        manip = []
        for i, arm in enumerate(system.arms):
            qi = d.assessment.path_q[0][system.arm_set.q_slices[i]]
            J = pin.computeFrameJacobian(arm.model, arm.data, qi, arm.tool_frame_id,
                                         pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
            manip.append(np.sqrt(np.linalg.det(J @ J.T)))
        assert d.assessment.manipulability_arm == int(np.argmin(manip))
        assert d.scores["manipulability"] == pytest.approx(min(manip), rel=1e-9)


def test_same_seed_same_designs_on_one_and_two_workers(searched):
    spec, one = searched  # one worker
    two = run_design(spec, workers=2)
    assert [d.index for d in one.designs] == [d.index for d in two.designs]
    for a, b in zip(one.designs, two.designs, strict=True):
        assert a.scores == b.scores
        assert a.scenario == b.scenario
    assert one.failures == two.failures


def test_a_path_near_a_singularity_fails_the_path_condition(monkeypatch):
    """The shipped demo's arms keep their tool Jacobians' smallest singular values above 0.1
    along the task (numpy's SVD of Pinocchio's Jacobian); asked for 0.2, the design
    fails the ``path`` condition at the first pose below it, naming the arm."""
    import multiarm_pin.design.assessment as assessment

    problem = DesignProblem(load_design(TWO_UR5_SPEC))
    cand = candidate_from_scenario(problem, TWO_UR5_SCENARIO)
    e = assess(problem, cand)
    assert e.ok
    built = build_scenario(parse_scenario(e.scenario, problem.spec.file), load_visuals=False)
    sigma = []
    for q in e.path_q:
        for i, arm in enumerate(built.system.arms):
            J = pin.computeFrameJacobian(arm.model, arm.data, q[built.system.arm_set.q_slices[i]],
                                         arm.tool_frame_id, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
            sigma.append(np.linalg.svd(J, compute_uv=False)[-1])
    assert 0.1 < min(sigma) < 0.15
    monkeypatch.setattr(assessment, "MIN_SINGULAR_VALUE", 0.2)
    e = assess(problem, cand)
    assert not e.ok and e.condition == "path" and "near a singularity" in e.detail
    first = next(x for x in sigma if x < 0.2)  # the first pose and arm below, in task order
    assert e.value == pytest.approx(0.2 - first, abs=1e-9)


def test_the_branch_round_tries_every_other_branch_of_each_arm(searched):
    """For each parent and arm: the 7 branches other than its own, one re-seed each; a design
    found twice is ranked once."""
    from multiarm_pin.design.candidates import BRANCHES, branch_of
    from multiarm_pin.design.search import PARENTS, _branch_round, _distinct

    spec, result = searched
    problem = DesignProblem(spec)
    found = [d.assessment for d in result.pareto]
    recipes = _branch_round(problem, found, 10_000)
    assert [r[3] for r in recipes] == list(range(10_000, 10_000 + len(recipes)))
    parents = {r[1].index: r for r in recipes}
    assert 1 <= len(parents) <= PARENTS + len(SCORES)  # the best, and the best on each score
    for r in parents.values():
        parent = next(e for e in found if e.index == r[1].index)
        for arm, a in enumerate(parent.candidate.arms):
            g = problem.object_placement.act(a.points.mean(axis=0))
            own = branch_of(problem, arm, a.base, g, parent.q0[arm])
            tried = sorted(x[5] for x in recipes if x[1].index == parent.index and x[4] == arm)
            assert tried == [b for b in range(BRANCHES) if b != own]
    # a limit keeps whole parents, in order, the first one always
    def keys(rs):
        return [(r[1].index, *r[3:]) for r in rs]

    first = [r for r in recipes if r[1].index == recipes[0][1].index]
    assert len(parents) > 1 and len(first) == 14
    assert keys(_branch_round(problem, found, 10_000, len(first) + 13)) == keys(first)
    assert keys(_branch_round(problem, found, 10_000, 0)) == keys(first)

    def indices(es):
        return [e.index for e in es]

    assert indices(_distinct(found + found)) == indices(_distinct(found)) == indices(found)
