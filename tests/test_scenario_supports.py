"""Scenario keys of issue 12: supports, external wrenches, per-joint unilateral, no arms."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import yaml

from multiarm_pin.app.runner import run_scenario
from multiarm_pin.app.scenario import build_scenario, load_scenario
from multiarm_pin.exceptions import ScenarioError

BOX = {
    "name": "box",
    "object": {"shape": {"type": "box", "size": [0.4, 0.3, 0.2]}, "mass": 2.0,
               "pose": {"position": [0.0, 0.0, 0.1]}},
    "arms": [],
    "supports": [{"name": "table", "plane": {"point": [0, 0, 0], "normal": [0, 0, 1]},
                  "points": "vertices", "restitution": 0.0}],
    "simulation": {"duration": 0.02, "dt": 0.01},
}


def _with(path: str, value):
    data = copy.deepcopy(BOX)
    keys = path.split(".")
    node = data
    for k in keys[:-1]:
        node = node[int(k)] if k.isdigit() else node[k]
    last = keys[-1]
    node[int(last) if last.isdigit() else last] = value
    return data


def _error(tmp_path, data, build=False) -> ScenarioError:
    p = tmp_path / "s.yaml"
    p.write_text(yaml.safe_dump(data), encoding="utf-8")
    with pytest.raises(ScenarioError) as info:
        sc = load_scenario(p)
        if build:
            build_scenario(sc)
    assert info.value.file == str(p) and str(p) in str(info.value)
    return info.value


@pytest.mark.parametrize(("path", "value", "key", "text"), [
    ("supports.0.plane.normal", [0, 0, 0], "supports[0].plane.normal", "zero length"),
    ("supports.0.restitution", 1.2, "supports[0].restitution", "in [0, 1]"),
    ("supports.0.restitution", -0.5, "supports[0].restitution", ">= 0"),
    ("supports.0.points", [[0, 0]], "supports[0].points", "(n, 3)"),
    ("supports.0.points", [[0, 0, 0, 1]], "supports[0].points", "(n, 3)"),
    ("supports.0.points", "corners", "supports[0].points", "'vertices'"),
    ("object.external_wrench", [{"from": 0.2, "to": 0.1, "wrench": [0] * 6}],
     "object.external_wrench[0].to", "to > from"),
    ("object.external_wrench", [{"from": 0, "to": 1, "wrench": [1, 2, 3]}],
     "object.external_wrench[0].wrench", "(6,)"),
])
def test_bad_support_and_wrench_keys(tmp_path, path, value, key, text):
    err = _error(tmp_path, _with(path, value))
    assert err.key == key and text in str(err)


def test_object_penetrating_a_support_names_it(tmp_path):
    err = _error(tmp_path, _with("object.pose.position", [0.0, 0.0, 0.09]), build=True)
    assert err.key == "supports[0].points"
    assert "penetrating support 'table'" in str(err) and "0.01 m below" in str(err)


def test_no_arms_and_no_supports_is_refused(tmp_path):
    err = _error(tmp_path, _with("supports", []))
    assert err.key == "arms" and "non-empty list of arms" in str(err)


def test_controller_without_arms_is_refused(tmp_path):
    p = tmp_path / "s.yaml"
    p.write_text(yaml.safe_dump(_with("controller", {"type": "gravity_compensation"})),
                 encoding="utf-8")
    with pytest.raises(ScenarioError, match="no arms, so no controller") as info:
        run_scenario(p, tmp_path / "out", html=False, plots=False)
    assert info.value.key == "controller.type"


def test_box_resting_on_vertices_runs_without_arms(tmp_path):
    """Eight vertex rows, four touching: at rest, they carry m g, the summary lists them."""
    p = tmp_path / "s.yaml"
    p.write_text(yaml.safe_dump(BOX), encoding="utf-8")
    res = run_scenario(p, tmp_path / "out", html=False, plots=True)
    s = res.summary
    assert s["events"] == [] and s["supports"][0]["points"] == 8
    np.testing.assert_allclose(res.trajectory["mu_table"].sum(axis=1), 2.0 * 9.81, rtol=1e-10)
    np.testing.assert_allclose(res.trajectory["contact_forces"][:, :, 2].sum(axis=1),
                               2.0 * 9.81, rtol=1e-10)
    assert (tmp_path / "out" / "contact_states.png").is_file()


def test_joint_unilateral_override(tmp_path):
    """A weld is bilateral by default; ``unilateral: true`` makes its six rows unilateral."""
    from multiarm_pin.app.scenario import parse_scenario

    arm = {"name": "a", "robot": "ur5", "q0": [0.0, -1.2, 1.6, -0.4, 1.57, 0.0],
           "joint": {"type": "weld"}}
    data = {"object": {"shape": {"type": "box", "size": [0.4, 0.3, 0.2]}, "mass": 1.0,
                       "pose": {"position": [0.5, 0.1, 0.4]}},
            "arms": [arm]}
    built = build_scenario(parse_scenario(copy.deepcopy(data), "x.yaml"))
    assert built.system.unilateral.sum() == 0
    data["arms"][0]["joint"]["unilateral"] = True
    built = build_scenario(parse_scenario(copy.deepcopy(data), "x.yaml"))
    assert built.system.unilateral.sum() == 6
    data["arms"][0]["joint"]["unilateral"] = "yes"
    with pytest.raises(ScenarioError, match="expected true or false") as info:
        parse_scenario(data, "x.yaml")
    assert info.value.key == "arms[0].joint.unilateral"


def test_support_extent_and_x_axis_are_read_and_built(tmp_path):
    """``extent`` makes the support a rectangle; ``x_axis`` is projected onto its plane."""
    from multiarm_pin.app.scenario import parse_scenario

    data = _with("supports.0.extent", [1.0, 0.8])
    sup = build_scenario(parse_scenario(data, "x.yaml")).system.supports
    assert sup.finite
    np.testing.assert_array_equal(sup.supports[0].extent, [1.0, 0.8])
    np.testing.assert_array_equal(sup.supports[0].x_axis, [1.0, 0.0, 0.0])  # the default
    data["supports"][0]["x_axis"] = [1.0, 1.0, 5.0]
    sup = build_scenario(parse_scenario(data, "x.yaml")).system.supports
    np.testing.assert_allclose(sup.supports[0].x_axis, [2**-0.5, 2**-0.5, 0.0], atol=1e-15)
    plain = build_scenario(parse_scenario(copy.deepcopy(BOX), "x.yaml")).system.supports
    assert not plain.finite and plain.supports[0].extent is None


@pytest.mark.parametrize(("path", "value", "key", "text"), [
    ("supports.0.extent", [-1.0, 0.5], "supports[0].extent", "two positive side lengths"),
    ("supports.0.extent", [0.0, 0.5], "supports[0].extent", "two positive side lengths"),
    ("supports.0.extent", [1.0, 0.5, 0.2], "supports[0].extent", "expected 2 numbers"),
    ("supports.0.extent", 1.0, "supports[0].extent", "expected shape (2,)"),
    ("supports.0.x_axis", [0, 0, -2], "supports[0].x_axis", "parallel to the plane's normal"),
    ("supports.0.x_axis", [0, 0, 0], "supports[0].x_axis", "parallel to the plane's normal"),
    ("supports.0.x_axis", [1, 0], "supports[0].x_axis", "expected 3 numbers"),
    ("supports.0.extnet", [1.0, 0.5], "supports[0].extnet", "extent"),
])
def test_bad_extents_exit_2_naming_the_key(tmp_path, capsys, path, value, key, text):
    """Bad ``extent`` / ``x_axis``: a ScenarioError with the key path, and ``run`` exits 2."""
    from multiarm_pin.app.cli import main

    data = _with(path, value)
    if path.endswith("x_axis"):
        data["supports"][0]["extent"] = [1.0, 0.5]
    err = _error(tmp_path, data)
    assert err.key == key and text in str(err), str(err)
    assert main(["run", str(tmp_path / "s.yaml"), "--out", str(tmp_path / "out")]) == 2
    stderr = capsys.readouterr().err
    assert stderr.startswith("error: ") and key in stderr and "Traceback" not in stderr
    assert not (tmp_path / "out").exists()


def test_a_box_pushed_off_a_finite_table_records_its_off_edge_events(tmp_path):
    """A scenario file with ``extent``: the off-edge time and labels in ``summary.json``.

    4 N on 2 kg, the table's edge (x = 0.25 m) 5 cm ahead of the leading vertices (rows 4
    and 6 of the box's vertices, x = +0.2 m, bottom): both lose the table at
    ``√(2 m d / F)`` = 0.2236 s.
    """
    data = _with("supports.0.extent", [1.0, 1.0])
    data["supports"][0]["plane"]["point"] = [-0.25, 0.0, 0.0]
    data["supports"][0]["x_axis"] = [1, 0, 0]
    data["object"]["external_wrench"] = [{"from": 0.0, "to": 1.0, "wrench": [4, 0, 0, 0, 0, 0]}]
    data["simulation"] = {"duration": 0.25, "dt": 0.005}
    p = tmp_path / "s.yaml"
    p.write_text(yaml.safe_dump(data), encoding="utf-8")
    res = run_scenario(p, tmp_path / "out", html=False, plots=False)
    s = res.summary
    assert s["supports"][0]["extent"] == [1.0, 1.0]
    assert s["supports"][0]["x_axis"] == [1.0, 0.0, 0.0]
    assert sorted((e["kind"], e["label"]) for e in s["events"]) == [
        ("off_edge", "table[4]"), ("off_edge", "table[6]")]
    for e in s["events"]:
        assert abs(e["t"] - np.sqrt(2 * 2.0 * 0.05 / 4.0)) < 1e-9
    assert any("Python stepper" in w for w in s["warnings"])
    np.testing.assert_array_equal(res.trajectory["support_extents"], [[1.0, 1.0]])
    assert sorted(res.trajectory["event_kind"].tolist()) == ["off_edge", "off_edge"]
