"""Frictionless point contacts on a polyhedral object and their zero-pitch wrenches.

A contact is a point ``p`` on the object's surface with the object's *inward* unit normal
``n`` (the direction in which the contact pushes the object). Its unit wrench on the object
about an origin ``o`` is ``[n; (p - o) × n]`` (THESIS_MAP, Eq 2.1-2.4). All points and
normals are expressed in the object frame; lengths in metres.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from multiarm_pin.exceptions import GraspError, InputError
from multiarm_pin.model.polyhedron import Polyhedron
from multiarm_pin.spatial import as_array

ON_FACE_TOLERANCE = 1e-6
"""Largest accepted distance [m] between a contact point and its face."""


@dataclass(frozen=True)
class GraspContact:
    """One frictionless point contact of a grasp analysis (a point and a normal on the object).

    Not the constraint layer's :class:`multiarm_pin.constraints.contact.Contact`, which joins
    a tool and the object in the dynamics (with ``W``, ``T``, ``φ``); the grasp analysis needs
    only the contact's wrench.

    Attributes:
        point: (3,) contact point in the object frame [m].
        normal: (3,) unit *inward* normal of the object at the point (object frame).
        face: index of the polyhedron face the contact lies on, or -1 when unknown.
        label: the face name or a user label, for reports.
    """

    point: np.ndarray
    normal: np.ndarray
    face: int = -1
    label: str = ""

    def wrench(self, origin: np.ndarray | None = None, length_scale: float = 1.0) -> np.ndarray:
        """Unit wrench ``[n; (p - o) × n / L]`` (6,) of the contact on the object.

        Args:
            origin: (3,) moment reference point in the object frame [m] (default: the origin).
            length_scale: ``L`` [m]; moments are divided by it to make them dimensionless.
        """
        o = np.zeros(3) if origin is None else origin
        return np.concatenate([self.normal, np.cross(self.point - o, self.normal) / length_scale])


@dataclass(frozen=True)
class Grasp:
    """A set of contacts on an object.

    Attributes:
        contacts: the contacts (``check_independence`` and ``region_by_inverse`` take the
            first six by default; the report's regions do not depend on the order:
            :func:`~multiarm_pin.grasp.seventh_contact.seventh_contact_regions`).
        polyhedron: the object's shape in the object frame, or ``None`` for bare contacts.
    """

    contacts: tuple[GraspContact, ...]
    polyhedron: Polyhedron | None = None

    def __len__(self) -> int:
        return len(self.contacts)

    @property
    def points(self) -> np.ndarray:
        """(N, 3) contact points [m], object frame."""
        return np.array([c.point for c in self.contacts]).reshape(-1, 3)

    @property
    def normals(self) -> np.ndarray:
        """(N, 3) inward unit normals, object frame."""
        return np.array([c.normal for c in self.contacts]).reshape(-1, 3)

    def wrenches(self, origin: np.ndarray | None = None, length_scale: float = 1.0) -> np.ndarray:
        """The wrench matrix (6, N): column k is ``[n_k; (p_k - o) × n_k / L]``."""
        return wrench_matrix(self.points, self.normals, origin, length_scale)

    def with_contacts(self, contacts: Sequence[GraspContact]) -> Grasp:
        """The same object with other contacts."""
        return Grasp(tuple(contacts), self.polyhedron)


def wrench_matrix(
    points: np.ndarray,
    normals: np.ndarray,
    origin: np.ndarray | None = None,
    length_scale: float = 1.0,
) -> np.ndarray:
    """Zero-pitch unit wrenches of frictionless contacts, as columns.

    Args:
        points: (N, 3) contact points [m].
        normals: (N, 3) inward unit normals (directions the contacts push the object).
        origin: (3,) moment reference point [m], same frame; default the frame origin.
        length_scale: ``L`` [m] dividing the moment rows (1 keeps them in metres).

    Returns:
        (6, N) matrix; column k is ``[n_k; (p_k - o) × n_k / L]``.
    """
    p = as_array(points, (None, 3), "contact points")
    n = as_array(normals, (None, 3), "contact normals")
    if len(p) != len(n):
        raise InputError(f"contact points and normals: got {len(p)} points and {len(n)} normals")
    if length_scale <= 0:
        raise InputError(f"length_scale: expected a positive length [m], got {length_scale}")
    o = np.zeros(3) if origin is None else as_array(origin, (3,), "origin")
    return np.vstack([n.T, np.cross(p - o, n).T / length_scale])


def contact_on_face(
    polyhedron: Polyhedron, face: int | str, point, tol: float = ON_FACE_TOLERANCE
) -> GraspContact:
    """A contact at ``point`` on face ``face`` of ``polyhedron``, pushing inwards.

    Args:
        polyhedron: the object's shape (object frame).
        face: face index or name (a box has ``+x -x +y -y +z -z``).
        point: (3,) contact point in the object frame [m]; must lie on the face.
        tol: accepted distance [m] from the face.

    Raises:
        GraspError: unknown face, or the point is not on the face (the message gives the
            distance to the face's plane and whether it is outside the face's edges).
    """
    try:
        k = polyhedron.face_index(face)
    except InputError as exc:
        raise GraspError(f"contact face: {exc}") from exc
    p = _point(point)
    dist = polyhedron.signed_distance_to_face(p, k)
    name = _face_name(polyhedron, k)
    if abs(dist) > tol:
        raise GraspError(
            f"contact point {p.tolist()} is not on face {name}: it is {dist:+.6g} m from the "
            f"face's plane (expected |distance| <= {tol:g} m)"
        )
    if not polyhedron.contains(p, tol):
        worst = float(np.max(polyhedron.normals @ p - polyhedron.offsets))
        raise GraspError(
            f"contact point {p.tolist()} is on the plane of face {name} but outside the face "
            f"by {worst:.6g} m (expected a point inside the face's edges)"
        )
    return GraspContact(p, -polyhedron.normals[k].copy(), k, name)


def contact_from_point_normal(
    point,
    normal,
    polyhedron: Polyhedron | None = None,
    tol: float = ON_FACE_TOLERANCE,
    label: str = "",
) -> GraspContact:
    """A contact from a point and an inward normal, matched to a face when a shape is given.

    Args:
        point: (3,) contact point, object frame [m].
        normal: (3,) inward normal (normalised here; must be non-zero).
        polyhedron: when given, the point must lie on a face whose inward normal is ``normal``.
        tol: distance [m] / normal-difference tolerance for the match.
        label: optional label for reports.

    Raises:
        GraspError: zero normal, or no face of ``polyhedron`` contains the point with that
            inward normal.
    """
    p = _point(point)
    n = as_array(normal, (3,), "contact normal")
    norm = float(np.linalg.norm(n))
    if norm < 1e-12:
        raise GraspError(f"contact normal: expected a non-zero vector, got {n.tolist()}")
    n = n / norm
    if polyhedron is None:
        return GraspContact(p, n, -1, label)
    for k in range(polyhedron.n_faces):
        if np.allclose(-polyhedron.normals[k], n, atol=max(tol, 1e-9)) and polyhedron.point_on_face(
            p, k, tol
        ):
            return GraspContact(p, -polyhedron.normals[k].copy(), k,
                                label or _face_name(polyhedron, k))
    raise GraspError(
        f"contact at {p.tolist()} with inward normal {np.round(n, 9).tolist()}: no face of the "
        "polyhedron contains this point with this inward normal (expected the point on a face "
        "and the normal equal to minus that face's outward normal)"
    )


def _point(point) -> np.ndarray:
    try:
        return as_array(point, (3,), "contact point")
    except InputError as exc:
        raise GraspError(str(exc)) from exc


def _face_name(polyhedron: Polyhedron, k: int) -> str:
    return polyhedron.face_names[k] if polyhedron.face_names else f"#{k}"
