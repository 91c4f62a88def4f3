"""Package data: shipped scenarios and robots found through the package, not the checkout."""

import copy
from pathlib import Path

import pytest
import yaml
from run_helpers import write

from multiarm_pin.app.cli import main
from multiarm_pin.app.scenario import load_scenario
from multiarm_pin.data import DEMO_SCENARIO, data_path, shipped_files
from multiarm_pin.exceptions import ScenarioError

ROOT = Path(__file__).resolve().parents[1]
MP6 = {"urdf": "PATH", "tool_frame": "tool0", "q0": [0.0] * 6, "joint": {"type": "weld"}}
BASE = {"object": {"shape": {"type": "box", "size": [0.4, 0.4, 0.4]}, "mass": 1.0},
        "arms": [MP6]}


def test_the_checkout_links_are_the_package_data():
    for name in ("scenarios", "robots"):
        assert (ROOT / name).resolve() == data_path(name).resolve()
    assert data_path("scenarios", DEMO_SCENARIO).is_file()
    assert data_path("robots", "mp6", "mp6.urdf").is_file()


def test_every_shipped_file_is_valid():
    names = [p.name for p in shipped_files("scenarios")]
    assert DEMO_SCENARIO in names and len(names) >= 10
    for f in shipped_files("scenarios"):
        load_scenario(f)
    assert {p.name for p in shipped_files("scenarios/grasps")} >= {"box_form_closure.yaml"}
    assert len(shipped_files("scenarios/studies")) >= 2


def _with_urdf(path):
    d = copy.deepcopy(BASE)
    d["arms"][0]["urdf"] = path
    return d


@pytest.mark.parametrize("urdf", ["mp6/mp6.urdf", "robots/mp6/mp6.urdf"])
def test_relative_urdf_falls_back_on_the_shipped_robots(tmp_path, urdf):
    sc = load_scenario(write(tmp_path / "s.yaml", yaml.safe_dump(_with_urdf(urdf))))
    assert Path(sc.arms[0].urdf) == data_path("robots", "mp6", "mp6.urdf").resolve()


def test_relative_urdf_beside_the_scenario_comes_first(tmp_path):
    own = tmp_path / "mp6" / "mp6.urdf"
    own.parent.mkdir()
    own.write_text(data_path("robots", "mp6", "mp6.urdf").read_text())
    sc = load_scenario(write(tmp_path / "s.yaml", yaml.safe_dump(_with_urdf("mp6/mp6.urdf"))))
    assert Path(sc.arms[0].urdf) == own.resolve()


def test_missing_urdf_names_every_place_looked_at(tmp_path):
    with pytest.raises(ScenarioError) as info:
        load_scenario(write(tmp_path / "s.yaml", yaml.safe_dump(_with_urdf("mp6/nope.urdf"))))
    err = info.value
    assert err.key == "arms[0].urdf" and "URDF file not found" in str(err)
    assert str(tmp_path / "mp6" / "nope.urdf") in str(err)
    assert str(data_path("robots") / "mp6" / "nope.urdf") in str(err)


def test_scenarios_command_lists_the_shipped_files(capsys):
    assert main(["scenarios"]) == 0
    out = capsys.readouterr().out
    assert DEMO_SCENARIO in out and "box_form_closure.yaml" in out
    assert "grasp_robustness.yaml" in out and str(data_path("scenarios")) in out


def test_grasp_picture_of_a_shipped_file_goes_to_the_current_folder(tmp_path, monkeypatch,
                                                                    capsys):
    monkeypatch.chdir(tmp_path)
    f = data_path("scenarios", "grasps", "box_form_closure.yaml")
    before = sorted(p.name for p in f.parent.iterdir())
    assert main(["grasp", str(f)]) == 0
    assert (tmp_path / "box_form_closure_grasp.png").stat().st_size > 1000
    assert sorted(p.name for p in f.parent.iterdir()) == before
    assert "form closure: yes" in capsys.readouterr().out
