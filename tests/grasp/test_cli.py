import argparse
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import multiarm_pin.grasp as grasp_pkg
from multiarm_pin.grasp.cli import configure_parser, run

ROOT = Path(__file__).resolve().parents[2]
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
    assert rep["region_methods_agree"] is True and rep["last_contact_in_region"] is True
    V = np.array(rep["region_vertices"])
    assert V.shape[1] == 3 and len(V) >= 3
    np.testing.assert_allclose(V[:, 2], 0.5)  # on the +z face
    assert (tmp_path / "p.png").stat().st_size > 1000
    assert rep["stability"]["bound"] > 0


def test_marginal_box_file(capsys, tmp_path):
    rep = _json(capsys, GRASPS / "box_marginal.yaml", "--no-picture")
    assert rep["form_closure"] is False and rep["margin"] == 0.0 and rep["independent"] is True
    assert rep["last_contact_in_region"] is False


def test_polyhedron_file_and_default_picture_location(capsys, tmp_path):
    src = tmp_path / "hexa.yaml"
    shutil.copy(GRASPS / "hexahedron_point_normal.yaml", src)
    rep = _json(capsys, src)
    assert rep["form_closure"] is True and rep["independent"] is True
    assert rep["region_methods_agree"] is True
    assert (tmp_path / "hexa_grasp.png").exists()
    assert rep["picture"] == str(tmp_path / "hexa_grasp.png")


def test_text_report(capsys, tmp_path):
    assert run(_args(GRASPS / "box_form_closure.yaml", "--picture", tmp_path / "a.png")) == 0
    out = capsys.readouterr().out
    assert "form closure: yes" in out and "independent: yes" in out and "stability" in out


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
    assert rep["form_closure"] is False and rep["region_vertices"] == []
    assert rep["region_empty"] is True
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
        [sys.executable, "-m", "multiarm_pin.grasp.cli", str(GRASPS / "box_form_closure.yaml"),
         "--json", "--picture", str(tmp_path / "x.png")],
        capture_output=True, text=True, cwd=ROOT, timeout=120,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    rep = json.loads(out.stdout)
    assert {"form_closure", "margin", "independent", "region_vertices"} <= set(rep)
    bad = subprocess.run(
        [sys.executable, "-m", "multiarm_pin.grasp.cli", str(tmp_path / "missing.yaml")],
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
