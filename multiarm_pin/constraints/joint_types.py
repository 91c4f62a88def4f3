"""The registry of joint types: one entry per name, and the one place joints are built by name.

:data:`JOINT_TYPES` maps each type name (the name a scenario file uses too) to a
:class:`JointType`: its builder, the DOF it leaves between tool and object, whether it can be
built where the tool is at t = 0, whether it is made of fingertip contacts on the object's
faces (then it needs the object's shape instead of a joint frame), and the default
``unilateral`` flag of its contacts. :func:`make_joint` (explicit placements),
:func:`make_joint_from_placements` (the tool where it is at t = 0),
:func:`multiarm_pin.system.joints_from_initial_state` and the scenario reader all dispatch
through it; an unknown name raises a :class:`~multiarm_pin.exceptions.ConstraintError` listing
the known ones, with a did-you-mean.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from dataclasses import dataclass

from multiarm_pin._registry import lookup
from multiarm_pin.constraints import library as lib
from multiarm_pin.constraints.fingertips import fingertips_from_placements, fingertips_on_faces
from multiarm_pin.constraints.joint import Joint
from multiarm_pin.exceptions import ConstraintError


@dataclass(frozen=True)
class JointType:
    """One joint type of the registry.

    Attributes:
        name: the type name (``Joint.kind`` of the joints it builds, and the scenario name).
        builder: ``builder(**params) -> Joint`` (:func:`make_joint`'s parameters).
        dof: degrees of freedom it leaves between tool and object, or None when they depend
            on the contacts given (fingertips, custom).
        placeable: it can be built where the tool is at t = 0
            (:func:`make_joint_from_placements`).
        from_contacts: it is made of fingertip contacts on the object's faces (given as
            ``contacts`` = ``[(face, point_in_object), ...]`` and ``radius``; it needs the
            object's shape), not placed by a joint frame.
        unilateral: default of its contacts' ``unilateral`` flag (True: they only push).
        description: one line for humans.
    """

    name: str
    builder: Callable[..., Joint]
    dof: int | None
    placeable: bool
    from_contacts: bool
    unilateral: bool
    description: str

    @property
    def parameters(self) -> tuple[str, ...]:
        """Names of the builder's keyword parameters."""
        return tuple(inspect.signature(self.builder).parameters)


JOINT_TYPES: dict[str, JointType] = {e.name: e for e in (
    JointType("weld", lib.weld, 0, True, False, False,
              "rigid grasp: 6 point-on-plane contacts (3-2-1)"),
    JointType("revolute", lib.revolute, 1, True, False, False,
              "rotation about J's z axis: 4 contacts on a cylinder + 1 on its end plane"),
    JointType("prismatic", lib.prismatic, 1, True, False, False,
              "translation along J's z axis: 2 planes, 3 contacts each (rank 5)"),
    JointType("cylindrical", lib.cylindrical, 2, True, False, False,
              "rotation about and translation along J's z axis: 4 contacts on a cylinder"),
    JointType("universal", lib.universal, 2, True, False, False,
              "rotations about J's x and y axes: 3 contacts on a ball + 1 on a plane"),
    JointType("spherical", lib.spherical, 3, True, False, False,
              "rotation about J's origin: 3 contacts on a ball"),
    JointType("corner_gripper", lib.corner_gripper, 2, True, False, True,
              "Example 3.1: 4 tips pressing on a box corner at J (box in x, y, z <= 0)"),
    JointType("fingertips", fingertips_on_faces, None, True, True, True,
              "spherical fingertips of the tool touching faces of the polyhedral object"),
    JointType("custom", lib.custom, None, False, False, False,
              "explicit contacts (points and surfaces) in a joint frame J"),
)}
"""Every joint type, by name (the name scenarios use)."""


def joint_type(kind: str) -> JointType:
    """The registry entry of ``kind``.

    Raises:
        ConstraintError: unknown type (lists the known ones, with a did-you-mean).
    """
    return lookup(JOINT_TYPES, kind, "joint type", ConstraintError, "types")


def _call(kind: str, build: Callable[..., Joint], params: dict, **placement) -> Joint:
    try:
        return build(**placement, **params)
    except TypeError as exc:
        raise ConstraintError(f"joint {kind!r}: bad parameters {sorted(params)}: {exc}") from exc


def make_joint(kind: str, **params) -> Joint:
    """Build a joint by type name from plain parameters (e.g. read from YAML).

    Args:
        kind: a name of :data:`JOINT_TYPES`.
        **params: the keyword arguments of its builder.

    Raises:
        ConstraintError: unknown type (the message lists the known ones), or bad parameters.
    """
    return _call(kind, joint_type(kind).builder, params)


def make_joint_from_placements(kind: str, tool_placement, object_placement, **params) -> Joint:
    """A joint built where the tool is at t = 0.

    For a type placed by a joint frame (weld, revolute, ..., corner_gripper) the joint frame J
    is the tool frame at t = 0; for fingertips the tips are where the tool holds them
    (:func:`~multiarm_pin.constraints.fingertips.fingertips_from_placements`).

    Args:
        kind: a name of :data:`JOINT_TYPES` whose entry is ``placeable``.
        tool_placement: tool world placement ``oMtool`` at t = 0.
        object_placement: object (COM frame) world placement ``oMobject`` at t = 0.
        **params: other parameters of that type (``size``, ``tip_radius``, ...; for
            fingertips ``polyhedron``, ``contacts``, ``radius``).

    Raises:
        ConstraintError: unknown or not placeable type (the message lists the placeable
            ones), or bad parameters.
    """
    placeable = {k: e for k, e in JOINT_TYPES.items() if e.placeable}
    try:
        entry = lookup(placeable, kind, "joint type", ConstraintError, "types")
    except ConstraintError as exc:
        raise ConstraintError(f"{exc} (the other types cannot be built from the initial "
                              "state)") from None
    if entry.from_contacts:
        return _call(kind, fingertips_from_placements, params, tool_placement=tool_placement,
                     object_placement=object_placement)
    M = lib.relative_placement(tool_placement, object_placement)
    return _call(kind, entry.builder, params, joint_in_object=M, joint_in_tool=None)


__all__ = ["JOINT_TYPES", "JointType", "joint_type", "make_joint", "make_joint_from_placements"]
