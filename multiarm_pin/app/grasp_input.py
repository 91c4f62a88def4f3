"""What a grasp analysis reads: a grasp file, or the fingertip contacts of a scenario.

``multiarm-pin grasp FILE`` and a study in mode ``grasp`` (:mod:`multiarm_pin.study.case`)
read their file through :func:`grasp_input_from_data` (or :func:`load_grasp_input`), so both
accept the same files the same way:

- a grasp file (``object`` and ``contacts``, no ``arms``): :mod:`multiarm_pin.grasp.report`;
- a scenario file (:mod:`multiarm_pin.app.scenario`): validated as a whole, then the grasp is
  the object's shape and the contacts of its ``fingertips`` joints (each contact's ``face`` and
  ``point``, in the order of the arms and of their contacts). What is not about that grasp
  (supports, gravity, controller, simulation, the object's mass and pose, arms joined by
  another joint type) is ignored, and one note says so.

A scenario without fingertip contacts (only welds or mechanical joints, or only supports) has
no point-contact grasp to analyse: form closure is a question about unilateral frictionless
contacts, and a weld or a mechanical joint is bilateral (it holds the object in the directions
it constrains whatever the others do), so it is refused with a clear error rather than
answered with a meaningless verdict.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from multiarm_pin.exceptions import GraspError, InputError, ScenarioError
from multiarm_pin.grasp.report import GraspFile, grasp_from_data
from multiarm_pin.yaml_reader import load_yaml_file

GRASP_JOINT_TYPES = ("fingertips", "contacts")
"""Joint types of a scenario whose contacts make the grasp (``contacts``: the old name)."""

_GRASP_SCENARIO_KEYS = ("name", "description", "object", "arms")
"""Top-level scenario keys that are about the grasp; the others are ignored with a note."""


@dataclass(frozen=True)
class GraspInput:
    """A grasp to analyse and where it came from.

    Attributes:
        grasp_file: the grasp (object, contacts, options) as a grasp file would give it.
        kind: ``"grasp"`` (a grasp file) or ``"scenario"`` (a scenario's fingertip contacts).
        contact_names: one name per contact (``arm:tip`` for a scenario, the face otherwise).
        notes: what was ignored (one line), empty for a grasp file.
    """

    grasp_file: GraspFile
    kind: str
    contact_names: tuple[str, ...] = ()
    notes: tuple[str, ...] = field(default_factory=tuple)


def is_grasp_file(data) -> bool:
    """True for a grasp file's data (``contacts`` and no ``arms``), False for a scenario."""
    return isinstance(data, Mapping) and "contacts" in data and "arms" not in data


def load_grasp_input(path: str | Path) -> GraspInput:
    """Read a grasp file or a scenario file for the grasp analysis.

    Raises:
        ScenarioError: unreadable file, invalid YAML or content, or a scenario with no
            fingertip contacts (names the file and the key path).
    """
    path = Path(path)
    return grasp_input_from_data(load_yaml_file(path), path)


def grasp_input_from_data(data, path: str | Path) -> GraspInput:
    """The grasp of parsed grasp-file or scenario data read from ``path``.

    Raises:
        ScenarioError: invalid data, a contact point off its face, or a scenario with no
            fingertip contacts.
    """
    path = Path(path)
    if not isinstance(data, Mapping) or "arms" not in data:
        gf = grasp_from_data(data, path)
        return GraspInput(gf, "grasp", tuple(c.label for c in gf.grasp.contacts))
    return _scenario_grasp(data, path)


def _scenario_grasp(data: Mapping, path: Path) -> GraspInput:
    from multiarm_pin.app.scenario import build_object, parse_scenario
    from multiarm_pin.grasp.contacts import Grasp, contact_on_face

    file = str(path)
    sc = parse_scenario(data, file)  # the whole scenario must be valid
    poly = build_object(sc).shape
    contacts, names, used, other = [], [], [], []
    for a, arm in enumerate(sc.arms):
        if arm.joint.type not in GRASP_JOINT_TYPES:
            other.append(f"{arm.name} ({arm.joint.type})")
            continue
        used.append(arm.name)
        for k, c in enumerate(arm.joint.contacts):
            key = f"arms[{a}].joint.contacts[{k}]"
            if c.point is None:
                raise ScenarioError(file, f"{key}.point", "the grasp analysis needs every "
                                    "contact point (object frame [m]); this contact gives only "
                                    "its face")
            try:
                contacts.append(contact_on_face(poly, c.face, c.point))
            except (GraspError, InputError) as exc:
                raise ScenarioError(file, key, str(exc)) from exc
            names.append(f"{arm.name}:{c.tip}")
    if not contacts:
        joints = ", ".join(other) if other else "no arms"
        supports = f" and {len(sc.supports)} support(s)" if sc.supports else ""
        raise ScenarioError(file, "arms", f"no fingertip grasp to analyse: the scenario has "
                            f"{joints}{supports} but no 'fingertips' joint; the grasp analysis "
                            "(form closure) is about frictionless point contacts pushing on the "
                            "object, and welds and mechanical joints are bilateral")
    ignored = [k for k in data if k not in _GRASP_SCENARIO_KEYS]
    obj = data.get("object", {})
    ignored += [f"object.{k}" for k in obj if k != "shape"] if isinstance(obj, Mapping) else []
    ignored += [f"arm {o}" for o in other]
    note = (f"scenario file: analysing the {len(contacts)} fingertip contacts of "
            f"{', '.join(used)} on the object's shape")
    if ignored:
        note += f"; ignored (not about the grasp): {', '.join(ignored)}"
    gf = GraspFile(path, Grasp(tuple(contacts), poly), None, 1.0)
    return GraspInput(gf, "scenario", tuple(names), (note,))


__all__ = [
    "GRASP_JOINT_TYPES",
    "GraspInput",
    "grasp_input_from_data",
    "is_grasp_file",
    "load_grasp_input",
]
