import argparse
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import multiarm_pin.grasp as grasp_pkg
from multiarm_pin.app.grasp_cli import configure_parser, run

ROOT = Path(__file__).resolve().parents[1]
GRASPS = ROOT / "scenarios" / "grasps"
BOX = "object: {shape: {type: box, size: [2, 1, 1]}}\n"


def _args(*argv):
    parser = argparse.ArgumentParser()
    configure_parser(parser)
    return parser.parse_args([str(a) for a in argv])


def _json(capsys, *argv):
    assert run(_args(*argv, "--json")) == 0
    return json.loads(capsys.readouterr().out)


def test_all_names_in___all___exist():
    for name in grasp_pkg.__all__:
        assert hasattr(grasp_pkg, name), name


def test_form_closure_box_file(capsys, tmp_path):
    rep = _json(capsys, GRASPS / "box_form_closure.yaml", "--picture", tmp_path / "p.png")
    assert rep["form_closure"] is True and rep["independent"] is True
    assert rep["margin"] > 0.03
    # seventh_contact_face: +z: the regions of the two contacts on +z, the six others fixed
    assert [(e["contact"], e["fixed_contacts"]) for e in rep["regions"]] == [
        (3, [1, 2, 4, 5, 6, 7]), (7, [1, 2, 3, 4, 5, 6])]
    for e in rep["regions"]:
        assert e["methods_agree"] is True and e["contact_inside"] is True and e["face"] == "+z"
        V = np.array(e["vertices"])
        assert V.shape[1] == 3 and len(V) >= 3
        np.testing.assert_allclose(V[:, 2], 0.5)  # on the +z face
    assert (tmp_path / "p.png").stat().st_size > 1000
    assert rep["stability"]["bound"] > 0


def test_marginal_box_file(capsys, tmp_path):
    rep = _json(capsys, GRASPS / "box_marginal.yaml", "--no-picture")
    assert rep["form_closure"] is False and rep["margin"] == 0.0 and rep["independent"] is True
    third, seventh = rep["regions"]
    # the seventh lies on its region's boundary; the force of contact 3 vanishes, so the six
    # others are dependent and contact 3 has no region
    assert seventh["contact"] == 7 and seventh["contact_inside"] is False
    assert third["contact"] == 3 and third["computed"] is False
    assert "not independent" in third["reason"]


def test_polyhedron_file_and_default_picture_location(capsys, tmp_path):
    src = tmp_path / "hexa.yaml"
    shutil.copy(GRASPS / "hexahedron_point_normal.yaml", src)
    rep = _json(capsys, src)
    assert rep["form_closure"] is True and rep["independent"] is True
    assert [e["contact"] for e in rep["regions"]] == [3, 7]  # the contacts on face 5
    assert all(e["methods_agree"] and e["contact_inside"] for e in rep["regions"])
    assert (tmp_path / "hexa_grasp.png").exists()
    assert rep["picture"] == str(tmp_path / "hexa_grasp.png")


def test_text_report(capsys, tmp_path):
    assert run(_args(GRASPS / "box_form_closure.yaml", "--picture", tmp_path / "a.png")) == 0
    out = capsys.readouterr().out
    assert "form closure: yes" in out and "(rank 6): yes" in out and "stability" in out
    assert "contact 7 on face +z, fixed 1, 2, 3, 4, 5, 6: area 1.36215 m^2" in out


def test_six_contacts_and_empty_region(capsys, tmp_path):
    f = tmp_path / "six.yaml"
    f.write_text(
        "object: {shape: {type: box, size: [0.8, 2.0, 2.0]}}\n"
        "contacts:\n"
        "  - {face: +x, point: [0.4, 0.55, 0.55]}\n"
        "  - {face: +y, point: [-0.05, 1.0, 0.55]}\n"
        "  - {face: +z, point: [0.35, 0.55, 1.0]}\n"
        "  - {face: -x, point: [-0.4, -0.55, -0.55]}\n"
        "  - {face: -y, point: [0.05, -1.0, -0.55]}\n"
        "  - {face: -z, point: [-0.35, -0.55, -1.0]}\n"
        "seventh_contact_face: +z\n"
    )
    rep = _json(capsys, f, "--no-picture")
    (e,) = rep["regions"]
    assert rep["form_closure"] is False and e["vertices"] == [] and e["empty"] is True
    assert e["contact"] is None and e["fixed_contacts"] == [1, 2, 3, 4, 5, 6]
    assert any("no point of face +z" in n for n in rep["notes"])


@pytest.mark.parametrize(
    "text,needle",
    [
        (BOX + "contacts:\n  - {face: +x, point: [1.2, 0, 0]}\n", "contacts[0]: contact point"),
        (BOX + "contacts:\n  - {face: 9, point: [1, 0, 0]}\n",
         "contacts[0]: contact face: face index 9 out of range"),
        ("object: {shape: {type: cone}}\ncontacts: []\n", "object.shape.type"),
        ("contacts: []\n", "object: missing"),
        ("object: {shape: {type: box, size: [2, 1, 1]}}\ncontacts: [1]\n", "contacts[0]"),
        ("object: {shape: {type: box, size: [2, 1, 1]}}\ncontacts: []\nseventh_contact_face: up\n",
         "seventh_contact_face"),
        ("object: [unclosed\n", "bad.yaml:2:1: YAML syntax error"),
    ],
)  # fmt: skip
def test_invalid_files_exit_2_naming_file_and_key(tmp_path, capsys, text, needle):
    f = tmp_path / "bad.yaml"
    f.write_text(text)
    assert run(_args(f, "--no-picture")) == 2
    err = capsys.readouterr().err
    assert str(f) in err and needle in err


def test_module_runs_as_a_program(tmp_path):
    out = subprocess.run(
        [sys.executable, "-m", "multiarm_pin.app.grasp_cli", str(GRASPS / "box_form_closure.yaml"),
         "--json", "--picture", str(tmp_path / "x.png")],
        capture_output=True, text=True, cwd=ROOT, timeout=120,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    rep = json.loads(out.stdout)
    assert {"form_closure", "margin", "independent", "regions"} <= set(rep)
    bad = subprocess.run(
        [sys.executable, "-m", "multiarm_pin.app.grasp_cli", str(tmp_path / "missing.yaml")],
        capture_output=True, text=True, cwd=ROOT, timeout=120,
    )  # fmt: skip
    assert bad.returncode == 2 and "missing.yaml" in bad.stderr


def test_bad_picture_format_and_bad_encodings_are_messages(tmp_path, capsys):
    """Issue 13: these were tracebacks (matplotlib's ValueError, UnicodeDecodeError)."""
    pic = tmp_path / "p.txt"
    assert run(_args(GRASPS / "box_form_closure.yaml", "--picture", pic)) == 2
    err = capsys.readouterr().err
    assert "--picture" in err and "unsupported picture format 'txt'" in err and ".png" in err
    assert not pic.exists()
    bad = tmp_path / "latin1.yaml"
    bad.write_bytes("name: caf\xe9\n".encode("latin-1") + BOX.encode())
    assert run(_args(bad, "--no-picture")) == 2
    assert f"{bad}: not a UTF-8 text file: byte 9 (line 1) is 0xe9" in capsys.readouterr().err
    dup = tmp_path / "dup.yaml"
    dup.write_text(BOX + "object: {shape: {type: box, size: [1, 1, 1]}}\n")
    assert run(_args(dup, "--no-picture")) == 2
    assert "duplicate key 'object' on line 2 (first on line 1)" in capsys.readouterr().err


def _reordered(tmp_path, order, extra="", name="reordered"):
    """box_form_closure.yaml with its contacts in ``order`` (0-based) and no face key."""
    lines = (GRASPS / "box_form_closure.yaml").read_text().splitlines()
    contacts = [ln for ln in lines if ln.startswith("  - {face:")]
    f = tmp_path / f"{name}.yaml"
    f.write_text(BOX.replace("[2, 1, 1]", "[2.0, 1.5, 1.0]") + "contacts:\n"
                 + "\n".join(contacts[i] for i in order) + "\n" + extra)
    return f


def test_region_does_not_depend_on_the_order_of_the_file(tmp_path, capsys):
    """Issue 25: with the -x contact listed last, the report said "form closure: yes" and
    "empty: no point of this face completes form closure"; another order gave a region.

    The first report through the command line as a user runs it (``multiarm-pin grasp``),
    the others through the subcommand's own handler (the same ``grasp_cli.run``) in-process."""
    from run_helpers import run_cli

    order = [0, 1, 2, 4, 5, 6, 3]  # the -x contact last
    f = _reordered(tmp_path, order)
    p = run_cli("grasp", f, "--json", "--no-picture")
    assert p.returncode == 0, p.stderr
    rep = json.loads(p.stdout)
    assert rep["form_closure"] is True
    # every contact's region (the six others fixed): non-empty, holding the contact
    assert [e["contact"] for e in rep["regions"]] == list(range(1, 8))
    for e in rep["regions"]:
        assert e["computed"] and not e["empty"] and e["contact_inside"] is True
        assert e["fixed_contacts"] == [i for i in range(1, 8) if i != e["contact"]]
    ref = _json(capsys, _reordered(tmp_path, range(7), name="file_order"), "--no-picture")
    areas = {order[e["contact"] - 1]: e["area"] for e in rep["regions"]}
    assert areas == pytest.approx({e["contact"] - 1: e["area"] for e in ref["regions"]},
                                  rel=1e-9)
    assert run(_args(f, "--no-picture", "--seventh", "7")) == 0
    text = capsys.readouterr().out
    assert "contact 7 on face -x, fixed 1, 2, 3, 4, 5, 6: area" in text
    assert "empty" not in text and "contact 7 inside it: yes" in text
    assert run(_args(f, "--no-picture", "--seventh", "8")) == 2
    assert "--seventh 8: expected a contact number in 1..7" in capsys.readouterr().err


def test_seventh_contact_key(tmp_path, capsys):
    rep = _json(capsys, _reordered(tmp_path, range(7), "seventh_contact: 4\n"), "--no-picture")
    assert rep["seventh_contact"] == 4
    assert [(e["contact"], e["face"]) for e in rep["regions"]] == [(4, "-x")]
    for value in ("0", "8", "x", "2.5"):
        f = _reordered(tmp_path, range(7), f"seventh_contact: {value}\n")
        assert run(_args(f, "--no-picture")) == 2
        err = capsys.readouterr().err
        assert f"{f}: seventh_contact: expected a contact number in 1..7" in err


SCENARIOS = ROOT / "scenarios"


def test_grasp_of_a_scenario_with_supports_through_the_cli(capsys):
    """Issue 25: `grasp` refused a scenario with supports that `sweep` in grasp mode read.

    The JSON report through the command line, the text report through the subcommand's
    handler (``grasp_cli.run``) in-process."""
    import yaml
    from run_helpers import run_cli

    from multiarm_pin.study.case import grasp_of
    from multiarm_pin.study.metrics import grasp_metrics

    f = SCENARIOS / "pick_from_table.yaml"
    p = run_cli("grasp", f, "--json", "--no-picture")
    assert p.returncode == 0, p.stderr
    rep = json.loads(p.stdout)
    assert rep["kind"] == "scenario" and rep["n_contacts"] == 7 and rep["form_closure"] is True
    assert rep["contact_names"][0] == "four_finger:fingertip_1"
    (note,) = [n for n in rep["notes"] if n.startswith("scenario file")]
    assert "ignored (not about the grasp): supports, controller, simulation" in note
    assert len(rep["regions"]) == 7 and all(e["contact_inside"] for e in rep["regions"])
    # the study's grasp mode reads the same grasp
    grasp, L = grasp_of(yaml.safe_load(f.read_text()), str(f))
    m = grasp_metrics(grasp, L)
    assert rep["margin"] == pytest.approx(m["margin"], abs=1e-12)
    assert run(_args(f, "--no-picture", "--seventh", "4")) == 0
    text = capsys.readouterr().out
    assert text.startswith("scenario file: ") and "4 four_finger:fingertip_4" in text
    assert "contact 4 on face +z, fixed 1, 2, 3, 5, 6, 7: area" in text


@pytest.mark.parametrize("name, needle", [
    ("two_ur5_box.yaml", "arms: no fingertip grasp to analyse: the scenario has left (weld), "
                         "right (weld)"),
    ("box_on_table.yaml", "arms: no fingertip grasp to analyse: the scenario has no arms and "
                          "1 support(s)"),
])
def test_grasp_of_a_scenario_without_fingertips_is_refused(name, needle):
    from run_helpers import run_cli

    p = run_cli("grasp", SCENARIOS / name, "--no-picture")
    assert p.returncode == 2 and "Traceback" not in p.stderr
    assert f"{SCENARIOS / name}: {needle}" in p.stderr and len(p.stderr.splitlines()) == 1


def test_grasp_of_a_scenario_contact_off_its_face(tmp_path, capsys):
    text = (SCENARIOS / "two_gripper_form_closure.yaml").read_text()
    first = text.index("point: [", text.index("contacts:"))
    f = tmp_path / "off.yaml"
    f.write_text(text[:first] + "point: [0.4, 0.9, 0.15]}" + text[text.index("}", first) + 1:])
    assert run(_args(f, "--no-picture")) == 2
    err = capsys.readouterr().err
    assert f"{f}: arms[0].joint.contacts[0]: contact point [0.4, 0.9, 0.15]" in err
