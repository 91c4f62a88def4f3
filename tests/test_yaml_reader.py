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
