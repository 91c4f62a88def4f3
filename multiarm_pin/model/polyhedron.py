"""Convex polyhedra: the shape of the manipulated object.

A :class:`Polyhedron` is described in its own frame by its vertices and its faces, each
face a plane ``n·x = d`` with unit outward normal ``n`` (the interior is ``n·x <= d``).
Lengths are in metres.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from multiarm_pin.exceptions import InputError
from multiarm_pin.spatial import as_array

BOX_FACE_NAMES = ("+x", "-x", "+y", "-y", "+z", "-z")


@dataclass(frozen=True)
class Polyhedron:
    """A convex polyhedron in its own frame.

    Attributes:
        vertices: (V, 3) vertex positions [m].
        normals: (F, 3) unit outward face normals.
        offsets: (F,) plane offsets [m]: face k is ``normals[k] · x = offsets[k]``.
        faces: for each face, the vertex indices in counter-clockwise order seen from outside.
        face_names: optional name of each face (a box has ``+x -x +y -y +z -z``).
    """

    vertices: np.ndarray
    normals: np.ndarray
    offsets: np.ndarray
    faces: tuple[tuple[int, ...], ...]
    face_names: tuple[str, ...] = field(default=())

    @property
    def n_faces(self) -> int:
        """Number of faces F."""
        return len(self.offsets)

    def face_index(self, face: int | str) -> int:
        """Index of a face given by index or by name.

        Raises:
            InputError: index out of range or unknown name (the message lists the valid ones).
        """
        if isinstance(face, str):
            if face in self.face_names:
                return self.face_names.index(face)
            raise InputError(
                f"unknown face {face!r}; faces: {', '.join(self.face_names) or '(unnamed)'}"
                f" or an index 0..{self.n_faces - 1}"
            )
        if isinstance(face, bool) or not isinstance(face, int | np.integer):
            raise InputError(f"face must be an index or a name, got {face!r}")
        if not 0 <= face < self.n_faces:
            raise InputError(f"face index {face} out of range 0..{self.n_faces - 1}")
        return int(face)

    def signed_distance_to_face(self, point: np.ndarray, face: int | str) -> float:
        """``n_k · p - d_k`` [m]: zero on the face's plane, negative inside."""
        k = self.face_index(face)
        return float(self.normals[k] @ point - self.offsets[k])

    def contains(self, point: np.ndarray, tol: float = 1e-9) -> bool:
        """True when ``point`` (3,) is inside or on the boundary (within ``tol`` m)."""
        return bool(np.all(self.normals @ point - self.offsets <= tol))

    def point_on_face(self, point: np.ndarray, face: int | str, tol: float = 1e-6) -> bool:
        """True when ``point`` lies on face ``face``'s plane and inside the polyhedron."""
        return abs(self.signed_distance_to_face(point, face)) <= tol and self.contains(point, tol)

    def face_frame(self, face: int | str) -> tuple[np.ndarray, np.ndarray]:
        """Origin (3,) and axes (3, 3) of a face's own 2-D coordinates.

        Returns:
            ``(origin, R)``: origin is the face's vertex centroid; ``R``'s columns are
            ``u, v, n`` with ``n`` the outward normal and ``u, v`` spanning the face, so a
            face point is ``origin + s u + t v``.
        """
        k = self.face_index(face)
        n = self.normals[k]
        origin = self.vertices[list(self.faces[k])].mean(axis=0)
        a = self.vertices[self.faces[k][0]] - origin
        u = a - (a @ n) * n
        u /= np.linalg.norm(u)
        v = np.cross(n, u)
        return origin, np.column_stack([u, v, n])

    def mass_properties(self, mass: float) -> tuple[np.ndarray, np.ndarray]:
        """Centre of mass (3,) [m] and inertia (3, 3) [kg m^2] about it, for uniform density."""
        return _solid_mass_properties(self, mass)

    @property
    def volume(self) -> float:
        """Volume [m^3]."""
        return _solid_integrals(self)[0]


def box(size) -> Polyhedron:
    """A box centred on its frame with edge lengths ``size = [sx, sy, sz]`` [m]."""
    s = as_array(size, (3,), "box size")
    if np.any(s <= 0):
        raise InputError(f"box size: expected three positive lengths, got {s.tolist()}")
    h = s / 2
    signs = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], dtype=float)
    vertices = signs * h
    normals = np.array(
        [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=float
    )
    offsets = np.array([h[0], h[0], h[1], h[1], h[2], h[2]])
    faces = tuple(_ordered_face(vertices, n, d) for n, d in zip(normals, offsets, strict=True))
    return Polyhedron(vertices, normals, offsets, faces, BOX_FACE_NAMES)


def from_vertices(vertices, tol: float = 1e-9) -> Polyhedron:
    """The convex hull of a point set (V, 3) [m], with coplanar hull triangles merged.

    Raises:
        InputError: fewer than 4 points, or all points coplanar.
    """
    pts = as_array(vertices, (None, 3), "polyhedron vertices")
    if len(pts) < 4:
        raise InputError(f"polyhedron vertices: need at least 4 points, got {len(pts)}")
    try:
        hull = ConvexHull(pts)
    except QhullError as exc:
        raise InputError("polyhedron vertices: the points are coplanar or degenerate") from exc
    used = np.unique(hull.simplices)
    verts = pts[used]
    planes: list[tuple[np.ndarray, float]] = []
    for eq in hull.equations:
        n, d = eq[:3], -eq[3]
        scale = np.linalg.norm(n)
        n, d = n / scale, d / scale
        if not any(np.allclose(n, m, atol=1e-7) and abs(d - e) < 1e-7 for m, e in planes):
            planes.append((n, d))
    normals = np.array([p[0] for p in planes])
    offsets = np.array([p[1] for p in planes])
    faces = tuple(_ordered_face(verts, n, d, tol=1e-7) for n, d in planes)
    return Polyhedron(verts, normals, offsets, faces, ())


def _ordered_face(vertices: np.ndarray, n: np.ndarray, d: float, tol: float = 1e-9):
    idx = np.flatnonzero(np.abs(vertices @ n - d) <= tol * max(1.0, abs(d)))
    c = vertices[idx].mean(axis=0)
    a = vertices[idx[0]] - c
    u = a / np.linalg.norm(a)
    v = np.cross(n, u)
    ang = np.arctan2((vertices[idx] - c) @ v, (vertices[idx] - c) @ u)
    # Counter-clockwise from the first vertex, in [0, 2π): the first vertex is at angle 0 by
    # construction (rounding may give it -1e-17), and a vertex opposite it lies at ±π up to
    # rounding; with angles in (-π, π] its place would depend on the BLAS kernel's sign of 0.
    ang = np.where(ang < 0.0, ang + 2.0 * np.pi, ang)
    ang[0] = 0.0
    return tuple(int(i) for i in idx[np.argsort(ang, kind="stable")])


def _solid_integrals(poly: Polyhedron) -> tuple[float, np.ndarray, np.ndarray]:
    """Volume, first moments (3,) and second moments (3, 3) ∫ x xᵀ dV about the frame origin."""
    c0 = poly.vertices.mean(axis=0)
    vol = 0.0
    first = np.zeros(3)
    second = np.zeros((3, 3))
    for face in poly.faces:
        p0 = poly.vertices[face[0]]
        for j in range(1, len(face) - 1):
            tet = np.array([c0, p0, poly.vertices[face[j]], poly.vertices[face[j + 1]]])
            v = abs(np.linalg.det(tet[1:] - tet[0])) / 6.0
            s = tet.sum(axis=0)
            vol += v
            first += v * s / 4.0
            second += v / 20.0 * (np.outer(s, s) + tet.T @ tet)
    return vol, first, second


def _solid_mass_properties(poly: Polyhedron, mass: float) -> tuple[np.ndarray, np.ndarray]:
    vol, first, second = _solid_integrals(poly)
    rho = mass / vol
    com = first / vol
    second_com = rho * second - mass * np.outer(com, com)
    inertia = np.trace(second_com) * np.eye(3) - second_com
    return com, 0.5 * (inertia + inertia.T)
