"""Fingertip grasps: spherical tips of one arm's tool touching faces of a polyhedral object.

Unlike the joints of :mod:`multiarm_pin.constraints.library`, a fingertip grasp has no joint
frame: it is given by its contacts, ``(face, point_in_object)`` pairs, and the tips' centres in
the tool frame (or the tool's placement at t = 0, from which the centres follow). Each tip is
a sphere of radius ``radius`` [m] touching the face's plane; its contacts are unilateral by
default (they push, and may separate).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from multiarm_pin.constraints.contact import Contact
from multiarm_pin.constraints.joint import Joint
from multiarm_pin.constraints.library import as_placement, relative_placement
from multiarm_pin.constraints.surfaces import Plane
from multiarm_pin.exceptions import ConstraintError, InputError
from multiarm_pin.model.polyhedron import Polyhedron
from multiarm_pin.spatial import as_array


def fingertips_on_faces(
    polyhedron: Polyhedron,
    contacts: Sequence[tuple[int | str, Sequence[float]]],
    radius: float,
    tip_points_in_tool,
    tool_in_object=None,
    name: str = "",
    tol: float = 1e-6,
    unilateral: bool = True,
    starts_apart: bool = False,
) -> Joint:
    """Spherical fingertips of one arm's tool touching faces of a polyhedral object.

    Args:
        polyhedron: the object's shape in the object (COM) frame.
        contacts: ``[(face, point_in_object), ...]``: face index or name, and the contact
            point (3,) on that face in the object frame [m].
        radius: fingertip radius [m] (0 for sharp points).
        tip_points_in_tool: (n, 3) fingertip centres in the tool frame [m].
        tool_in_object: the tool's placement in the object frame at assembly; fitted to the
            tips (least squares rigid fit) when None.
        name: label.
        tol: largest mismatch [m] between the tips and the contact points.
        unilateral: fingertips on faces only push (True, the default); False holds them as
            bilateral rows.
        starts_apart: the tips may start away from their faces (positive gaps) and touch
            down during the run (:class:`~multiarm_pin.constraints.joint.Joint`).

    Raises:
        ConstraintError: a point off its face, a count mismatch, or tips that no rigid
            placement of the tool brings onto the contact points.
    """
    try:
        tips = as_array(tip_points_in_tool, (None, 3), "tip_points_in_tool")
    except InputError as exc:
        raise ConstraintError(str(exc)) from exc
    centres, planes = _face_contacts(polyhedron, contacts, radius, tol)
    if len(tips) != len(centres):
        raise ConstraintError(
            f"fingertips_on_faces: {len(centres)} contacts but {len(tips)} tip points"
        )
    if tool_in_object is None:
        M = _rigid_fit(tips, centres)
    else:
        M = as_placement(tool_in_object, "tool_in_object")
    contact_list = [
        Contact(point=t, surface=pl, radius=float(radius), point_on="tool", name=f"tip[{k}]",
                unilateral=bool(unilateral))
        for k, (t, pl) in enumerate(zip(tips, planes, strict=True))
    ]
    try:
        return Joint(contact_list, M, kind="fingertips", name=name or "fingertips",
                     gap_tolerance=tol, starts_apart=starts_apart)
    except ConstraintError as exc:
        raise ConstraintError(f"fingertips_on_faces: tips do not match the points: {exc}") from exc


def fingertips_from_placements(polyhedron: Polyhedron, contacts, radius: float, tool_placement,
                               object_placement, name: str = "", tol: float = 1e-6,
                               unilateral: bool = True, starts_apart: bool = False) -> Joint:
    """Fingertips placed where they are at t = 0 (tips computed from the initial placements).

    Args:
        polyhedron: the object's shape in the object (COM) frame.
        contacts: ``[(face, point_in_object), ...]`` as in :func:`fingertips_on_faces`.
        radius: fingertip radius [m].
        tool_placement: tool world placement at t = 0.
        object_placement: object (COM frame) world placement at t = 0.
        name: label.
        tol: tolerance [m] for points on faces.
        unilateral: as in :func:`fingertips_on_faces`.
        starts_apart: as in :func:`fingertips_on_faces`.
    """
    M = relative_placement(tool_placement, object_placement)
    centres, _ = _face_contacts(polyhedron, contacts, radius, tol)
    tips = np.array([M.actInv(c) for c in centres])
    return fingertips_on_faces(polyhedron, contacts, radius, tips, M, name, tol, unilateral,
                               starts_apart)


def _face_contacts(polyhedron, contacts, radius, tol):
    r = float(radius)
    if not np.isfinite(r) or r < 0:
        raise ConstraintError(f"fingertip radius must be >= 0 [m], got {radius!r}")
    if len(contacts) == 0:
        raise ConstraintError("fingertips_on_faces: needs at least one (face, point) contact")
    centres, planes = [], []
    for k, item in enumerate(contacts):
        try:
            face, point = item
        except (TypeError, ValueError) as exc:
            raise ConstraintError(
                f"fingertip contact {k}: expected (face, point_in_object), got {item!r}"
            ) from exc
        try:
            f = polyhedron.face_index(face)
            p = as_array(point, (3,), f"fingertip contact {k} point")
        except InputError as exc:
            raise ConstraintError(f"fingertip contact {k}: {exc}") from exc
        if not polyhedron.point_on_face(p, f, tol):
            raise ConstraintError(
                f"fingertip contact {k}: point {p.tolist()} is not on face {face!r} "
                f"(distance to its plane {polyhedron.signed_distance_to_face(p, f):.3g} m, "
                f"tolerance {tol:g} m) or lies outside the polyhedron"
            )
        n = polyhedron.normals[f]
        centres.append(p + r * n)
        planes.append(Plane(p, n))
    return np.array(centres), planes


def _rigid_fit(tips_in_tool: np.ndarray, centres_in_object: np.ndarray) -> pin.SE3:
    """Least-squares placement M (tool in object) with ``M * tips ≈ centres`` (Kabsch)."""
    a0, b0 = tips_in_tool.mean(axis=0), centres_in_object.mean(axis=0)
    H = (tips_in_tool - a0).T @ (centres_in_object - b0)
    U, _, Vt = np.linalg.svd(H)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0])
    R = Vt.T @ D @ U.T
    return pin.SE3(R, b0 - R @ a0)



__all__ = ["fingertips_from_placements", "fingertips_on_faces"]
