"""Strict reading of YAML input files (scenarios, grasps).

Plain ``yaml.safe_load`` lets a repeated key silently win (``mass: 4`` then ``mass: 400``
runs with 400 kg) and turns a file that is not UTF-8 into a ``UnicodeDecodeError``
traceback. :func:`load_yaml_file` refuses both with a
:class:`~multiarm_pin.exceptions.ScenarioError` naming the file, the key path and the lines.
"""

from __future__ import annotations

import re
from pathlib import Path

import yaml

from multiarm_pin.exceptions import ScenarioError


class StrictLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that also reads YAML 1.2 floats such as ``1e12`` or ``2E-3``.

    YAML 1.1 (PyYAML's default) wants a dot and a signed exponent (``1.0e+12``) and reads
    ``1e12`` as the *string* ``"1e12"``, which then fails as "expected a number".
    """


StrictLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


def _check_duplicates(node: yaml.Node, file: str, path: str = "") -> None:
    """Raise on a mapping that repeats a key, anywhere below ``node``."""
    if isinstance(node, yaml.MappingNode):
        seen: dict = {}
        for key_node, value_node in node.value:
            key = key_node.value if isinstance(key_node, yaml.ScalarNode) else None
            child = f"{path}.{key}" if path else str(key)
            if key is not None and key != "<<":
                mark = key_node.start_mark
                if key in seen:
                    first = seen[key]
                    here, there = f"line {mark.line + 1}", f"line {first.line + 1}"
                    if first.line == mark.line:
                        here += f" column {mark.column + 1}"
                        there += f" column {first.column + 1}"
                    raise ScenarioError(file, child, f"duplicate key {key!r} on {here} (first on "
                                        f"{there}); each key may appear once")
                seen[key] = mark
            _check_duplicates(value_node, file, child)
    elif isinstance(node, yaml.SequenceNode):
        for i, item in enumerate(node.value):
            _check_duplicates(item, file, f"{path}[{i}]")


def load_yaml_text(text: str, file: str):
    """Parse YAML text strictly (no duplicate keys).

    Args:
        text: the YAML document.
        file: where it came from (for messages).

    Returns:
        The parsed data (as ``yaml.safe_load``, plus YAML 1.2 floats like ``1e12``), None
        for an empty document.

    Raises:
        ScenarioError: syntax error or a duplicate key (naming both lines).
    """
    try:
        node = yaml.compose(text, Loader=StrictLoader)
        if node is not None:
            _check_duplicates(node, file)
        return yaml.load(text, Loader=StrictLoader)  # noqa: S506 (a SafeLoader subclass)
    except yaml.YAMLError as exc:
        raise ScenarioError(file, "", f"invalid YAML (YAML syntax error): {exc}") from None
    except RecursionError:
        raise ScenarioError(file, "", "YAML nested too deeply") from None


def load_yaml_file(path) -> object:
    """Read a UTF-8 YAML file strictly.

    Args:
        path: the file.

    Returns:
        The parsed data.

    Raises:
        ScenarioError: file missing or unreadable, not UTF-8 (with the byte offset), YAML
            syntax error or duplicate key.
    """
    path = Path(path)
    f = str(path)
    if not path.is_file():
        raise ScenarioError(f, "", "file not found" if not path.exists()
                            else "not a file (expected a YAML file)")
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise ScenarioError(f, "", f"cannot read the file: {exc.strerror or exc}") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        raise ScenarioError(f, "", f"not a UTF-8 text file: byte {exc.start} (line {line}) is "
                            f"0x{raw[exc.start]:02x}; expected a YAML file encoded in UTF-8"
                            ) from None
    if "\x00" in text:
        raise ScenarioError(f, "", "contains NUL bytes; expected a YAML text file")
    return load_yaml_text(text, f)


__all__ = ["StrictLoader", "load_yaml_file", "load_yaml_text"]
