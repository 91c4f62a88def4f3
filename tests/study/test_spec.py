import copy
import math

import numpy as np
import pytest
import yaml

from multiarm_pin.exceptions import MultiArmError, StudyError
from multiarm_pin.model.polyhedron import box
from multiarm_pin.study.spec import (
    apply_overrides,
    load_study,
    parse_key_path,
    resolve_key_path,
)
from tests.study.helpers import SCENARIOS, tiny_grasp_study, tiny_simulation_study, write_study


def test_parse_key_path():
    assert parse_key_path("arms[0].base.position[2]") == ["arms", 0, "base", "position", 2]
    assert parse_key_path("object.mass") == ["object", "mass"]
    for bad in ("", "a..b", "a.", "[0].a", "a b", ".a"):
        with pytest.raises(ValueError):
            parse_key_path(bad)


def test_resolve_and_apply_overrides_leave_base_untouched():
    base = yaml.safe_load((SCENARIOS / "two_ur5_box.yaml").read_text())
    before = copy.deepcopy(base)
    assert resolve_key_path(base, "arms[1].base.position[1]") == -0.55
    new = apply_overrides(base, {"object.mass": 7.5, "arms[1].base.position[1]": -0.6})
    assert new["object"]["mass"] == 7.5 and new["arms"][1]["base"]["position"][1] == -0.6
    assert base == before


def test_cases_grid_times_samples_and_seeded_draws(tmp_path):
    spec = load_study(tiny_simulation_study(tmp_path, masses=(2.0, 6.0, 9.0), samples=3))
    cases = spec.cases()
    assert len(cases) == 9
    assert [c.params["object.mass"] for c in cases] == [2.0] * 3 + [6.0] * 3 + [9.0] * 3
    kps = np.array([c.params["controller.kp"] for c in cases])
    assert np.all((kps >= 50.0) & (kps <= 150.0)) and len(set(kps)) == 9
    # the same study gives the same cases (draws depend on the seed and the case only)
    again = load_study(tiny_simulation_study(tmp_path, masses=(2.0, 6.0, 9.0), samples=3))
    assert [c.overrides for c in again.cases()] == [c.overrides for c in cases]
    assert [c.key for c in again.cases()] == [c.key for c in cases]
    # overrides hold the fixed value and the drawn ones
    assert all(c.overrides["simulation.duration"] == 0.01 for c in cases)
    assert all(c.overrides["controller.kp"] == c.params["controller.kp"] for c in cases)
    # the draw is numpy's uniform from default_rng([seed, index])
    rng = np.random.default_rng([3, 4])
    assert cases[4].params["controller.kp"] == rng.uniform(50.0, 150.0)


def test_normal_draws_have_their_sigma_and_default_mean(tmp_path):
    p = write_study(tmp_path, {
        "base": str(SCENARIOS / "two_ur5_box.yaml"),
        "parameters": [{"path": "arms[0].base.position", "normal": {"sigma": 0.01}}],
        "samples": 400, "seed": 1})
    cases = load_study(p).cases()
    X = np.array([c.overrides["arms[0].base.position"] for c in cases])
    assert X.shape == (400, 3)
    mean, std = X.mean(axis=0), X.std(axis=0, ddof=1)
    # base value [0, 0.55, 0]; 400 draws: the mean is within 5 standard errors
    assert np.all(np.abs(mean - [0.0, 0.55, 0.0]) < 5 * 0.01 / math.sqrt(400))
    assert np.all(np.abs(std - 0.01) < 0.002)


def test_contact_perturbation_stays_in_face_planes_with_sigma(tmp_path):
    spec = load_study(tiny_grasp_study(tmp_path, sigmas=(0.0, 0.01), samples=300))
    cases = spec.cases()
    base = spec.base_data
    poly = box(base["object"]["shape"]["size"])
    zero = [c for c in cases if c.params["perturb_contacts.sigma"] == 0.0]
    assert all(c.overrides[k] == pytest.approx(resolve_key_path(base, k), abs=0)
               for c in zero for k in c.overrides)
    moved = [c for c in cases if c.params["perturb_contacts.sigma"] == 0.01]
    key = "arms[0].joint.contacts[2].point"  # on +z
    P = np.array([c.overrides[key] for c in moved])
    p0 = np.array(resolve_key_path(base, key))
    assert np.allclose(P[:, 2], p0[2], atol=1e-15)  # stays in the +z plane
    d = P[:, :2] - p0[:2]
    assert np.all(np.abs(d.std(axis=0, ddof=1) - 0.01) < 0.0015)
    for c in moved[:20]:  # every contact stays on its own face's plane
        for a, arm in enumerate(base["arms"]):
            for k, ct in enumerate(arm["joint"]["contacts"]):
                pt = np.array(c.overrides[f"arms[{a}].joint.contacts[{k}].point"])
                assert abs(poly.signed_distance_to_face(pt, ct["face"])) < 1e-12


@pytest.mark.parametrize("mutate, key, words", [
    (lambda d: d["parameters"].append({"path": "object.mas", "grid": [1, 2]}),
     "parameters[1].path", ["'object.mas'", "did you mean 'mass'"]),
    (lambda d: d["parameters"].append({"path": "arms[5].base", "grid": [1]}),
     "parameters[1].path", ["has 2 items"]),
    (lambda d: d["parameters"].append({"path": "controller.kp", "normal": {"sigma": -0.1}}),
     "parameters[1].normal.sigma", ["standard deviation >= 0", "-0.1"]),
    (lambda d: d["parameters"].append({"perturb_contacts": {"sigma": [0.01, -0.002]}}),
     "parameters[1].perturb_contacts.sigma[1]", ["standard deviation >= 0"]),
    (lambda d: d["parameters"].append({"path": "controller.kp",
                                       "uniform": {"low": 3, "high": 1}}),
     "parameters[1].uniform", ["low <= high"]),
    (lambda d: d.update(metrics=["max_constraint_violaton"]), "metrics[0]",
     ["did you mean 'max_constraint_violation'"]),
    (lambda d: d.update(sampels=3), "sampels", ["did you mean 'samples'"]),
    (lambda d: d.update(base="nowhere.yaml"), "base", ["not found"]),
    (lambda d: d.update(mode="grsp"), "mode", ["did you mean 'grasp'"]),
    (lambda d: d["parameters"].append({"path": "object.mass", "grid": [1, 2]}),
     "parameters[1]", ["varied twice"]),
])
def test_bad_study_files_name_the_key(tmp_path, mutate, key, words):
    d = {"name": "bad", "base": str(SCENARIOS / "two_ur5_box.yaml"),
         "parameters": [{"path": "object.mass", "grid": [2.0, 4.0]}]}
    mutate(d)
    p = write_study(tmp_path, d)
    with pytest.raises(StudyError) as e:
        load_study(p)
    msg = str(e.value)
    assert e.value.key == key and str(p) in msg, msg
    for w in words:
        assert w in msg, msg
    assert isinstance(e.value, MultiArmError)


def test_invalid_base_file_is_a_study_error(tmp_path):
    base = tmp_path / "base.yaml"
    base.write_text("object: {shape: {type: box, size: [1, 1, 1]}, mass: -1}\narms: []\n")
    p = write_study(tmp_path, {"base": str(base),
                               "parameters": [{"path": "object.mass", "grid": [1]}]})
    with pytest.raises(StudyError, match="invalid base file"):
        load_study(p)


def test_grids_of_names_and_vectors_are_table_cells(tmp_path):
    p = write_study(tmp_path, {
        "base": str(SCENARIOS / "two_ur5_box.yaml"),
        "parameters": [{"path": "simulation.solver", "grid": ["object_first", "dense_kkt"]},
                       {"path": "arms[0].base.position", "grid": [[0, 0.5, 0], [0, 0.6, 0]]}]})
    cases = load_study(p).cases()
    assert [c.params["simulation.solver"] for c in cases] == ["object_first"] * 2 + \
        ["dense_kkt"] * 2
    assert cases[1].params["arms[0].base.position"] == "[0.0, 0.6, 0.0]"
    assert cases[1].overrides["arms[0].base.position"] == [0, 0.6, 0]


def test_grasp_mode_reads_the_scenario_as_the_grasp_command_does(tmp_path):
    """Issue 25: one reader; a scenario with supports is a grasp, a weld-only one is not."""
    spec = load_study(write_study(tmp_path, {
        "base": str(SCENARIOS / "pick_from_table.yaml"), "mode": "grasp",
        "parameters": [{"perturb_contacts": {"sigma": [0.001]}}]}))
    assert spec.base_kind == "scenario" and spec.mode == "grasp"
    with pytest.raises(StudyError, match=r"base: invalid base file for mode 'grasp': .*"
                       r"two_ur5_box.yaml: arms: no fingertip grasp to analyse"):
        load_study(write_study(tmp_path, {
            "base": str(SCENARIOS / "two_ur5_box.yaml"), "mode": "grasp",
            "parameters": [{"path": "object.mass", "grid": [1.0, 2.0]}]}, name="weld.yaml"))
