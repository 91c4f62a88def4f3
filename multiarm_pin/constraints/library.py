"""Library of joints built from frictionless point contacts (thesis Sec 3.9.1, Example 3.1).

Every joint except the fingertip grasps is described in a *joint frame* J: its placement in
the object frame (``joint_in_object``) and in the tool frame (``joint_in_tool``, identity by
default); the two coincide when the joint is assembled. In J:

- weld: 6 contacts (3-2-1 planes), 0 DOF;
- revolute about z: 4 contacts on a cylinder of axis z + 1 on the end plane, 1 DOF;
- prismatic along z: two planes (normals x and y) with 3 non-collinear contacts each
  (6 contacts, rank 5), 1 DOF;
- cylindrical along/about z: the revolute without its end contact, 2 DOF;
- universal, rotations about x and y: 3 contacts on a sphere (mutually perpendicular
  normals) + 1 on a plane of normal y with its tip centre on the x axis, 2 DOF
  (the allowed motions are ``Ry(b) Rx(a)`` of the tool side);
- spherical about the origin: 3 contacts on a sphere, 3 DOF;
- corner gripper (Example 3.1): J at a corner of a box occupying x, y, z <= 0; contacts 1 and
  3 on the face z = 0, 2 on y = 0, 4 on x = 0; 2 DOF.

Fingertip grasps (no joint frame) are in :mod:`multiarm_pin.constraints.fingertips`; the
registry of every joint type, and :func:`make_joint`, in
:mod:`multiarm_pin.constraints.joint_types`.

By default the tips are on the tool and the surfaces on the object (``points_on="tool"``).
``size`` [m] is the joint's characteristic length (lever arms of its contacts), ``tip_radius``
[m] the radius of the tips. Placements are ``pin.SE3``, 4x4 matrices, or mappings with
``position`` and one of ``rotation``/``quaternion`` ([x, y, z, w])/``rpy``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pinocchio as pin

from multiarm_pin.constraints.contact import POINT_ON, Contact
from multiarm_pin.constraints.joint import Joint
from multiarm_pin.constraints.surfaces import Cylinder, Plane, Sphere, Surface, make_surface
from multiarm_pin.exceptions import ConstraintError, InputError
from multiarm_pin.spatial import as_array, se3_from

DEFAULT_SIZE = 0.05
"""Default characteristic length of a joint [m]."""

_EX, _EY, _EZ = np.eye(3)


def as_placement(value, name: str = "placement") -> pin.SE3:
    """A placement from a ``pin.SE3``, a 4x4 homogeneous matrix or a mapping.

    Args:
        value: ``pin.SE3``; (4, 4) array; or a mapping with ``position`` [m] and optionally one
            of ``rotation`` (3x3), ``quaternion`` ([x, y, z, w]) or ``rpy`` [rad].
        name: what it is, for messages.

    Raises:
        ConstraintError: anything else, or invalid numbers.
    """
    try:
        if isinstance(value, pin.SE3):
            return value.copy()
        if isinstance(value, Mapping):
            unknown = set(value) - {"position", "rotation", "quaternion", "rpy"}
            if unknown:
                raise InputError(
                    f"{name}: unknown keys {sorted(unknown)}; expected position and one of "
                    "rotation, quaternion [x, y, z, w], rpy"
                )
            return se3_from(
                value.get("position", np.zeros(3)),
                rotation=value.get("rotation"),
                quaternion=value.get("quaternion"),
                rpy=value.get("rpy"),
                name=name,
            )
        H = as_array(value, (4, 4), f"{name} (4x4 homogeneous matrix)")
        return se3_from(H[:3, 3], rotation=H[:3, :3], name=name)
    except InputError as exc:
        raise ConstraintError(str(exc)) from exc


def relative_placement(tool_placement, object_placement) -> pin.SE3:
    """The tool's placement in the object frame, ``oMobject⁻¹ oMtool``."""
    return as_placement(object_placement, "object placement").actInv(
        as_placement(tool_placement, "tool placement")
    )


# -- contacts defined in the joint frame ---------------------------------------------------
def _contact(
    point_J: np.ndarray,
    surface_J: Surface,
    name: str,
    J_in_tool: pin.SE3,
    J_in_object: pin.SE3,
    tip_radius: float,
    points_on: str,
    unilateral: bool = False,
) -> Contact:
    """A contact touching ``surface_J`` at ``point_J`` (both in J), tip on ``points_on``."""
    _, normal, _ = surface_J.local(point_J)
    centre_J = point_J + tip_radius * normal
    carrier, holder = (J_in_tool, J_in_object) if points_on == "tool" else (J_in_object, J_in_tool)
    return Contact(
        point=carrier.act(centre_J),
        surface=surface_J.transformed(holder.rotation, holder.translation),
        radius=tip_radius,
        point_on=points_on,
        name=name,
        unilateral=unilateral,
    )


def _build(
    kind: str,
    spec: Sequence[tuple[Sequence[float], Surface]],
    joint_in_object,
    joint_in_tool,
    tip_radius: float,
    points_on: str,
    expected_dof: int,
    name: str,
    alpha_rows=None,
    unilateral: bool | None = None,
) -> Joint:
    if points_on not in POINT_ON:
        raise ConstraintError(f"{kind}: points_on must be one of {POINT_ON}, got {points_on!r}")
    r = float(tip_radius)
    if not np.isfinite(r) or r < 0:
        raise ConstraintError(f"{kind}: tip_radius must be >= 0 [m], got {tip_radius!r}")
    J_o = as_placement(joint_in_object, f"{kind} joint_in_object")
    J_t = pin.SE3.Identity() if joint_in_tool is None else as_placement(
        joint_in_tool, f"{kind} joint_in_tool"
    )
    contacts = [
        _contact(np.asarray(p, float), s, f"{kind}[{k}]", J_t, J_o, r, points_on)
        for k, (p, s) in enumerate(spec)
    ]
    return Joint(
        contacts,
        tool_in_object=J_o * J_t.inverse(),
        kind=kind,
        name=name or kind,
        expected_dof=expected_dof,
        alpha_rows=alpha_rows,
        unilateral=unilateral,
    )


def _size(size) -> float:
    try:
        s = float(size)
    except (TypeError, ValueError) as exc:
        raise ConstraintError(f"joint size must be a positive length [m], got {size!r}") from exc
    if not np.isfinite(s) or s <= 0:
        raise ConstraintError(f"joint size must be a positive length [m], got {size!r}")
    return s


def _plane_at(p, n) -> tuple[np.ndarray, Plane]:
    p = np.asarray(p, float)
    return p, Plane(p, n)


def weld(joint_in_object, joint_in_tool=None, size: float = DEFAULT_SIZE, tip_radius: float = 0.0,
         points_on: str = "tool", name: str = "",
         unilateral: bool | None = None) -> Joint:
    """A rigid grasp: 6 independent point-on-plane contacts (3-2-1), 0 DOF.

    Like every mechanical joint of this library (revolute, prismatic, ...), its contacts are
    bilateral unless ``unilateral=True`` (then each can only push and may separate).
    """
    L = _size(size)
    h = np.sqrt(3.0) / 2
    spec = [
        _plane_at([L, 0, 0], _EZ),
        _plane_at([-L / 2, h * L, 0], _EZ),
        _plane_at([-L / 2, -h * L, 0], _EZ),
        _plane_at([L, 0, 0], _EY),
        _plane_at([-L, 0, 0], _EY),
        _plane_at([0, L, 0], _EX),
    ]
    return _build("weld", spec, joint_in_object, joint_in_tool, tip_radius, points_on, 0, name,
                  unilateral=unilateral)


def weld_from_placements(tool_placement, object_placement, size: float = DEFAULT_SIZE,
                         name: str = "", unilateral: bool | None = None) -> Joint:
    """A weld that holds the tool where it is at t = 0.

    Args:
        tool_placement: the tool's world placement ``oMtool`` at t = 0.
        object_placement: the object's (COM frame) world placement ``oMobject`` at t = 0.
        size: characteristic length [m] of the contact pattern.
        name: label.
        unilateral: overrides the contacts' flag (bilateral when None).
    """
    return weld(relative_placement(tool_placement, object_placement), None, size, name=name,
                unilateral=unilateral)


def _cylinder_spec(L: float, end: bool):
    cyl = Cylinder(center=np.zeros(3), radius=L, axis=_EZ)
    spec = [
        ([L, 0, L], cyl),
        ([0, L, L], cyl),
        ([L, 0, -L], cyl),
        ([0, L, -L], cyl),
    ]
    if end:
        spec.append(_plane_at([0, 0, L], _EZ))
    return spec


def revolute(joint_in_object, joint_in_tool=None, size: float = DEFAULT_SIZE,
             tip_radius: float = 0.0, points_on: str = "tool", name: str = "",
             unilateral: bool | None = None) -> Joint:
    """Rotation about J's z axis: 4 contacts on a cylinder (radius ``size``) + 1 end, 1 DOF."""
    L = _size(size)
    return _build("revolute", _cylinder_spec(L, True), joint_in_object, joint_in_tool,
                  tip_radius, points_on, 1, name, unilateral=unilateral)


def cylindrical(joint_in_object, joint_in_tool=None, size: float = DEFAULT_SIZE,
                tip_radius: float = 0.0, points_on: str = "tool", name: str = "",
                unilateral: bool | None = None) -> Joint:
    """Rotation about and translation along J's z axis: 4 contacts on a cylinder, 2 DOF."""
    L = _size(size)
    return _build("cylindrical", _cylinder_spec(L, False), joint_in_object, joint_in_tool,
                  tip_radius, points_on, 2, name, unilateral=unilateral)


def prismatic(joint_in_object, joint_in_tool=None, size: float = DEFAULT_SIZE,
              tip_radius: float = 0.0, points_on: str = "tool", name: str = "",
              unilateral: bool | None = None) -> Joint:
    """Translation along J's z axis: planes x = 0 and y = 0, 3 contacts each, 1 DOF.

    The six contacts have rank 5: the last one is dropped as redundant.
    """
    L = _size(size)
    spec = [
        _plane_at([0, 0, L], _EX),
        _plane_at([0, 0, -L], _EX),
        _plane_at([0, L, 0], _EX),
        _plane_at([0, 0, L], _EY),
        _plane_at([0, 0, -L], _EY),
        _plane_at([L, 0, 0], _EY),
    ]
    return _build("prismatic", spec, joint_in_object, joint_in_tool, tip_radius, points_on, 1,
                  name, unilateral=unilateral)


def _sphere_spec(L: float):
    ball = Sphere(center=np.zeros(3), radius=L)
    return [([L, 0, 0], ball), ([0, L, 0], ball), ([0, 0, L], ball)]


def spherical(joint_in_object, joint_in_tool=None, size: float = DEFAULT_SIZE,
              tip_radius: float = 0.0, points_on: str = "tool", name: str = "",
              unilateral: bool | None = None) -> Joint:
    """Rotation about J's origin: 3 contacts on a ball of radius ``size``, 3 DOF."""
    L = _size(size)
    return _build("spherical", _sphere_spec(L), joint_in_object, joint_in_tool, tip_radius,
                  points_on, 3, name, unilateral=unilateral)


def universal(joint_in_object, joint_in_tool=None, size: float = DEFAULT_SIZE,
              tip_radius: float = 0.0, points_on: str = "tool", name: str = "",
              unilateral: bool | None = None) -> Joint:
    """Rotations about J's x and y axes: 3 contacts on a ball + 1 on the plane y = 0, 2 DOF."""
    L = _size(size)
    # the plane contact's tip centre sits on the x axis, so both rotations keep it closed
    spec = _sphere_spec(L) + [_plane_at([2 * L, -float(tip_radius), 0], _EY)]
    return _build("universal", spec, joint_in_object, joint_in_tool, tip_radius, points_on, 2,
                  name, unilateral=unilateral)


def corner_gripper(joint_in_object, joint_in_tool=None, points=None, size: float = DEFAULT_SIZE,
                   tip_radius: float = 0.0, name: str = "", alpha_rows=None,
                   unilateral: bool = True) -> Joint:
    """Example 3.1: a gripper holding a box corner with 4 contacts, 2 DOF.

    Args:
        joint_in_object: placement of the corner frame J in the object frame; the box occupies
            x, y, z <= 0 in J, so the corner's faces have outward normals +x, +y, +z.
        joint_in_tool: placement of J in the tool frame (identity when None).
        points: (4, 3) contact points in J: ``(x1, y1, 0)``, ``(x2, 0, z2)``, ``(x3, y3, 0)``,
            ``(0, y4, z4)`` (contacts 1, 3 on the face z = 0, 2 on y = 0, 4 on x = 0), all
            coordinates <= 0. Default: a pattern scaled by ``size``.
        size: scale of the default pattern [m].
        tip_radius: fingertip radius [m].
        name: label.
        alpha_rows: motion coordinates (e.g. ``["vx", "vy"]`` as in Example 3.1); chosen
            automatically when None.
        unilateral: the four fingertips press on the corner's faces, so they only push
            (True, the default); False holds them as bilateral rows.

    Raises:
        ConstraintError: a point off its face or outside the box, contacts giving fewer than
            4 independent constraints, or ``alpha_rows`` that cannot parametrise the motion
            (``["vx", "vy"]`` needs ``adf + bce != 0``, letters of Example 3.1).
    """
    L = _size(size)
    if points is None:
        pts = L * np.array([[-0.2, -0.8, 0.0], [-0.6, 0.0, -0.3], [-0.9, -0.1, 0.0],
                            [0.0, -0.5, -0.7]])
    else:
        try:
            pts = as_array(points, (4, 3), "corner_gripper points")
        except InputError as exc:
            raise ConstraintError(str(exc)) from exc
    faces = (2, 1, 2, 0)  # coordinate that is zero for contacts 1..4
    for k, (p, f) in enumerate(zip(pts, faces, strict=True)):
        if abs(p[f]) > 1e-9 or np.any(p > 1e-9):
            raise ConstraintError(
                f"corner_gripper: contact {k + 1} at {p.tolist()} must lie on the face "
                f"{'xyz'[f]} = 0 of the box corner with all coordinates <= 0"
            )
    spec = [_plane_at(p, np.eye(3)[f]) for p, f in zip(pts, faces, strict=True)]
    return _build("corner_gripper", spec, joint_in_object, joint_in_tool, tip_radius, "tool", 2,
                  name, alpha_rows, unilateral)


def custom(contacts: Sequence[Mapping], joint_in_object, joint_in_tool=None,
           expected_dof: int | None = None, name: str = "", alpha_rows=None,
           unilateral: bool = False) -> Joint:
    """A joint from explicit contacts defined in the joint frame J.

    Args:
        contacts: mappings with ``point`` (3,) on the surface in J [m], ``surface`` (a mapping
            with ``type`` plane/sphere/cylinder and its parameters in J), and optionally
            ``tip_radius`` [m], ``points_on`` (``"tool"``/``"object"``) and ``unilateral``
            (bool, default: the joint's ``unilateral``).
        joint_in_object: placement of J in the object frame.
        joint_in_tool: placement of J in the tool frame (identity when None).
        expected_dof: if given, the DOF the contacts must leave.
        name: label.
        alpha_rows: motion coordinates (names of ``TWIST_NAMES``); automatic when None.
        unilateral: default of the contacts' own ``unilateral`` flag: False (bilateral rows,
            a mechanical joint, like the rest of the library); True for contacts that only
            push (fingertips).
    """
    J_o = as_placement(joint_in_object, "custom joint_in_object")
    J_t = pin.SE3.Identity() if joint_in_tool is None else as_placement(
        joint_in_tool, "custom joint_in_tool"
    )
    built = []
    for k, c in enumerate(contacts):
        try:
            surf = dict(c["surface"])
            kind = surf.pop("type")
            point = as_array(c["point"], (3,), f"contact {k} point")
        except (KeyError, TypeError, InputError) as exc:
            raise ConstraintError(
                f"custom joint contact {k}: expected point and surface {{type, ...}}: {exc}"
            ) from exc
        built.append(
            _contact(point, make_surface(kind, **surf), f"contact[{k}]", J_t, J_o,
                     float(c.get("tip_radius", 0.0)), c.get("points_on", "tool"),
                     c.get("unilateral", unilateral))
        )
    return Joint(built, J_o * J_t.inverse(), kind="custom", name=name or "custom",
                 expected_dof=expected_dof, alpha_rows=alpha_rows)


__all__ = [
    "DEFAULT_SIZE",
    "as_placement",
    "corner_gripper",
    "custom",
    "cylindrical",
    "prismatic",
    "relative_placement",
    "revolute",
    "spherical",
    "universal",
    "weld",
    "weld_from_placements",
]
