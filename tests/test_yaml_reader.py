"""Strict YAML: duplicate keys refused (both lines named), YAML 1.2 floats, encodings."""

import pytest

from multiarm_pin.exceptions import ScenarioError
from multiarm_pin.yaml_reader import load_yaml_file, load_yaml_text


def test_duplicate_keys_name_both_lines_and_the_key_path():
    text = "object:\n  mass: 4\n  shape: {type: box}\n  mass: 400\n"
    with pytest.raises(ScenarioError) as info:
        load_yaml_text(text, "f.yaml")
    assert info.value.key == "object.mass"
    assert "duplicate key 'mass' on line 4 (first on line 2)" in str(info.value)
    with pytest.raises(ScenarioError, match=r"arms\[1\].name: duplicate key 'name' on line 3 "
                       r"column 13 \(first on line 3 column 4\)"):
        load_yaml_text("arms:\n- {name: a}\n- {name: b, name: c}\n", "f.yaml")


def test_same_key_in_different_mappings_is_fine():
    data = load_yaml_text("a: {x: 1}\nb: {x: 2}\nc: [{x: 3}, {x: 4}]\n", "f.yaml")
    assert data == {"a": {"x": 1}, "b": {"x": 2}, "c": [{"x": 3}, {"x": 4}]}


@pytest.mark.parametrize("text, value", [("1e12", 1e12), ("-2E-3", -2e-3), ("1.0e300", 1e300),
                                         ("3", 3), ("0.5", 0.5), ("1e", "1e"), ("e5", "e5")])
def test_yaml_12_floats(text, value):
    assert load_yaml_text(f"v: {text}\n", "f.yaml")["v"] == value


def test_file_errors(tmp_path):
    with pytest.raises(ScenarioError, match="file not found"):
        load_yaml_file(tmp_path / "none.yaml")
    with pytest.raises(ScenarioError, match="not a file"):
        load_yaml_file(tmp_path)
    f = tmp_path / "utf16.yaml"
    f.write_bytes("name: x\n".encode("utf-16"))
    with pytest.raises(ScenarioError, match=r"not a UTF-8 text file: byte 0 \(line 1\) is 0xff"):
        load_yaml_file(f)
    f.write_bytes(b"name: x\x00\n")
    with pytest.raises(ScenarioError, match="NUL"):
        load_yaml_file(f)
    f.write_bytes(b"a: [1, 2\n")
    with pytest.raises(ScenarioError, match="YAML syntax error"):
        load_yaml_file(f)


def test_syntax_error_is_one_line_with_file_line_and_column():
    with pytest.raises(ScenarioError) as info:
        load_yaml_text("a: 1\nb: [1, 2\n", "f.yaml")
    assert (info.value.line, info.value.column) == (3, 1)
    text = str(info.value)
    assert text.startswith("f.yaml:3:1: YAML syntax error: ") and "\n" not in text
    assert "the end of the file" in text and "started on line 2, column 4" in text
    assert "<unicode string>" not in text and "<stream end>" not in text


BAD_YAML = "name: x\nobject: {shape: {type: box, size: [1, 1, 1]}\ncontacts: []\n"
"""A flow mapping left open on line 2 (column 9): PyYAML stops at line 3, column 1."""


@pytest.mark.parametrize("command", ["run", "grasp", "sweep", "sweep-base", "info"])
def test_syntax_errors_through_the_cli(tmp_path, command):
    """Exit 2, one or two lines naming the file and line:column, no traceback (issue 25)."""
    from run_helpers import run_cli, write

    bad = write(tmp_path / "bad.yaml", BAD_YAML)
    if command == "sweep-base":  # a valid study whose base scenario is broken
        study = write(tmp_path / "study.yaml", "base: bad.yaml\nmode: grasp\nparameters:\n"
                      "  - {path: object.mass, grid: [1, 2]}\n")
        p = run_cli("sweep", study, "--out", tmp_path / "out")
    else:
        p = run_cli(command, bad, *(["--out", tmp_path / "out"] if command == "sweep" else []))
    assert p.returncode == 2, (p.stdout, p.stderr)
    err = p.stderr.strip()
    assert f"{bad}:3:1: YAML syntax error: expected ',' or '}}', but got a value" in err
    assert "started on line 2, column 9" in err
    assert len(err.splitlines()) <= 2, err
    assert "Traceback" not in err and "<unicode string>" not in err
