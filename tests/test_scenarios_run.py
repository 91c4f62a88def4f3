"""Every worked example in scenarios/ runs (short) and passes physical checks."""

from pathlib import Path

import numpy as np
import pytest

from multiarm_pin.app.runner import run_scenario
from multiarm_pin.app.scenario import load_scenario
from multiarm_pin.exceptions import ScenarioError
from multiarm_pin.spatial import quaternion_to_rotation

SCENARIOS = sorted((Path(__file__).resolve().parent.parent / "scenarios").glob("*.yaml"))
DURATION = 0.1


def test_the_examples_are_there():
    names = {p.stem for p in SCENARIOS}
    assert {"two_ur5_box", "three_ur5_box", "revolute_handle", "ur5_panda_box",
            "mp6_pair_box"} <= names


COLLIDING: dict[str, str] = {}
"""Shipped scenarios whose initial state collides (refused as bad input), with why."""


@pytest.mark.parametrize("path", [
    pytest.param(p, marks=pytest.mark.xfail(reason=COLLIDING[p.stem], strict=True,
                                            raises=ScenarioError))
    if p.stem in COLLIDING else p for p in SCENARIOS], ids=[p.stem for p in SCENARIOS])
def test_scenario_runs_and_is_physical(path, tmp_path):
    sc = load_scenario(path)
    assert all(a.q0 is None for a in sc.arms), "examples place their arms by IK"
    res = run_scenario(path, tmp_path, duration=DURATION, html=False, plots=False)
    r, s, built = res.result, res.summary, res.built
    assert s["finite"]
    assert s["feasible"], s["violations"]  # within the URDF's limits, nothing colliding
    assert all(v is None or v > 0 for v in s["clearance"].values()), s["clearance"]
    assert s["steps"] == round(DURATION / sc.simulation.dt)
    assert s["max_constraint_violation"] < 1e-6
    # Newton-Euler of the object from the recorded forces (independent of the solver):
    # m a = m g + sum of contact forces (+ the external force, if any); I_w w_dot + w x I_w w =
    # sum of moments about the COM (+ the external moment, applied at the COM)
    m = built.obj.mass
    tr = res.trajectory
    f = tr["contact_forces"]
    p = tr["contact_points"]
    ext = tr["external_wrench"]
    lin = m * r.object_acceleration[:, :3] - (f.sum(axis=1) + m * sc.gravity + ext[:, :3])
    scale = np.abs(f).max() + m * 9.81
    assert np.abs(lin).max() < 1e-6 * scale
    moments = np.cross(p - tr["object_position"][:, None, :], f).sum(axis=1) + ext[:, 3:]
    for k in (0, len(r.t) // 2, len(r.t) - 1):
        Rk = quaternion_to_rotation(r.object_quaternion[k])
        Iw = Rk @ built.obj.inertia @ Rk.T
        w = r.object_twist[k, 3:]
        ang = Iw @ r.object_acceleration[k, 3:] + np.cross(w, Iw @ w) - moments[k]
        assert np.abs(ang).max() < 1e-6 * scale
    # object_pd scenarios follow their reference at the start (no jump)
    if sc.controller.type == "object_pd":
        assert np.linalg.norm(r.object_position[-1] - r.object_position[0]) < 0.05
    # unilateral fingertips must push while they touch (a gripper that starts apart,
    # tilt_pick's, carries no force until it touches down)
    if built.system.unilateral.any():
        n, uni = built.system.n_arms, built.system.unilateral
        touching = r.active[:, :n, :uni.shape[1]] & uni
        assert r.mu[:, :n, :uni.shape[1]][touching].min() > 0
        assert s["min_unilateral_contact_force"] >= 0


def test_fingertip_grasp_is_form_closure():
    from multiarm_pin.app.scenario import build_scenario
    from multiarm_pin.grasp import form_closure, wrench_matrix

    path = next(p for p in SCENARIOS if p.stem == "fingertips_form_closure")
    built = build_scenario(load_scenario(path))
    sys_ = built.system
    ct = sys_.blocks(built.initial_state).constraints
    mask = ct.mask
    assert mask.sum() == 7 and sys_.unilateral.sum() == 7
    com = built.initial_state.obj.position
    W = wrench_matrix(ct.contact_points[mask] - com, ct.normals[mask])
    res = form_closure(W)
    assert res.form_closure and res.rank == 6 and res.margin > 0.02
    # without the seventh contact the corners alone are not form closure (needs 7)
    assert not form_closure(W[:, :6], allow_fewer=True).form_closure
    # each fingertip sphere touches its face: centre 15 mm off the face plane (FK check)
    obj = built.obj.shape
    for spec, arm, q in zip(built.scenario.arms, built.arms, built.q0, strict=True):
        for c in spec.joint.contacts:
            p = arm.frame_placement(q, c.tip).translation - com
            assert obj.signed_distance_to_face(p, c.face) == pytest.approx(0.015, abs=1e-8)


FAILING_ON_PURPOSE = {"grasp_failure": "its README line: not feasible (joint velocities, then a "
                                       "gripper in its own wrist)"}
"""Shipped scenarios that show a failure on purpose, with why."""

WHOLE_RUN_ELSEWHERE = {"tilt_pick": "tests/test_tilt_pick.py runs it whole once (the Python "
                                    "stepper: the slowest run) and checks its feasibility"}
"""Shipped scenarios whose whole run another test checks, with where."""


@pytest.mark.parametrize("path", [p for p in SCENARIOS if p.stem not in WHOLE_RUN_ELSEWHERE],
                         ids=[p.stem for p in SCENARIOS if p.stem not in WHOLE_RUN_ELSEWHERE])
def test_every_shipped_scenario_is_feasible_over_its_whole_run(path):
    # no false alarms: within the URDF's limits and collision-free at every recorded sample
    # of the whole run (the test above runs 0.1 s of each)
    from multiarm_pin.app.run_feasibility import check_initial_state
    from multiarm_pin.app.runner import scenario_controller, simulate_built
    from multiarm_pin.app.scenario import build_scenario
    from multiarm_pin.feasibility import feasibility_report

    built = build_scenario(load_scenario(path), load_visuals=False)
    scene = check_initial_state(built)
    sim = built.scenario.simulation
    result = simulate_built(built, scenario_controller(built), sim.duration, sim.dt, sim.solver)
    assert result.t[-1] == pytest.approx(sim.duration)
    report = feasibility_report(built.system, result, ground=built.scenario.ground,
                                scene=scene)
    if path.stem in FAILING_ON_PURPOSE:
        assert not report.feasible
        return
    assert report.feasible, [v.describe() for v in report.violations]
    assert all(v is None or v > 0 for v in report.clearance.values()), report.clearance
