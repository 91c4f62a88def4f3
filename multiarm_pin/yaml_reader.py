"""Strict reading of YAML input files (scenarios, grasps, studies).

Two layers, shared by every file format of the package:

- :func:`load_yaml_file` / :func:`load_yaml_text`: plain ``yaml.safe_load`` lets a repeated key
  silently win (``mass: 4`` then ``mass: 400`` runs with 400 kg) and turns a file that is not
  UTF-8 into a ``UnicodeDecodeError`` traceback; these refuse both with a
  :class:`~multiarm_pin.exceptions.ScenarioError` naming the file, the key path and the lines.
- :class:`Reader`: walks the parsed data with its key path (``arms[1].joint.type``) and
  validates each value (mapping keys, strings among choices, numbers, arrays of a shape,
  placements), with a did-you-mean (:func:`did_you_mean`) for unknown keys and values.

This module sits at the package's top level (it depends on nothing but the exceptions) so that
the grasp layer (:mod:`multiarm_pin.grasp.report`) and the application shell
(:mod:`multiarm_pin.app.scenario`) read their files the same way without the grasp layer
importing the application shell.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pinocchio as pin
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
        ScenarioError: syntax error (one line: file, line, column, what was found) or a
            duplicate key (naming both lines).
    """
    try:
        node = yaml.compose(text, Loader=StrictLoader)
        if node is not None:
            _check_duplicates(node, file)
        return yaml.load(text, Loader=StrictLoader)  # noqa: S506 (a SafeLoader subclass)
    except yaml.MarkedYAMLError as exc:
        raise syntax_error(exc, file) from None
    except yaml.YAMLError as exc:
        raise ScenarioError(file, "", f"invalid YAML (YAML syntax error): {exc}") from None
    except RecursionError:
        raise ScenarioError(file, "", "YAML nested too deeply") from None


def syntax_error(exc: yaml.MarkedYAMLError, file: str) -> ScenarioError:
    """One line for a PyYAML error: ``file:line:column: YAML syntax error: what was found``.

    PyYAML's own text quotes the document as ``<unicode string>`` over several lines (the
    context, a caret line, the problem); this keeps the problem, its position (1-based) and
    where the construct it was reading started.
    """
    mark = exc.problem_mark or exc.context_mark
    problem = _plain(exc.problem or "syntax error")
    text = f"YAML syntax error: {problem}"
    if exc.context:
        cm = exc.context_mark
        elsewhere = (cm is not None and mark is not None
                     and (cm.line, cm.column) != (mark.line, mark.column))
        started = f" started on line {cm.line + 1}, column {cm.column + 1}" if elsewhere else ""
        text += f" ({_plain(exc.context)}{started})"
    if mark is None:
        return ScenarioError(file, "", text)
    return ScenarioError(file, "", text, mark.line + 1, mark.column + 1)


def _plain(text: str) -> str:
    """PyYAML's token names in words (``'<stream end>'`` is the end of the file)."""
    for token, words in (("'<stream end>'", "the end of the file"),
                         ("<stream end>", "the end of the file"),
                         ("end of stream", "end of the file"),
                         ("'<scalar>'", "a value"),
                         ("<block end>", "the end of the indented block"),
                         ("'<block mapping start>'", "a key indented differently"),
                         ("<block mapping start>", "a key indented differently")):
        text = text.replace(token, words)
    return " ".join(text.split())


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



# ----------------------------------------------------------------------------- key paths
def did_you_mean(word: str, options: Sequence[str]) -> str:
    """`` (did you mean 'x'?)`` for the closest of ``options``, or an empty string."""
    close = difflib.get_close_matches(str(word), [str(o) for o in options], n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


class Reader:
    """Reads one parsed YAML value with its key path; every failure is a ScenarioError.

    ``Reader(file, "", data)`` wraps a whole document; :meth:`get` and :meth:`child` descend
    (``arms[1].joint.type``); the typed readers (:meth:`mapping`, :meth:`string`,
    :meth:`number`, :meth:`array`, :meth:`placement`) raise
    :class:`~multiarm_pin.exceptions.ScenarioError` naming the file, the key path and what was
    expected, with a did-you-mean for unknown keys and values.

    Attributes:
        file: the file the value came from (for messages).
        path: the key path of the value (``""`` for the document).
        value: the parsed value (None when the key is absent).
    """

    def __init__(self, file: str, path: str, value):
        self.file, self.path, self.value = file, path, value

    def error(self, message: str, key: str | None = None) -> ScenarioError:
        """The error to raise: ``message`` at this key path (or at ``key``)."""
        return ScenarioError(self.file, key if key is not None else self.path, message)

    def child(self, key, value) -> Reader:
        """The reader of ``value`` found at ``key`` (a mapping key, or a list index)."""
        if isinstance(key, int):
            return Reader(self.file, f"{self.path}[{key}]", value)
        return Reader(self.file, f"{self.path}.{key}" if self.path else str(key), value)

    def mapping(self, allowed: Sequence[str], required: Sequence[str] = ()) -> dict:
        """The value as a dict with only ``allowed`` keys and every ``required`` one."""
        if not isinstance(self.value, Mapping):
            raise self.error(f"expected a mapping with keys {', '.join(allowed)}, got "
                             f"{describe(self.value)}")
        for k in self.value:
            if k not in allowed:
                raise self.error(
                    f"unknown key {k!r}{did_you_mean(k, allowed)}; expected keys: "
                    f"{', '.join(allowed)}",
                    self.child(k, None).path,
                )
        for k in required:
            if k not in self.value:
                raise self.error(f"missing required key {k!r}", self.child(k, None).path)
        return dict(self.value)

    def get(self, key: str) -> Reader:
        """The reader of key ``key`` of this mapping (value None when absent)."""
        return self.child(key, self.value.get(key) if isinstance(self.value, Mapping) else None)

    def string(self, choices: Sequence[str] | None = None) -> str:
        """The value as a string, one of ``choices`` when given."""
        if not isinstance(self.value, str):
            what = f"one of {', '.join(choices)}" if choices else "a string"
            raise self.error(f"expected {what}, got {describe(self.value)}")
        if choices is not None and self.value not in choices:
            raise self.error(f"unknown value {self.value!r}{did_you_mean(self.value, choices)}; "
                             f"expected one of {', '.join(choices)}")
        return self.value

    def number(self, positive: bool = False, nonnegative: bool = False) -> float:
        """The value as a finite float (not a bool), optionally > 0 or >= 0."""
        v = self.value
        if isinstance(v, bool) or not isinstance(v, int | float) or not np.isfinite(v):
            raise self.error(f"expected a number, got {describe(v)}")
        if positive and v <= 0:
            raise self.error(f"expected a positive number, got {v}")
        if nonnegative and v < 0:
            raise self.error(f"expected a number >= 0, got {v}")
        return float(v)

    def array(self, shape: Sequence[int | None], meaning: str = "") -> np.ndarray:
        """The value as a finite float array of ``shape`` (None: any length).

        ``meaning`` (units, axes) is quoted in the messages.
        """
        exp = _shape_text(shape) + (f" ({meaning})" if meaning else "")
        v = self.value
        if isinstance(v, str | bytes | Mapping) or v is None or isinstance(v, bool):
            raise self.error(f"expected a list of numbers of shape {exp}, got {describe(v)}")
        try:
            arr = np.asarray(v, dtype=float)
        except (TypeError, ValueError):
            raise self.error(f"expected numbers of shape {exp}, got {describe(v)}") from None
        if arr.ndim != len(shape) or any(
            s is not None and s != n for s, n in zip(shape, arr.shape, strict=False)
        ):
            if len(shape) == 1 and arr.ndim == 1:
                raise self.error(f"expected {shape[0]} numbers {exp}, got {arr.shape[0]}: "
                                 f"{arr.tolist()}")
            raise self.error(f"expected shape {exp}, got shape {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise self.error(f"expected finite numbers, got {arr.tolist()}")
        return arr

    def quaternion(self) -> np.ndarray:
        """(4,) unit quaternion ``[x, y, z, w]`` (norm within 1e-6 of 1, then normalised)."""
        q = self.array((4,), "[x, y, z, w]")
        n = float(np.linalg.norm(q))
        if abs(n - 1.0) > 1e-6:
            raise self.error(f"expected a unit quaternion [x, y, z, w], got norm {n:.9g}: "
                             f"{q.tolist()}")
        return q / n

    def placement(self) -> pin.SE3:
        """A placement ``{position [m], quaternion [x, y, z, w] | rpy [rad]}``.

        Missing parts are the identity's; quaternion and rpy together are refused.
        """
        d = self.mapping(("position", "quaternion", "rpy"))
        if "quaternion" in d and "rpy" in d:
            raise self.error("give only one of quaternion [x, y, z, w] or rpy")
        p = self.get("position").array((3,), "m") if "position" in d else np.zeros(3)
        if "quaternion" in d:
            R = pin.Quaternion(self.get("quaternion").quaternion()).toRotationMatrix()
        elif "rpy" in d:
            r = self.get("rpy").array((3,), "roll, pitch, yaw [rad]")
            R = pin.rpy.rpyToMatrix(*r)
        else:
            R = np.eye(3)
        return pin.SE3(R, p)


def describe(v) -> str:
    """A short text of a parsed value for messages (``a list of 2: [1, 2]``)."""
    if isinstance(v, Mapping):
        return f"a mapping with keys {list(v)}"
    if isinstance(v, list | tuple):
        return f"a list of {len(v)}: {v!r}"[:120]
    return f"{type(v).__name__} {v!r}"[:120]


def _shape_text(shape) -> str:
    inner = ", ".join("n" if s is None else str(s) for s in shape)
    return f"({inner},)" if len(shape) == 1 else f"({inner})"


__all__ = [
    "Reader",
    "StrictLoader",
    "describe",
    "did_you_mean",
    "load_yaml_file",
    "load_yaml_text",
    "syntax_error",
]
