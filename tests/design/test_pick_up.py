"""The pick-up planner (design/pick_up.py, issue 27): tilt, insert under, lift.

Static checks re-done here by independent means: the final grasp's form closure by an LP of
scipy's (not the package's), the tips at every key pose by Pinocchio's forward kinematics
against targets built here from the phases, joint limits from the URDF models, the insert
tip's height by turning its lowest point with ``pin.exp3``. One plan is simulated against
the issue's "done when".
"""

from __future__ import annotations

import copy
import itertools
from functools import cache

import numpy as np
import pinocchio as pin
import pytest
import yaml
from scipy.optimize import linprog

from multiarm_pin.data import data_path
from multiarm_pin.design.pick_up import (
    INSERT_CLEARANCE,
    INSERT_DEPTH,
    Candidate,
    PickUpPlanner,
    grasp_wrenches,
    plan_pick_up,
    tilt_angle_range,
    use_tilt,
)
from multiarm_pin.design.spec import parse_design
from multiarm_pin.exceptions import DesignError, DesignImpossibleError
from tests.run_helpers import tilt_pick_event_times

SPEC = data_path("scenarios", "designs", "tilt_pick.yaml")

SHIPPED = ("+x", 0.12)
"""The shipped spec's plan checked here: its smallest tilt about +x that passes."""


def _data() -> dict:
    return copy.deepcopy(yaml.safe_load(SPEC.read_text(encoding="utf-8")))


def _spec(data=None):
    return parse_design(_data() if data is None else data, str(SPEC))


@cache
def _checked():
    planner = PickUpPlanner(_spec())
    return planner, planner.check(Candidate(0, *SHIPPED))


def _built(scenario):
    from multiarm_pin.app.scenario import build_scenario
    from multiarm_pin.app.scenario.schema import parse_scenario

    return build_scenario(parse_scenario(scenario, str(SPEC)), load_visuals=False)


def _closure(W: np.ndarray) -> bool:
    """Form closure (Eq 2.1): rank 6 and a strictly positive combination of the columns is
    zero (scipy's LP, each weight at least 1)."""
    res = linprog(np.zeros(W.shape[1]), A_eq=W, b_eq=np.zeros(6),
                  bounds=[(1, None)] * W.shape[1], method="highs")
    return np.linalg.matrix_rank(W) == 6 and res.status == 0


def test_the_tilt_angle_lifts_the_insert_tip_to_its_clearance():
    """At the smallest angle, the insert tip's lowest point (contact ``e`` in from the raised
    edge, 0.004 m further out, centre a radius plus INSERT_DEPTH below the bottom plane,
    lowest point a radius lower) turned about the pivot by ``pin.exp3`` is INSERT_CLEARANCE
    above the table; the largest is 0.6 of the tipping angle atan(a / c). ``e``: the side
    tips' centres are a radius off the -x and -y faces and ``s`` (the tip triangle's side,
    0.05 √3 m) apart along the diagonal plane ``x + y = const``, so ``s / √2`` apart along
    x; the bottom tip's centre is at their midpoint, ``s / (2 √2) - r`` in from the edge."""
    a, c, r = 0.4, 0.2, 0.015
    lo, hi = tilt_angle_range(a, c, r)
    e = 0.05 * np.sqrt(3) / (2 * np.sqrt(2)) - r
    p = np.array([-a + e - 0.004, 0.0, -c - INSERT_DEPTH - 2 * r])  # object frame
    pivot = np.array([a, 0.0, -c])
    z = (pin.exp3(np.array([0.0, lo, 0.0])) @ (p - pivot))[2]
    assert abs(z - INSERT_CLEARANCE) < 1e-12
    assert abs(hi - 0.6 * np.arctan(a / c)) < 1e-12


def test_the_shipped_spec_plans_a_statically_checked_scenario():
    """The plan about +x: every check met; the 13 final contacts are form closure (scipy's
    LP) and not without the bottom tip; at every key pose each arm's tips are on the targets
    built here from the phases' offsets and the object's pose (residual < 1e-6 m, by
    forward kinematics), within joint limits, joints moving < 0.5 rad between key poses;
    clearance at least the spec's margin."""
    planner, c = _checked()
    assert c.ok, (c.condition, c.detail)
    sc = c.scenario
    assert [p["name"] for p in sc["controller"]["phases"]] == [
        "rest", "tilt", "top", "insert", "close", "grip", "squeeze", "lift", "carry"]
    built = _built(sc)
    W = grasp_wrenches(built)
    assert W.shape[1] == 13 and _closure(W)
    assert not _closure(np.delete(W, 12, axis=1))  # the insert gripper's bottom tip
    # tips at the key poses, by forward kinematics
    arms = built.system.arm_set.arms
    M0 = planner.M0
    start = np.split(np.asarray(built.initial_state.q), np.cumsum([a.nq for a in arms])[:-1])
    poses = planner.key_poses(c.candidate, sc)
    assert len(poses) == len(c.key_q) == 12
    for k, (_, M, offs) in enumerate(poses):
        qs = np.split(c.key_q[k], np.cumsum([a.nq for a in arms])[:-1])
        for i, a in enumerate(arms):
            name = sc["arms"][i]["name"]
            ap = np.asarray(sc["arms"][i]["joint"].get("approach", np.zeros(3)))
            for t in [x["tip"] for x in sc["arms"][i]["joint"]["contacts"]]:
                pin.framesForwardKinematics(a.model, a.data, start[i])
                local = M0.actInv(a.data.oMf[a.model.getFrameId(t)].translation) - ap
                pin.framesForwardKinematics(a.model, a.data, qs[i])
                got = a.data.oMf[a.model.getFrameId(t)].translation
                assert np.linalg.norm(got - M.act(local + offs[name])) < 1e-6
            assert np.all(qs[i] >= a.model.lowerPositionLimit - 1e-9)
            assert np.all(qs[i] <= a.model.upperPositionLimit + 1e-9)
    assert np.abs(np.diff(c.key_q, axis=0)).max() < 0.5
    assert c.scores["clearance"] >= planner.spec.search.clearance
    assert c.scores["torque_ratio"] <= 0.75
    # the tilt: about the +x bottom edge, the -x side rises
    tilt = sc["controller"]["phases"][1]
    np.testing.assert_allclose(tilt["pivot"], [0.4, 0.0, 0.7], atol=1e-12)
    np.testing.assert_allclose(tilt["axis"], [0.0, 1.0, 0.0], atol=1e-12)


def _min_norm_nonnegative(W: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``argmin ‖μ‖`` with ``W μ = w``, ``μ >= 0``, by enumerating supports (K <= 10).

    The optimum ``μ*`` is the least-norm solution of ``W_S μ_S = w`` on its own support
    ``S`` (strictly positive there: a local, hence global, optimum of the problem without
    the signs); every other feasible restricted solution is no shorter.
    """
    best = None
    for mask in itertools.product((False, True), repeat=W.shape[1]):
        S = np.flatnonzero(mask)
        if not len(S):
            continue
        mu_S = np.linalg.lstsq(W[:, S], w, rcond=None)[0]
        if np.linalg.norm(W[:, S] @ mu_S - w) > 1e-9 * np.linalg.norm(w) or mu_S.min() < 0:
            continue
        if best is None or np.linalg.norm(mu_S) < np.linalg.norm(best):
            best = np.zeros(W.shape[1])
            best[S] = mu_S
    return best


def test_the_tilted_pose_static_torques_are_the_couples():
    """The plan's static torque ratio at the tilted key pose: the box held by the couple's
    six tips (the other hands apart) against the pivot edge's two vertices (the far ones
    are 0.8 sin 0.12 m up): the least-norm pushing forces balancing the weight (solved here
    by enumerating the supports), each arm's ``g(q) + Σ Jᵀ f`` (Pinocchio's gravity and
    LOCAL_WORLD_ALIGNED Jacobians at the tips' centres, on the force's line), over the
    URDF's effort limits: the largest equals the plan's to 1e-6."""
    from multiarm_pin.app.precheck import effort_limits

    planner, c = _checked()
    sc = c.scenario
    k = c.labels.index("tilt")
    M = planner.key_poses(c.candidate, sc)[k][1]
    arms = _built(sc).system.arm_set.arms
    qs = np.split(c.key_q[k], np.cumsum([a.nq for a in arms])[:-1])
    cols, tips = [], []
    for p in np.asarray(sc["supports"][0]["points"], float)[:2]:  # the pivot's vertices
        cols.append(np.r_[0.0, 0.0, 1.0, np.cross(M.act(p) - M.translation, [0, 0, 1.0])])
    for i in (0, 1):  # pusher, stop
        for con in sc["arms"][i]["joint"]["contacts"]:
            n = -M.rotation @ {"-x": [-1.0, 0, 0], "+x": [1.0, 0, 0]}[con["face"]]
            x = arms[i].frame_placement(qs[i], con["tip"]).translation
            cols.append(np.r_[n, np.cross(x - M.translation, n)])
            tips.append((i, con["tip"], n))
    weight = sc["object"]["mass"] * 9.81
    mu = _min_norm_nonnegative(np.array(cols).T, np.array([0, 0, weight, 0, 0, 0]))
    ratio = 0.0
    for i, a in enumerate(arms):
        tau = pin.computeGeneralizedGravity(a.model, a.data, qs[i]).copy()
        for j, (arm, tip, n) in enumerate(tips):
            if arm == i:
                J = pin.computeFrameJacobian(a.model, a.data, qs[i], a.model.getFrameId(tip),
                                             pin.LOCAL_WORLD_ALIGNED)[:3]
                tau += J.T @ (mu[2 + j] * n)
        ratio = max(ratio, float(np.max(np.abs(tau) / effort_limits(a))))
    assert mu[:2].min() > 1.0 and mu[2:].max() > 1.0  # the pivot and the couple carry it
    assert abs(ratio - c.scores["torque_ratios"]["tilt"]) < 1e-6
    assert set(c.scores["torque_ratios"]) == {"rest", "tilt", "carry"}


def test_a_turned_pivot_turns_the_whole_plan():
    """Pivot -y: the support rows 0, 1 are the -y bottom edge's vertices, the couple's faces
    are -y (stop) and +y (pusher), the tilt axis is along x and raises the +y side."""
    planner, _ = _checked()
    sc = planner.scenario(Candidate(0, "-y", 0.2))
    pts = np.array(sc["supports"][0]["points"])
    np.testing.assert_allclose(pts[:2, 1], -0.3)
    np.testing.assert_allclose(pts[2:, 1], 0.3)
    assert {c["face"] for c in sc["arms"][0]["joint"]["contacts"]} == {"+y"}
    assert {c["face"] for c in sc["arms"][1]["joint"]["contacts"]} == {"-y"}
    tilt = sc["controller"]["phases"][1]
    R = pin.exp3(np.asarray(tilt["axis"]) * tilt["angle"])
    raised = np.array([0.0, 0.3, 0.7]) - np.asarray(tilt["pivot"])
    assert (R @ raised)[2] > 0.05


def test_strategy_and_bad_specs():
    """``strategy: tilt`` always tilts; ``auto`` tilts when the table covers the bottom face
    and not when the box overhangs a small stand; a sphere, a tilted box, a box off the
    table or a spec without the couple's grippers is a DesignError naming the key."""
    assert use_tilt(_spec())
    d = _data()
    d["task"]["strategy"] = "auto"
    assert use_tilt(_spec(d))
    d["supports"][0]["points"] = [[0.3, 0.2, -0.2], [0.3, -0.2, -0.2], [-0.3, 0.2, -0.2],
                                  [-0.3, -0.2, -0.2]]
    del d["supports"][0]["extent"]
    assert not use_tilt(_spec(d))
    d["task"]["strategy"] = "tilt"
    assert use_tilt(_spec(d))
    bad = _data()
    bad["object"]["pose"]["position"] = [0.0, 0.0, 0.95]
    with pytest.raises(DesignError, match="supports"):
        _spec(bad)
    bad = _data()
    bad["arms"] = bad["arms"][1:]
    with pytest.raises(DesignError, match="arms"):
        _spec(bad)
    bad = _data()
    bad["bases"] = {"fixed": [{"position": [0, 0, 0]}] * 4}
    with pytest.raises(DesignError, match="bases.fixed"):
        _spec(bad)
    bad = _data()
    bad["task"]["strategy"] = "roll"
    with pytest.raises(DesignError, match="strategy"):
        _spec(bad)


def test_a_box_too_tall_to_tilt_is_reported_with_its_reason():
    """A 0.4 x 0.4 x 1.0 box: the tilt that lets a tip under the raised side exceeds 0.6 of
    the tipping angle about every edge; the planner says so, per edge, before any IK."""
    d = _data()
    d["object"]["shape"]["size"] = [0.4, 0.4, 1.0]
    d["object"]["pose"]["position"] = [0.0, 0.0, 1.2]
    d["supports"][0]["points"] = [[0.2, 0.2, -0.5], [0.2, -0.2, -0.5], [-0.2, 0.2, -0.5],
                                  [-0.2, -0.2, -0.5]]
    with pytest.raises(DesignImpossibleError, match="too tall") as exc:
        plan_pick_up(_spec(d), first=True)
    assert str(exc.value).count("too tall") == 4


DRAW_CASES = 6
"""Boxes drawn by the random-draw test (the benchmark draws more and simulates each)."""

IMPOSSIBLE_BOUND = 0.25
"""Largest fraction of drawn boxes the planner may report impossible (README)."""


def test_drawn_boxes_plan_or_say_why():
    """Boxes drawn in the README's range (edges 0.4-1.0 m, masses 1-8 kg, lying along the
    table's axes, the table 0.4 and 0.3 m wider on each side): each plans (every check met,
    the 13 contacts form closure by scipy's LP, clearance at least the margin, IK residual
    below 1e-6 m) or is reported impossible with its reason; at most IMPOSSIBLE_BOUND of
    them impossible."""
    from multiarm_pin.design.pick_up import with_box

    rng = np.random.default_rng(27)
    impossible = []
    for k in range(DRAW_CASES):
        size, mass = rng.uniform(0.4, 1.0, 3), rng.uniform(1.0, 8.0)
        spec = parse_design(with_box(_data(), size, mass), f"draw{k}")
        try:
            res = plan_pick_up(spec, first=True)
        except DesignImpossibleError as exc:
            assert "no tilt plan" in str(exc) and len(str(exc)) > 60
            impossible.append(str(exc))
            continue
        c = res.plans[0]
        assert c.ok and c.scores["ik_residual"] < 1e-6
        assert c.scores["clearance"] >= spec.search.clearance
        W = grasp_wrenches(_built(c.scenario))
        assert W.shape[1] == 13 and _closure(W)
    assert len(impossible) <= IMPOSSIBLE_BOUND * DRAW_CASES, impossible


def test_the_shipped_spec_simulates_the_issues_events():
    """The first plan of the shipped spec (+x, 0.12 rad) run through (the Python stepper):
    the far edge's vertices separate first, then the insert tip touches down on the bottom
    face, then the pivot's vertices separate; no contact force below zero; feasible; the
    final pose on the closed form (the start turned 0.12 rad about the +x bottom edge, then
    moved by (0.05, 0, 0.05) m) to 1e-3 m; every arm more than 1 cm clear of the whole table
    top."""
    from multiarm_pin.app.run_feasibility import check_initial_state
    from multiarm_pin.app.runner import scenario_controller, simulate_built
    from multiarm_pin.feasibility import feasibility_report

    res = plan_pick_up(_spec(), first=True)
    c = res.plans[0]
    assert (c.candidate.pivot, c.candidate.angle) == SHIPPED
    built = _built(c.scenario)
    scene = check_initial_state(built)
    sim = built.scenario.simulation
    run = simulate_built(built, scenario_controller(built), sim.duration, sim.dt, sim.solver)
    report = feasibility_report(built.system, run, ground=built.scenario.ground, scene=scene)
    assert report.feasible, [v.describe() for v in report.violations]
    assert report.clearance["arm_support"] > 0.01  # the whole table top
    far, bottom, pivot = tilt_pick_event_times(run.events)
    assert far < bottom < pivot
    assert run.mu.min() >= 0.0
    th = SHIPPED[1]
    R = pin.exp3(np.array([0.0, th, 0.0]))
    p = np.array([0.4, 0.0, 0.7])
    goal = p + R @ (np.array([0.0, 0.0, 0.9]) - p) + [0.05, 0.0, 0.05]
    assert np.linalg.norm(run.object_position[-1] - goal) < 1e-3


def test_the_design_command_writes_a_pick_up_folder(tmp_path):
    """``multiarm-pin design`` on a pick-up spec (one random base, --no-run): exit 0, a
    report naming the plans, plan.json, and design_1.yaml a scenario the reader builds
    whose tilt phase is the best plan's."""
    import json

    from multiarm_pin.app.cli import main
    from multiarm_pin.app.scenario import load_scenario

    d = _data()
    d["search"]["candidates"] = 1
    spec = tmp_path / "tilt_pick.yaml"
    spec.write_text(yaml.safe_dump(d), encoding="utf-8")
    out = tmp_path / "out"
    code = main(["design", str(spec), "--out", str(out), "--workers", "1", "--quiet",
                 "--no-run"])
    assert code == 0
    report = (out / "report.md").read_text(encoding="utf-8")
    assert "## Plans" in report and "Not simulated" in report
    plan = json.loads((out / "plan.json").read_text(encoding="utf-8"))
    assert plan["checked"] == 13 and plan["plans"]
    path = out / "designs" / "design_1.yaml"
    assert load_scenario(path).controller.type == "phased_pd"
    sc = yaml.safe_load(path.read_text(encoding="utf-8"))
    tilt = next(p for p in sc["controller"]["phases"] if p["kind"] == "tilt")
    assert abs(tilt["angle"] - plan["plans"][0]["angle"]) < 1e-12
