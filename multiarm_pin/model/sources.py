"""Where arm models come from: the robot registry and URDF files, and what loading needs.

:func:`load_example_robot` loads a registered robot once per process
(:meth:`~multiarm_pin.model.robots.RobotEntry.load`), :func:`validate_urdf` checks a URDF file
with ``yourdfpy`` before Pinocchio reads it, :func:`lock_joints` locks joints at their neutral
value, and :func:`frame_id` / :func:`unique_frame_names` cope with URDFs that give a link and
a joint the same name. :class:`~multiarm_pin.model.arm.Arm` builds on them.
"""

from __future__ import annotations

import functools
from pathlib import Path

import pinocchio as pin

from multiarm_pin.exceptions import FrameNotFoundError, JointNotFoundError, URDFError
from multiarm_pin.model.robots import robot_entry


def frame_id(model: pin.Model, name: str, source: str = "") -> int:
    """Id of the frame called ``name``; when several share it, the body frame (then any).

    Some URDFs give a link and its parent joint the same name (Unitree Z1's
    ``gripperStator``), which ``model.getFrameId(name)`` refuses.

    Raises:
        FrameNotFoundError: no frame has that name (lists the frames).
    """
    ids = [i for i, f in enumerate(model.frames) if f.name == name]
    if not ids:
        raise FrameNotFoundError(name, [f.name for f in model.frames], source)
    for kind in (pin.FrameType.OP_FRAME, pin.FrameType.BODY):
        for i in ids:
            if model.frames[i].type == kind:
                return i
    return ids[0]


@functools.cache
def load_example_robot(robot: str) -> tuple[pin.Model, pin.GeometryModel]:
    """The registry entry's model and visual model (:meth:`RobotEntry.load`), once per process.

    Loading parses the URDF and reads every mesh (seconds for some robots); callers never
    modify the cached objects (reducing and appending them makes copies).
    """
    wrapper = robot_entry(robot).load()
    return wrapper.model, wrapper.visual_model


def unique_frame_names(model: pin.Model) -> pin.Model:
    """A copy of ``model`` whose frames have unique names (``pin.appendModel`` needs them).

    A frame sharing its name with a body frame is renamed ``<name>_<type>`` (Unitree Z1's
    fixed joint ``gripperStator`` becomes ``gripperStator_fixed_joint``); the body keeps it.
    """
    names = [f.name for f in model.frames]
    if len(set(names)) == len(names):
        return model
    model = model.copy()
    for i, n in enumerate(names):
        if names.count(n) > 1 and i != frame_id(model, n):
            fr = model.frames[i]
            fr.name = f"{n}_{str(fr.type).split('.')[-1].lower()}"
            model.frames[i] = fr
    return model


def lock_joints(model: pin.Model, visual, joints, source: str):
    """Lock ``joints`` at their neutral value; returns ``(model, visual)``."""
    missing = [j for j in joints if not model.existJointName(j)]
    if missing:
        raise JointNotFoundError(missing, list(model.names)[1:], source)
    ids = [model.getJointId(j) for j in joints]
    q_ref = pin.neutral(model)
    if visual is not None:
        return pin.buildReducedModel(model, visual, ids, q_ref)
    return pin.buildReducedModel(model, ids, q_ref), None


def validate_urdf(path: str | Path) -> None:
    """Check that ``path`` is a readable, well-formed URDF robot, with ``yourdfpy``.

    Raises:
        URDFError: naming the file and what is wrong.
    """
    path = Path(path)
    if not path.is_file():
        raise URDFError(str(path), "file not found")
    import xml.etree.ElementTree as ET

    import yourdfpy

    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise URDFError(str(path), f"malformed URDF (XML error: {exc})") from exc
    if root.tag != "robot":
        raise URDFError(str(path), f"malformed URDF: root element is <{root.tag}>, not <robot>")
    try:
        urdf = yourdfpy.URDF.load(
            str(path), build_scene_graph=False, load_meshes=False, load_collision_meshes=False
        )
    except Exception as exc:  # lxml / yourdfpy raise many types for malformed XML
        raise URDFError(str(path), f"malformed URDF: {exc}") from exc
    if urdf.robot is None or not urdf.robot.links:
        raise URDFError(str(path), "no <robot> with links found")
    try:
        ok = urdf.validate()
    except Exception as exc:
        raise URDFError(str(path), f"invalid URDF: {exc}") from exc
    if ok is False:
        raise URDFError(str(path), "invalid URDF (yourdfpy validation failed)")


__all__ = ["frame_id", "load_example_robot", "lock_joints", "unique_frame_names", "validate_urdf"]
