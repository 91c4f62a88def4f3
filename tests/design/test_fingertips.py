"""Fingertip designs (the shipped mp6 hands): rigid grips, closure re-checked independently."""

import json

import numpy as np
import pinocchio as pin
import pytest
import yaml

from multiarm_pin.app.cli import main
from multiarm_pin.data import data_path
from multiarm_pin.design import load_design, parse_design, run_design
from multiarm_pin.design.assessment import DesignProblem, assess, candidate_from_scenario
from multiarm_pin.design.candidates import corner_assignments, fit_gripper
from tests.design.design_cases import (
    UR5_TIPS,
    recheck_fingertip_design,
    small,
    ur5_tips_spec_data,
)

SPEC = data_path("scenarios", "designs", "two_gripper_form_closure.yaml")


@pytest.fixture(scope="module")
def searched():
    spec = small(load_design(SPEC), candidates=12, refine=1, polish=1)
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
    e = assess(problem, candidate_from_scenario(
        problem, data_path("scenarios", "two_gripper_form_closure.yaml")))
    assert e.ok, (e.condition, e.detail)
    assert e.scores["lp_margin"] == pytest.approx(0.0479, abs=5e-4)  # the scenario's comment
    assert e.scores["ferrari_canny"] > 0 and e.scores["stability"] > 0


def test_fingertip_designs_pass_independent_rechecks(searched):
    spec, result = searched
    assert result.designs
    problem = DesignProblem(spec)
    for d in result.designs:
        recheck_fingertip_design(spec, problem, d)


def test_a_gripper_given_by_tip_positions_on_a_ur5_designs_and_runs(tmp_path):
    """Tips as points in the UR5's tool frame: the rigid gripper is fitted at a box corner,
    its designs pass the independent re-checks, and the best runs through the task as
    ``multiarm-pin run`` reads it."""
    spec = parse_design(ur5_tips_spec_data(), str(tmp_path / "ur5_tips.yaml"))
    assert spec.arms[0].tips == tuple(tuple(t) for t in UR5_TIPS)
    result = run_design(spec)
    assert result.designs
    problem = DesignProblem(spec)
    np.testing.assert_allclose(problem.tips_in_tool[0], UR5_TIPS)
    for d in result.designs:
        contacts = d.scenario["arms"][0]["joint"]["contacts"]
        assert [c["tip"] for c in contacts] == UR5_TIPS  # points, no frames, no URDF
        recheck_fingertip_design(spec, problem, d)
    path = tmp_path / "design_1.yaml"
    path.write_text(yaml.safe_dump(result.designs[0].scenario), encoding="utf-8")
    out = tmp_path / "run"
    assert main(["run", str(path), "--out", str(out), "--quiet", "--no-html"]) == 0
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert summary["status"] == "complete" and summary["feasible"] is True
