"""Feasibility checks against independent references: rnea + Jᵀw, the URDF's effort limits,
coal.distance on the same shapes and placements, and hand-placed collisions."""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET

import coal
import numpy as np
import pinocchio as pin
import pytest
import yaml

from multiarm_pin.app.runner import scenario_controller, simulate_built
from multiarm_pin.app.scenario import build_scenario
from multiarm_pin.app.scenario import load_scenario as load_scenario_file
from multiarm_pin.app.scenario.schema import parse_scenario
from multiarm_pin.exceptions import ScenarioError
from multiarm_pin.feasibility import CATEGORIES, CollisionScene, check_design, feasibility_report
from multiarm_pin.feasibility.collisions import GJK_TOLERANCE
from multiarm_pin.sim.controllers import make_controller
from tests.feasibility.collision_cases import assert_clearances_are_brute_force
from tests.run_helpers import write

DEMO = "scenarios/two_ur5_box.yaml"


def run_cli(*args):
    """``multiarm-pin ARGS`` in this process: ``(returncode, stdout, stderr)``."""
    import contextlib
    import io

    from multiarm_pin.app.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in args])
    return _Done(code, out.getvalue(), err.getvalue())


class _Done:
    def __init__(self, returncode, stdout, stderr):
        self.returncode, self.stdout, self.stderr = returncode, stdout, stderr


def _demo(mass=4.0, duration=0.02, extra=None):
    data = yaml.safe_load(open(DEMO, encoding="utf-8"))
    data["object"]["mass"] = mass
    data["controller"] = {"type": "object_pd", "kp": 100.0, "kd": 20.0}  # hold it still
    data["simulation"]["duration"] = duration
    data.update(extra or {})
    return data


@pytest.fixture(scope="module")
def held():
    built = build_scenario(parse_scenario(_demo(), DEMO), load_visuals=False)
    ctrl = make_controller("object_pd", built.system, kp=100.0, kd=20.0)
    result = simulate_built(built, ctrl, 0.02, 0.002, "object_first")
    return built, result


def _urdf_efforts(arm) -> dict:
    from multiarm_pin.feasibility.arm_geometry import _loader_paths

    urdf = _loader_paths("ur5")[0]
    root = ET.parse(urdf).getroot()
    return {j.get("name"): float(j.find("limit").get("effort")) for j in root.iter("joint")
            if j.find("limit") is not None}


def test_torques_are_gravity_plus_jacobian_transpose_wrench(held):
    built, result = held
    system = built.system
    for i, arm in enumerate(system.arms):
        sq, sv = system.arm_set.q_slices[i], system.arm_set.v_slices[i]
        N = int(system.constraint_set.N[i])
        data = arm.model.createData()
        for k in range(len(result.t)):
            q, v, qdd = result.q[k, sq], result.v[k, sv], result.qdd[k, sv]
            tool = arm.tool_placement(q).translation
            f = result.mu[k, i, :N, None] * result.normals[k, i, :N]  # on the object
            r = result.contact_points[k, i, :N] - tool
            w = np.concatenate([f.sum(axis=0), np.cross(r, f).sum(axis=0)])
            pin.computeJointJacobians(arm.model, data, q)
            pin.framesForwardKinematics(arm.model, data, q)
            J = pin.getFrameJacobian(arm.model, data, arm.tool_frame_id,
                                     pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
            expected = pin.rnea(arm.model, data, q, v, qdd) + J.T @ w
            np.testing.assert_allclose(result.tau[k, sv], expected, rtol=0, atol=1e-8)
    assert np.abs(result.qdd).max() < 1e-3  # held still: rnea is the gravity torque


def test_peak_torque_ratio_from_urdf_effort(held):
    built, result = held
    report = feasibility_report(built.system, result)
    assert report.feasible, report.violations
    efforts = _urdf_efforts(built.arms[0])
    for i, arm in enumerate(built.system.arms):
        tau = result.tau[:, built.system.arm_set.v_slices[i]]
        for c, name in enumerate(list(arm.model.names)[1:]):
            ratio = np.abs(tau[:, c]).max() / efforts[name]
            assert report.limits[arm.name][name]["peak_torque_ratio"] == pytest.approx(
                ratio, rel=1e-12)


def _geometry_placement(scene, g, state):
    """World placement of geometry g computed from the arm's own model (not the scene's)."""
    o = scene.hull.geometryObjects[g]
    if scene.names[g] == "object":
        return pin.SE3(state.obj.rotation, state.obj.position)
    if scene.owner[g] < 0:
        return o.placement
    i = scene.owner[g]
    arm = scene.system.arms[i]
    ag = scene.arm_geometry[i]
    local = g - sum(len(x.names) for x in scene.arm_geometry[:i])
    ao = ag.hull.geometryObjects[local]
    data = arm.model.createData()
    pin.forwardKinematics(arm.model, data, state.q[scene.system.arm_set.q_slices[i]])
    return data.oMi[ao.parentJoint] * ao.placement


def _coal_distance(scene, k, state):
    a, b = (int(x) for x in scene.pairs[k])
    ta, tb = (_geometry_placement(scene, g, state) for g in (a, b))
    ga, gb = scene.hull.geometryObjects[a].geometry, scene.hull.geometryObjects[b].geometry
    req = coal.DistanceRequest()
    req.gjk_tolerance = GJK_TOLERANCE
    return coal.distance(ga, coal.Transform3s(ta.rotation, ta.translation), gb,
                         coal.Transform3s(tb.rotation, tb.translation), req,
                         coal.DistanceResult())


def test_clearances_equal_coal_distance(held):
    built, result = held
    system = built.system
    scene = CollisionScene(system, built.initial_state)
    report = check_design(system, built.initial_state, scene=scene)
    run = feasibility_report(system, result, scene=scene)
    for ci, name in enumerate(CATEGORIES):
        cols = np.flatnonzero((scene.category == ci) & ~scene.grasp_pair)
        if not len(cols):
            assert report.clearance[name] is None
            continue
        at0 = min(_coal_distance(scene, k, built.initial_state) for k in cols)
        assert report.clearance[name] == pytest.approx(at0, abs=1e-9)
        along = min(_coal_distance(scene, k, result.state(s)) for k in cols
                    for s in range(len(result.t)))
        assert run.clearance[name] == pytest.approx(along, abs=1e-9)
        assert run.clearance[name] > 0


def test_four_tonne_box_is_infeasible_and_stop_exits_1(tmp_path):
    f = write(tmp_path / "heavy.yaml", yaml.safe_dump(_demo(mass=4000.0, duration=0.01)))
    p = run_cli("run", f, "--out", tmp_path / "r", "--no-html", "--quiet")
    assert p.returncode == 0, p.stderr
    s = json.loads((tmp_path / "r" / "summary.json").read_text())
    assert s["feasible"] is False and "NOT FEASIBLE" in p.stdout
    kinds = {v["kind"] for v in s["violations"]}
    assert "torque" in kinds
    v = next(v for v in s["violations"] if v["kind"] == "torque")
    assert abs(v["value"]) > v["limit"] and v["t_first"] == 0.0
    f2 = write(tmp_path / "heavy_stop.yaml", yaml.safe_dump(
        _demo(mass=4000.0, duration=0.01, extra={"limits": {"torque": "stop"}})))
    p = run_cli("run", f2, "--out", tmp_path / "r2", "--no-html", "--quiet")
    assert p.returncode == 1, p.stderr
    s = json.loads((tmp_path / "r2" / "summary.json").read_text())
    assert s["status"] == "failed" and "limits.torque" in s["error"] and s["t_end"] == 0.0


def _one_ur5(tmp_path, name, q0, pose, extra=""):
    text = f"""name: {name}
object:
  shape: {{type: box, size: [0.4, 0.3, 0.2]}}
  mass: 1.0
  pose: {{position: {pose}}}
arms:
  - name: a
    robot: ur5
    q0: {q0}
    joint: {{type: weld}}
controller: {{type: gravity_compensation}}
simulation: {{duration: 0.02, dt: 0.002}}
{extra}"""
    return write(tmp_path / f"{name}.yaml", text)


@pytest.mark.parametrize("case, q0, pose, extra, pair", [
    ("base_in_box", [0.0, -1.2, 1.6, -0.4, 1.57, 0.0], [0.0, 0.0, 0.05], "",
     ("a/base_link", "object")),
    ("link_under_ground", [0.0, 0.6, 0.0, 0.0, 0.0, 0.0], [1.5, 0.0, 1.0], "",
     ("a/", "ground")),
])
def test_hand_placed_collisions_at_start_exit_2(tmp_path, case, q0, pose, extra, pair):
    f = _one_ur5(tmp_path, case, q0, pose, extra)
    p = run_cli("run", f, "--out", tmp_path / "r", "--no-html", "--quiet")
    assert p.returncode == 2, p.stdout + p.stderr
    assert "collide at the initial state" in p.stderr
    assert re.search(rf"{pair[0]}\S* and {pair[1]} interpenetrate by [0-9.]+ mm", p.stderr), \
        p.stderr


def test_two_arms_crossing_named(tmp_path):
    # the right arm stands upright under the left one's forearm (two meshes overlapping)
    data = _demo()
    data["arms"][1]["base"]["position"] = [0.3, 0.3, 0.0]
    data["arms"][1]["joint"] = {"type": "weld"}
    data["arms"][1]["q0"] = [0.0, -1.57, 0.0, -1.57, 0.0, 0.0]
    del data["arms"][1]["q_seed"]
    f = write(tmp_path / "crossing.yaml", yaml.safe_dump(data))
    p = run_cli("run", f, "--out", tmp_path / "r", "--no-html", "--quiet")
    assert p.returncode == 2, p.stdout + p.stderr
    assert "collide at the initial state" in p.stderr
    assert re.search(r"left/forearm_link and right/upper_arm_link interpenetrate by [0-9.]+ mm",
                     p.stderr), p.stderr


def test_fingertip_inside_the_table_named(tmp_path):
    # pick_from_table's stand under the whole bottom face: the -z fingertip is inside it
    data = yaml.safe_load(open("scenarios/pick_from_table.yaml", encoding="utf-8"))
    data["supports"][0]["points"] = "vertices"
    for arm in data["arms"]:
        arm["urdf"] = str((__import__("pathlib").Path("scenarios") / arm["urdf"]).resolve())
    f = write(tmp_path / "table.yaml", yaml.safe_dump(data))
    p = run_cli("run", f, "--out", tmp_path / "r", "--no-html", "--quiet")
    assert p.returncode == 2, p.stdout + p.stderr
    assert re.search(r"three_finger/fingertip_3 and table interpenetrate by [0-9.]+ mm",
                     p.stderr), p.stderr


def test_collision_along_a_run_has_its_time_and_stop_exits_1(tmp_path):
    # the demo lowered to the floor: the arms' wrists reach the ground on the way
    data = _demo(duration=0.6)
    data["controller"]["waypoints"] = [{"t": 0.6, "position": [0.5, 0.0, 0.05]}]
    f = write(tmp_path / "down.yaml", yaml.safe_dump(data))
    p = run_cli("run", f, "--out", tmp_path / "r", "--no-html", "--quiet")
    assert p.returncode == 0, p.stderr
    s = json.loads((tmp_path / "r" / "summary.json").read_text())
    hits = [v for v in s["violations"] if v["kind"] == "collision" and v["other"] == "ground"]
    assert hits and s["feasible"] is False, s["violations"]
    t_first = min(v["t_first"] for v in hits)
    assert 0.0 < t_first < 0.6 and s["clearance"]["arm_ground"] < 0
    data["limits"] = {"collision": "stop"}
    f = write(tmp_path / "down_stop.yaml", yaml.safe_dump(data))
    p = run_cli("run", f, "--out", tmp_path / "r2", "--no-html", "--quiet")
    assert p.returncode == 1, p.stderr
    s2 = json.loads((tmp_path / "r2" / "summary.json").read_text())
    assert s2["status"] == "failed" and "limits.collision" in s2["error"]
    assert s2["t_end"] == pytest.approx(min(v["t_first"] for v in s2["violations"]
                                            if v["kind"] == "collision"))


def test_scenario_limits_and_ground_keys_are_validated():
    data = _demo()
    data["limits"] = {"torque": "clip"}
    with pytest.raises(ScenarioError, match=r"limits\.torque"):
        parse_scenario(data, "x.yaml")
    data["limits"] = {"speed": "stop"}
    with pytest.raises(ScenarioError, match=r"limits"):
        parse_scenario(data, "x.yaml")
    data["limits"] = {"collision": "stop"}
    data["ground"] = None
    sc = parse_scenario(data, "x.yaml")
    assert sc.limits.stops() == ("collision",) and sc.ground is None
    data["ground"] = {"height": -0.1}
    assert parse_scenario(data, "x.yaml").ground == -0.1


def test_a_base_rests_on_the_ground_it_stands_on(held):
    built, _ = held
    on = check_design(built.system, built.initial_state)  # every UR5 base mesh reaches below 0
    assert on.feasible and on.clearance["arm_ground"] > 0
    scene = CollisionScene(built.system, built.initial_state, ground=0.0)
    names = {scene.pair_names(k) for k in range(len(scene.pairs))}
    assert ("left", "base_link", "ground") not in names
    raised = check_design(built.system, built.initial_state, ground=0.05)  # not its floor
    pairs = {(v.arm, v.link, v.other) for v in raised.violations if v.kind == "collision"}
    assert ("left", "base_link", "ground") in pairs and ("right", "base_link", "ground") in pairs


def test_scan_equals_every_pair_at_every_sample():
    # mp6 grippers (primitives placed off their joints) on a stand: the bounds that skip
    # samples against the brute force of every pair at every sample
    built = build_scenario(load_scenario_file("scenarios/pick_from_table.yaml"),
                           load_visuals=False)
    ctrl = scenario_controller(built)
    result = simulate_built(built, ctrl, 0.1, built.scenario.simulation.dt, "auto")
    scene = CollisionScene(built.system, built.initial_state)
    cps = [result.contact_points[:, i, :int(built.system.constraint_set.N[i])]
           for i in range(built.system.n_arms)]
    scan = scene.scan(result.q, result.object_position, result.object_quaternion, cps)
    brute = assert_clearances_are_brute_force(scene, result, scan)
    assert not scan.hits
    assert scan.measured < brute.size / 2  # most (sample, pair) were bounded, not measured


def test_arm_limits_are_the_urdf_limits_and_statistics_find_the_first_time(held):
    from multiarm_pin.feasibility.arm_geometry import _loader_paths
    from multiarm_pin.feasibility.limits import arm_limits, limit_statistics

    built, _ = held
    arm = built.arms[0]
    root = ET.parse(_loader_paths("ur5")[0]).getroot()
    urdf = {j.get("name"): j.find("limit") for j in root.iter("joint")
            if j.find("limit") is not None}
    lim = arm_limits(arm)
    for c, name in enumerate(lim.joints):
        tag = urdf[name]
        assert lim.effort[c] == float(tag.get("effort"))
        assert lim.velocity[c] == float(tag.get("velocity"))
        assert (lim.lower[c], lim.upper[c]) == (float(tag.get("lower")), float(tag.get("upper")))
    # synthetic samples: joint 1 passes its velocity limit at t = 0.3, joint 2 its upper
    # position limit at t = 0.2, joint 0 reaches exactly its effort limit (not beyond)
    t = np.linspace(0.0, 0.5, 6)
    q = np.zeros((6, 6))
    q[2:, 2] = lim.upper[2] + 0.01
    v = np.zeros((6, 6))
    v[3:, 1] = 1.5 * lim.velocity[1]
    tau = np.zeros((6, 6))
    tau[4, 0] = -lim.effort[0]
    stats = limit_statistics(lim, t, q, v, tau)
    assert stats[0].t_torque is None and stats[0].peak_torque_ratio == 1.0
    assert stats[1].t_velocity == pytest.approx(0.3) and stats[1].peak_velocity_ratio == 1.5
    assert stats[2].t_position == pytest.approx(0.2)
    assert stats[2].position_margin == pytest.approx(-0.01)


def test_a_run_ending_on_nan_is_checked_up_to_it(held):
    import dataclasses

    built, result = held
    q = result.q.copy()
    q[-1] = np.nan  # a failed run's last sample
    broken = dataclasses.replace(result, q=q)
    report = feasibility_report(built.system, broken)
    whole = feasibility_report(built.system, result)
    assert report.feasible and report.clearance.keys() == whole.clearance.keys()
    assert all(v is None or v >= whole.clearance[k] - 1e-12
               for k, v in report.clearance.items())
