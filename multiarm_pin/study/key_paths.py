"""Key paths into a parsed YAML file: ``arms[0].base.position[2]``, read, set, overridden.

A key path names one value of a scenario or grasp file by its own keys: mapping keys joined
by ``.``, list items by ``[i]``. A study (:mod:`multiarm_pin.study.spec`) names what it
varies by key path; each case is the base file with ``{key path: value}`` overrides set.
"""

from __future__ import annotations

import copy
import re
from collections.abc import Mapping, Sequence

from multiarm_pin.app.scenario import did_you_mean
from multiarm_pin.exceptions import StudyError

_TOKEN = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)|\[(-?\d+)\]|(\.)")


def parse_key_path(path: str) -> list[str | int]:
    """Split ``arms[0].base.position[2]`` into ``["arms", 0, "base", "position", 2]``.

    Raises:
        ValueError: not a key path.
    """
    if not isinstance(path, str) or not path:
        raise ValueError(f"expected a key path such as 'object.mass', got {path!r}")
    tokens: list[str | int] = []
    pos, expect_name = 0, True
    while pos < len(path):
        m = _TOKEN.match(path, pos)
        if m is None:
            raise ValueError(f"bad key path {path!r} at character {pos + 1}")
        name, index, dot = m.groups()
        if name is not None:
            if not expect_name:
                raise ValueError(f"bad key path {path!r}: missing '.' before {name!r}")
            tokens.append(name)
            expect_name = False
        elif index is not None:
            if expect_name and tokens:
                raise ValueError(f"bad key path {path!r}: '[' after '.'")
            tokens.append(int(index))
            expect_name = False
        else:
            if expect_name:
                raise ValueError(f"bad key path {path!r}: empty key before '.'")
            expect_name = True
        pos = m.end()
    if expect_name or not tokens or not isinstance(tokens[0], str):
        raise ValueError(f"bad key path {path!r}")
    return tokens


def _join(tokens: Sequence[str | int]) -> str:
    out = ""
    for t in tokens:
        out += f"[{t}]" if isinstance(t, int) else (f".{t}" if out else t)
    return out


def resolve_key_path(data, path: str, file: str = "<base>", key: str = "path"):
    """The value at ``path`` in ``data``.

    Args:
        data: the parsed base file.
        path: the key path.
        file: the study file (for messages).
        key: the study key holding the path (for messages).

    Raises:
        StudyError: the path does not exist (names the deepest existing part and, for a
            mapping, the closest key).
    """
    try:
        tokens = parse_key_path(path)
    except ValueError as exc:
        raise StudyError(file, key, str(exc)) from None
    node = data
    for i, t in enumerate(tokens):
        where = _join(tokens[:i]) or "the top level"
        if isinstance(t, str):
            if not isinstance(node, Mapping):
                raise StudyError(file, key, f"{path!r} does not exist in the base file: "
                                 f"{where} is not a mapping, so it has no key {t!r}")
            if t not in node:
                raise StudyError(file, key, f"{path!r} does not exist in the base file: "
                                 f"{where} has no key {t!r}{did_you_mean(t, list(node))}; "
                                 f"its keys: {', '.join(map(str, node))}")
            node = node[t]
        else:
            if not isinstance(node, list):
                raise StudyError(file, key, f"{path!r} does not exist in the base file: "
                                 f"{where} is not a list, so it has no item [{t}]")
            if not 0 <= t < len(node):
                raise StudyError(file, key, f"{path!r} does not exist in the base file: "
                                 f"{where} has {len(node)} items, no item [{t}]")
            node = node[t]
    return node


def set_key_path(data, path: str, value) -> None:
    """Set the value at an existing key path, in place (see :func:`resolve_key_path`)."""
    tokens = parse_key_path(path)
    node = data
    for t in tokens[:-1]:
        node = node[t]
    node[tokens[-1]] = value


def apply_overrides(base, overrides: Mapping[str, object]):
    """A deep copy of ``base`` with each ``{key path: value}`` set (in the given order)."""
    data = copy.deepcopy(base)
    for path, value in overrides.items():
        set_key_path(data, path, copy.deepcopy(value))
    return data
