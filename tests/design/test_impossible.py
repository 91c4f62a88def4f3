"""Impossible specs end with an answer: the condition no candidate met, the best value reached."""

import pytest
import yaml

from multiarm_pin.app.cli import main
from multiarm_pin.data import data_path
from multiarm_pin.design import parse_design, run_design
from multiarm_pin.exceptions import DesignImpossibleError
from tests.design.design_cases import small, spec_data


def _impossible(data, **budget):
    spec = small(parse_design(data, "impossible.yaml"), **budget)
    with pytest.raises(DesignImpossibleError) as info:
        run_design(spec)
    return info.value


def test_a_500_kg_box_is_too_heavy_for_two_ur5s():
    d = spec_data()
    d["object"]["mass"] = 500.0
    err = _impossible(d, candidates=8, refine=0)
    assert err.condition == "torque"
    assert err.best > 1.5  # a UR5's shoulder holds a few kg at this reach, not 250
    assert f"{err.best:.3g}x its limit at best" in str(err)
    assert "ur5_" in str(err)


def test_an_object_out_of_every_arms_reach():
    d = spec_data()
    d["object"]["pose"]["position"] = [4.0, 0.0, 0.35]
    d["task"] = {"lift": 0.1}
    err = _impossible(d, candidates=8, refine=0)
    assert err.condition == "reach"
    assert err.best > 1.0  # the region ends 2.7 m from the box's nearest face
    assert "no base in the region reaches the object" in str(err)
    assert f"closest {err.best:.3g} m" in str(err)


def test_fingertips_cannot_hold_a_box_whose_bottom_rests_on_a_larger_table():
    d = yaml.safe_load(data_path("scenarios", "designs", "two_gripper_form_closure.yaml")
                       .read_text(encoding="utf-8"))
    d["supports"] = [{"name": "table", "plane": {"point": [0, 0, 0.7], "normal": [0, 0, 1]},
                      "points": "vertices", "extent": [2.0, 2.0]}]
    err = _impossible(d, candidates=4, refine=0)
    assert err.condition == "closure"
    assert err.best <= 0.0
    msg = str(err)
    assert "the -z face rests on 'table'" in msg and "cannot push up" in msg
    assert "form closure needs a contact on it" in msg


def test_the_command_exits_1_naming_the_condition(tmp_path, capsys):
    d = spec_data()
    d["object"]["mass"] = 500.0
    d["search"] = {"candidates": 8, "refine": 0, "seed": 0}
    spec = tmp_path / "heavy.yaml"
    spec.write_text(yaml.safe_dump(d), encoding="utf-8")
    code = main(["design", str(spec), "--out", str(tmp_path / "out"), "--workers", "1",
                 "--quiet"])
    err = capsys.readouterr().err
    assert code == 1
    assert "impossible:" in err and "x its limit at best" in err
    assert not (tmp_path / "out").exists()  # nothing written for no design
