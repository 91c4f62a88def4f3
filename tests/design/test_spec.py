"""Design spec files: what they hold, and errors that name the key path."""

import numpy as np
import pytest

from multiarm_pin.data import shipped_files
from multiarm_pin.design import load_design, parse_design
from multiarm_pin.design.spec import GRIPPERS
from multiarm_pin.exceptions import DesignError
from tests.design.design_cases import spec_data


def test_every_shipped_spec_is_valid():
    names = [p.name for p in shipped_files("scenarios/designs")]
    assert {"two_ur5_box.yaml", "three_ur5_box.yaml",
            "two_gripper_form_closure.yaml"} <= set(names)
    for f in shipped_files("scenarios/designs"):
        spec = load_design(f)
        assert spec.arms and spec.trajectory["times"][0] == 0.0


def test_arms_with_a_count_become_named_slots_and_grippers_their_hands():
    spec = parse_design(spec_data(), "s.yaml")
    assert [s.name for s in spec.arms] == ["ur5_0", "ur5_1"]
    assert all(s.gripper == "weld" and s.robot == "ur5" for s in spec.arms)
    d = spec_data()
    d["arms"] = [{"name": "hand", "gripper": {"fingertips": "mp6_4f"}}]
    slot = parse_design(d, "s.yaml").arms[0]
    assert slot.gripper == "fingertips" and slot.tips == GRIPPERS["mp6_4f"].tips
    assert slot.urdf.endswith("mp6_4f.urdf") and slot.tool_frame == "tool0"


def test_a_gripper_given_by_tip_positions_in_the_tool_frame():
    d = spec_data()
    tips = [[0.05, 0.0, 0.1], [-0.05, 0.0, 0.1], [0.0, 0.05, 0.12]]
    d["arms"] = [{"robot": "ur5", "gripper": {"fingertips": tips, "tip_radius": 0.01}}]
    slot = parse_design(d, "s.yaml").arms[0]
    assert slot.gripper == "fingertips" and slot.robot == "ur5" and slot.tip_radius == 0.01
    assert slot.tips == tuple(tuple(t) for t in tips)


def test_a_lift_task_is_one_waypoint_straight_up():
    d = spec_data()
    d["task"] = {"lift": 0.2, "duration": 1.5}
    spec = parse_design(d, "s.yaml")
    np.testing.assert_allclose(spec.trajectory["times"], [0.0, 1.5])
    np.testing.assert_allclose(spec.trajectory["positions"][1] - spec.trajectory["positions"][0],
                               [0.0, 0.0, 0.2])


@pytest.mark.parametrize("edit, key, words", [
    (lambda d: d["bases"]["region"].update(x=[1.0, 0.0]), "bases.region.x", "lo <= hi"),
    (lambda d: d["bases"].update(yaw="any"), "bases.yaw", "free"),
    (lambda d: d["arms"][0].update(gripper={"fingertips": "mp6_5f"}),
     "arms[0].gripper.fingertips", "did you mean"),
    (lambda d: d.update(weights={"torque": 1.0}), "weights.torque", "torque_ratio"),
    (lambda d: d["task"].update(lift=0.1), "task", "exactly one of 'lift'"),
    (lambda d: d.update(search={"candidates": 0}), "search.candidates", "positive"),
    (lambda d: d["object"].update(mass=-1), "object.mass", "positive"),
    (lambda d: d.update(bases={"fixed": [{"position": [0, 0, 0]}]}), "bases.fixed",
     "expected 2 base placements"),
    (lambda d: d["arms"][0].update(gripper={"fingertips": [[0, 0, 0.1], [0, 0.1]]}),
     "arms[0].gripper.fingertips[1]", "expected 3 numbers"),
    (lambda d: d["arms"][0].update(gripper={"fingertips": [[0, 0, 0.1], 3, [0, 0, 0.2]]}),
     "arms[0].gripper.fingertips[1]", "a frame name or a fingertip centre [x, y, z]"),
    (lambda d: d["arms"][0].update(gripper={"fingertips": [[0, 0, 0.1], [0, 0.1, 0.1]]}),
     "arms[0].gripper.fingertips", "at least 3 tips"),
    (lambda d: d["task"].update(waypoints=[{"t": 1.0, "position": [0, 0, 1]},
                                           {"t": 0.5, "position": [0, 0, 1]}]),
     "task.waypoints[1].t", "increase strictly"),
])
def test_errors_name_the_key_path(edit, key, words):
    d = spec_data()
    edit(d)
    with pytest.raises(DesignError) as info:
        parse_design(d, "spec.yaml")
    assert info.value.key == key
    assert words in str(info.value)
    assert str(info.value).startswith("spec.yaml: ")


def test_the_command_refuses_a_bad_spec_with_exit_2(tmp_path, capsys):
    import yaml

    from multiarm_pin.app.cli import main

    d = spec_data()
    d["bases"]["region"]["y"] = [0.5]
    spec = tmp_path / "bad.yaml"
    spec.write_text(yaml.safe_dump(d), encoding="utf-8")
    assert main(["design", str(spec), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert f"{spec}: bases.region.y: expected 2 numbers" in err
    assert not (tmp_path / "out").exists()


def test_fingertip_grippers_need_a_box():
    d = spec_data()
    d["object"]["shape"] = {"type": "polyhedron", "vertices": [
        [0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]}
    d["arms"] = [{"name": "hand", "gripper": {"fingertips": "mp6_3f"}}]
    with pytest.raises(DesignError) as info:
        parse_design(d, "spec.yaml")
    assert info.value.key == "arms" and "corner of a box" in str(info.value)
