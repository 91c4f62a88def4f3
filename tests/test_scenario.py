"""Scenario files: validation messages (file, key path, expectation) and building."""

import copy
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import yaml

from multiarm_pin.app.scenario import build_scenario, did_you_mean, load_scenario, parse_scenario
from multiarm_pin.exceptions import ScenarioError

REPO = Path(__file__).resolve().parent.parent
HALF_PI = float(np.pi / 2)

BASE = {
    "name": "t",
    "object": {"shape": {"type": "box", "size": [0.8, 0.4, 0.3]}, "mass": 4.0,
               "pose": {"position": [0.5, 0.0, 0.35], "quaternion": [0, 0, 0, 1]}},
    "arms": [
        {"name": "left", "robot": "ur5", "tool_frame": "tool0",
         "base": {"position": [0.0, 0.55, 0.0], "rpy": [0, 0, 0]},
         "q_seed": [0.0, -1.2, 1.6, -0.4, 1.57, 0.0],
         "joint": {"type": "weld", "placement_in_object": {"position": [0.0, 0.2, 0.0],
                                                           "rpy": [HALF_PI, 0, 0]}}},
        {"name": "right", "robot": "ur5",
         "base": {"position": [0.0, -0.55, 0.0]},
         "q0": [0.0, -1.2, 1.6, -0.4, 1.57, 0.0],
         "joint": {"type": "weld"}},
    ],
    "controller": {"type": "none"},
    "simulation": {"duration": 0.1, "integrator": "rk4", "dt": 0.01, "solver": "object_first",
                   "baumgarte": {"alpha": 5.0, "beta": 5.0}},
}


def write(tmp_path, data, name="s.yaml"):
    p = tmp_path / name
    p.write_text(yaml.safe_dump(data), encoding="utf-8")
    return p


def error_of(tmp_path, data, build=False) -> ScenarioError:
    p = write(tmp_path, data)
    with pytest.raises(ScenarioError) as info:
        sc = load_scenario(p)
        if build:
            build_scenario(sc)
    err = info.value
    assert err.file == str(p)
    assert str(p) in str(err)
    return err


def test_valid_file_parses():
    sc = parse_scenario(copy.deepcopy(BASE), "x.yaml")
    assert sc.name == "t" and len(sc.arms) == 2
    assert sc.arms[1].tool_frame is None and sc.arms[0].q0 is None
    assert sc.simulation.baumgarte == (5.0, 5.0)
    assert np.allclose(sc.gravity, [0, 0, -9.81])


def test_typo_key_did_you_mean(tmp_path):
    d = copy.deepcopy(BASE)
    d["arms"][1]["jiont"] = d["arms"][1].pop("joint")
    err = error_of(tmp_path, d)
    assert err.key == "arms[1].jiont"
    assert "did you mean 'joint'" in str(err)
    d = copy.deepcopy(BASE)
    d["simulation"]["integrater"] = "rk4"
    err = error_of(tmp_path, d)
    assert err.key == "simulation.integrater" and "'integrator'" in str(err)


def test_typo_value_did_you_mean(tmp_path):
    d = copy.deepcopy(BASE)
    d["arms"][1]["joint"]["type"] = "revolut"
    err = error_of(tmp_path, d)
    assert err.key == "arms[1].joint.type"
    assert "did you mean 'revolute'" in str(err) and "weld" in str(err)


def test_wrong_type(tmp_path):
    d = copy.deepcopy(BASE)
    d["object"]["mass"] = "heavy"
    err = error_of(tmp_path, d)
    assert err.key == "object.mass" and "expected a number" in str(err)
    d = copy.deepcopy(BASE)
    d["arms"][0]["base"] = [0, 0, 0]
    err = error_of(tmp_path, d)
    assert err.key == "arms[0].base" and "expected a mapping" in str(err)


def test_quaternion_wrong_length(tmp_path):
    d = copy.deepcopy(BASE)
    d["object"]["pose"]["quaternion"] = [0, 0, 1]
    err = error_of(tmp_path, d)
    assert err.key == "object.pose.quaternion"
    assert "expected 4 numbers" in str(err) and "got 3" in str(err)
    d["object"]["pose"]["quaternion"] = [0, 0, 0, 2]
    err = error_of(tmp_path, d)
    assert "unit quaternion" in str(err)


def test_unknown_robot(tmp_path):
    d = copy.deepcopy(BASE)
    d["arms"][1]["robot"] = "ur55"
    err = error_of(tmp_path, d, build=True)
    assert err.key == "arms[1].robot"
    assert "unknown robot 'ur55'" in str(err) and "did you mean" in str(err)
    assert "panda" in str(err)


def test_missing_tool_frame(tmp_path):
    d = copy.deepcopy(BASE)
    d["arms"][0]["tool_frame"] = "tool1"
    err = error_of(tmp_path, d, build=True)
    assert err.key == "arms[0].tool_frame"
    assert "'tool1' not found" in str(err) and "did you mean 'tool0'" in str(err)
    d = copy.deepcopy(BASE)
    d["arms"][0] = {"urdf": "robots/mp6/mp6.urdf", "q0": [0] * 6, "joint": {"type": "weld"}}
    err = error_of(tmp_path, d)
    assert err.key == "arms[0].tool_frame" and "needs 'tool_frame'" in str(err)


def test_missing_q0_without_placement(tmp_path):
    d = copy.deepcopy(BASE)
    del d["arms"][1]["q0"]
    err = error_of(tmp_path, d)
    assert err.key == "arms[1].q0" and "placement_in_object" in str(err)


def test_inconsistent_initial_state_reports_gap(tmp_path):
    # the weld is placed in the object AND q0 is given: the tool is elsewhere
    d = copy.deepcopy(BASE)
    d["arms"][1]["joint"] = {"type": "weld", "placement_in_object": {
        "position": [0.0, -0.2, 0.0], "rpy": [-HALF_PI, 0, 0]}}
    err = error_of(tmp_path, d, build=True)
    assert err.key == "arms[1].q0"
    assert "inconsistent initial state" in str(err) and "gap" in str(err)
    gap = float(str(err).split("gap ")[1].split(" m")[0])
    assert abs(gap) > 1e-3


def test_wrong_q0_length(tmp_path):
    d = copy.deepcopy(BASE)
    d["arms"][1]["q0"] = [0.0] * 5
    err = error_of(tmp_path, d, build=True)
    assert err.key == "arms[1].q0" and "expected 6 numbers" in str(err)


def test_unreachable_placement(tmp_path):
    d = copy.deepcopy(BASE)
    d["arms"][0]["joint"]["placement_in_object"]["position"] = [0.0, 2.5, 0.0]
    err = error_of(tmp_path, d, build=True)
    assert err.key == "arms[0].joint.placement_in_object"
    assert "out of reach" in str(err) and "residual" in str(err)


def test_yaml_and_file_errors(tmp_path):
    p = tmp_path / "bad.yaml"
    p.write_text("name: [unclosed\n", encoding="utf-8")
    with pytest.raises(ScenarioError, match="YAML syntax"):
        load_scenario(p)
    with pytest.raises(ScenarioError, match="file not found"):
        load_scenario(tmp_path / "nope.yaml")
    d = copy.deepcopy(BASE)
    d["arms"] = []
    assert error_of(tmp_path, d).key == "arms"
    d = copy.deepcopy(BASE)
    d["arms"][1]["name"] = "left"
    assert "duplicate" in str(error_of(tmp_path, d))
    d = copy.deepcopy(BASE)
    d["controller"] = {"type": "object_pd", "kpp": 3}
    err = error_of(tmp_path, d)
    assert err.key == "controller.kpp" and "did you mean 'kp'" in str(err)


def test_did_you_mean():
    assert did_you_mean("integrater", ["integrator", "dt"]) == " (did you mean 'integrator'?)"
    assert did_you_mean("zzz", ["integrator"]) == ""


def test_build_places_tool_by_ik_and_welds_at_q0(tmp_path):
    built = build_scenario(load_scenario(write(tmp_path, copy.deepcopy(BASE))))
    oMo = pin.SE3(np.eye(3), np.array([0.5, 0.0, 0.35]))
    # arm 0 by IK: its tool is at placement_in_object in the object frame (FK check)
    rel = oMo.actInv(built.arms[0].tool_placement(built.q0[0]))
    assert np.allclose(rel.translation, [0.0, 0.2, 0.0], atol=1e-9)
    assert np.allclose(rel.rotation, pin.rpy.rpyToMatrix(HALF_PI, 0, 0), atol=1e-9)
    assert built.ik[0] is not None and built.ik[0].residual < 1e-9
    # arm 1 from q0: the weld holds the tool where it is
    assert built.ik[1] is None
    assert np.allclose(built.q0[1], BASE["arms"][1]["q0"])
    assert list(built.system.constraint_set.N) == [6, 6]
    built.system.check_initial_state(built.initial_state)


def test_fingertips_on_faces_by_ik(tmp_path):
    # an mp6 gripper puts its three fingertips on the +z face of a box, near three points
    d = {
        "object": {"shape": {"type": "box", "size": [0.6, 0.6, 0.3]}, "mass": 2.0,
                   "pose": {"position": [0.6, 0.0, 0.2]}},
        "arms": [{
            "name": "g", "urdf": str(REPO / "robots/mp6/mp6.urdf"), "tool_frame": "tool0",
            "q_seed": [0.0, 0.6, 1.0, 0.0, 1.4, 0.0],
            "joint": {"type": "contacts", "tip_radius": 0.015, "contacts": [
                {"tip": "fingertip_1", "face": "+z", "point": [0.05, 0.0, 0.15]},
                {"tip": "fingertip_2", "face": "+z", "point": [0.0, -0.05, 0.15]},
                {"tip": "fingertip_3", "face": "+z", "point": [0.0, 0.05, 0.15]}]}}],
    }
    built = build_scenario(load_scenario(write(tmp_path, d)))
    arm, q = built.arms[0], built.q0[0]
    # independent check: every fingertip sphere centre is 15 mm above the top face
    for f in ("fingertip_1", "fingertip_2", "fingertip_3"):
        z = arm.frame_placement(q, f).translation[2]
        assert z == pytest.approx(0.2 + 0.15 + 0.015, abs=1e-9)
    assert built.joints[0].kind == "fingertips"
    assert built.system.unilateral.sum() == 3
    d["arms"][0]["joint"]["contacts"][0]["tip"] = "fingertip_9"
    err = error_of(tmp_path, d, build=True)
    assert err.key == "arms[0].joint.contacts[0].tip" and "did you mean" in str(err)
    d["arms"][0]["joint"]["contacts"][0] = {"tip": "fingertip_1", "face": "+z",
                                            "point": [0.05, 0.0, 0.2]}
    err = error_of(tmp_path, d, build=True)
    assert err.key == "arms[0].joint.contacts[0].point" and "not on face" in str(err)


def test_fingertips_given_as_points_in_the_tool_frame(tmp_path):
    """A tip given as its centre in the tool frame is the same tip as the frame there: the
    mp6's fingertip frames, measured by Pinocchio, written as points, put the frames on the
    face (a rigid gripper: the points move with the tool)."""
    from multiarm_pin.model.arm import Arm

    urdf = str(REPO / "robots/mp6/mp6.urdf")
    arm = Arm.from_urdf(urdf, "tool0", load_visuals=False)
    model, data = arm.model, arm.model.createData()
    q = pin.neutral(model)
    pin.framesForwardKinematics(model, data, q)
    oMt = data.oMf[model.getFrameId("tool0")]
    names = ("fingertip_1", "fingertip_2", "fingertip_3")
    tips = [oMt.actInv(data.oMf[model.getFrameId(n)].translation).tolist() for n in names]
    points = ([0.05, 0.0, 0.15], [0.0, -0.05, 0.15], [0.0, 0.05, 0.15])
    d = {
        "object": {"shape": {"type": "box", "size": [0.6, 0.6, 0.3]}, "mass": 2.0,
                   "pose": {"position": [0.6, 0.0, 0.2]}},
        "arms": [{
            "name": "g", "urdf": urdf, "tool_frame": "tool0",
            "q_seed": [0.0, 0.6, 1.0, 0.0, 1.4, 0.0],
            "joint": {"type": "fingertips", "tip_radius": 0.015, "contacts": [
                {"tip": t, "face": "+z", "point": p} for t, p in zip(tips, points,
                                                                     strict=True)]}}],
    }
    built = build_scenario(load_scenario(write(tmp_path, d)))
    assert [c.tip for c in built.scenario.arms[0].joint.contacts] == ["tip0", "tip1", "tip2"]
    qk = built.q0[0]
    pin.framesForwardKinematics(model, data, qk)
    for n in names:  # every fingertip frame's centre 15 mm above the top face
        assert data.oMf[model.getFrameId(n)].translation[2] == pytest.approx(
            0.2 + 0.15 + 0.015, abs=1e-9)
    assert built.joints[0].kind == "fingertips"
    assert built.system.unilateral.sum() == 3
    built.system.check_initial_state(built.initial_state)
    # bad tips: a wrong length, neither a name nor a point
    d["arms"][0]["joint"]["contacts"][1]["tip"] = [0.0, 0.1]
    err = error_of(tmp_path, d)
    assert err.key == "arms[0].joint.contacts[1].tip" and "expected 3 numbers" in str(err)
    d["arms"][0]["joint"]["contacts"][1]["tip"] = 7
    err = error_of(tmp_path, d)
    assert err.key == "arms[0].joint.contacts[1].tip"
    assert "a frame name or the tip's centre [x, y, z] in the tool frame" in str(err)


# ----------------------------------------------------------------------------- issue 13
def _three_joint_ur5(joint_type, position):
    d = copy.deepcopy(BASE)
    d["arms"] = [{"name": "short", "robot": "ur5", "base": {"position": [0.0, 0.55, 0.0]},
                  "locked_joints": ["wrist_1_joint", "wrist_2_joint", "wrist_3_joint"],
                  "q_seed": [0.0, -1.0, 1.2],
                  "joint": {"type": joint_type,
                            "placement_in_object": {"position": position, "rpy": [1.0, 0, 0]}}}]
    return d


def test_spherical_joint_places_a_three_joint_arm(tmp_path):
    """The issue's case: a 3-joint arm asked for a full 6-D pose was "out of reach"."""
    from multiarm_pin.model.arm import Arm

    arm = Arm.from_robot_name("ur5", locked_joints=("wrist_1_joint", "wrist_2_joint",
                                                    "wrist_3_joint"), load_visuals=False,
                              base_placement=pin.SE3(np.eye(3), np.array([0.0, 0.55, 0.0])))
    # a point the 3-joint arm reaches, in the object frame (object at [0.5, 0, 0.35])
    p_world = arm.tool_placement(np.array([-0.4, -0.9, 1.1])).translation
    p_obj = (p_world - [0.5, 0.0, 0.35]).tolist()
    built = build_scenario(load_scenario(write(tmp_path, _three_joint_ur5("spherical", p_obj))))
    assert built.arms[0].nv == 3
    q = built.q0[0]
    assert np.linalg.norm(built.arms[0].tool_placement(q).translation - p_world) < 1e-9
    # the same point as a weld (position + rpy) is out of reach for 3 joints
    err = error_of(tmp_path, _three_joint_ur5("weld", p_obj), build=True)
    assert err.key == "arms[0].joint.placement_in_object" and "out of reach" in str(err)


def test_weld_inside_the_object_is_a_warning(tmp_path):
    from multiarm_pin.app.scenario_checks import input_warnings

    d = copy.deepcopy(BASE)
    d["arms"][0]["joint"]["placement_in_object"]["position"] = [0.0, 0.15, 0.0]  # 5 cm in
    built = build_scenario(load_scenario(write(tmp_path, d)))
    warns = input_warnings(built, 0.1)
    assert len(warns) == 1
    assert "arms[0].joint.placement_in_object: the joint frame is 0.05 m inside the object" \
        in warns[0]
    ok = build_scenario(load_scenario(write(tmp_path, copy.deepcopy(BASE), "ok.yaml")))
    assert input_warnings(ok, 0.1) == []  # on the surface: no warning


def test_simulation_compiled_is_a_boolean(tmp_path):
    assert parse_scenario(copy.deepcopy(BASE), "x.yaml").simulation.compiled is True
    data = copy.deepcopy(BASE)
    data["simulation"]["compiled"] = False
    assert parse_scenario(data, "x.yaml").simulation.compiled is False
    data["simulation"]["compiled"] = "no"
    err = error_of(tmp_path, data)
    assert err.key == "simulation.compiled" and "true or false" in str(err)
