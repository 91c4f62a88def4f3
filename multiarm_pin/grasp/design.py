"""Design helpers for grasping large objects with two fixed grippers (thesis Sec 2.2.3).

* Boxes (Sec 2.2.3.1): gripper 1 holds three contacts near the corner ``(+l_x, +l_y, +l_z)``
  at distance ``A`` from the edges (the top one at ``E`` from the x edge), gripper 2 the
  mirrored three at the opposite corner. With Example 2.1's
  ``a = l_y - A, b = l_z - A, c = l_x - A, d = l_z - A, e = l_x - E, f = l_y - A`` a seventh
  contact on the top face on the line ``y = f`` closes the grasp iff it is further than
  ``D_x = |2 det(a_A) / (a d)| = |2 (A - E)|`` from the top contact (on the side away from
  the corner when ``A > E``): the layout works for every box large enough to hold it.
* Objects with three pairs of parallel planes (Sec 2.2.3.2, Example 2.3): the same idea on a
  centrally symmetric hexahedron whose faces have inward normals ``e1 = -(cos θ, 0, sin θ)``,
  ``e2 = -(sin β cos γ, cos β cos γ, sin γ)``, ``e3 = -(0, 0, 1)``; the minimal offset of the
  seventh contact is found from the region of Eq 2.3.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from multiarm_pin.exceptions import GraspError
from multiarm_pin.grasp.contacts import Grasp, contact_on_face
from multiarm_pin.grasp.seventh_contact import ContactRegion, region_by_inverse
from multiarm_pin.model.polyhedron import Polyhedron, box, from_vertices
from multiarm_pin.spatial import as_array


def seventh_offset_min(A: float, E: float) -> float:
    """``D_x = |2 (A - E)|`` [m]: minimal distance from the top contact to the seventh one."""
    return abs(2.0 * (A - E))


def two_corner_box_grasp(size, A: float, E: float, D: float) -> Grasp:
    """Seven contacts from two fixed grippers at opposite corners of a box (Sec 2.2.3.1).

    Args:
        size: (3,) box edge lengths [m]; half-sizes ``l = size / 2``.
        A: distance [m] of the corner contacts from the edges (front, side, and the top
            contact's y offset).
        E: distance [m] of the top contact from the x edge.
        D: distance [m] along x from the top contact to the seventh contact (also on top,
            on ``y = f``), placed away from the corner when ``A > E`` and towards it when
            ``A < E``; closure needs ``D > |2 (A - E)|``.

    Returns:
        A :class:`Grasp` with contacts ``p1 (+x), p2 (+y), p3 (+z), -p1 (-x), -p2 (-y),
        -p3 (-z)`` and the seventh on +z.

    Raises:
        GraspError: a contact falls off its face, or ``A == E`` (dependent contacts).
    """
    s = as_array(size, (3,), "box size")
    if A == E:
        raise GraspError("two-corner box grasp: A == E makes det(a_A) = 0 (dependent contacts)")
    poly = box(s)
    h = s / 2
    a, b, c, d, e, f = h[1] - A, h[2] - A, h[0] - A, h[2] - A, h[0] - E, h[1] - A
    p1, p2, p3 = np.array([h[0], a, b]), np.array([c, h[1], d]), np.array([e, f, h[2]])
    x7 = e - D if A > E else e + D
    specs = [("+x", p1), ("+y", p2), ("+z", p3), ("-x", -p1), ("-y", -p2), ("-z", -p3),
             ("+z", np.array([x7, f, h[2]]))]  # fmt: skip
    return Grasp(tuple(contact_on_face(poly, fc, p) for fc, p in specs), poly)


def parallel_planes_object(theta: float, beta: float, gamma: float, corner) -> Polyhedron:
    """A centrally symmetric hexahedron with three pairs of parallel planes (Example 2.3).

    Args:
        theta: angle [rad] of the front face's normal from x, about -y (Sec 2.2.3.2).
        beta: angle [rad] of the side face's normal about z.
        gamma: elevation [rad] of the side face's normal; the top face is horizontal.
        corner: (3,) the corner ``(L_x, L_y, L_z)`` [m] where front, side and top meet; the
            opposite corner is ``-corner``.

    Returns:
        The :class:`Polyhedron`, faces named ``front side top back other_side bottom``.
    """
    L = as_array(corner, (3,), "corner")
    n = np.array(
        [
            [np.cos(theta), 0.0, np.sin(theta)],
            [np.sin(beta) * np.cos(gamma), np.cos(beta) * np.cos(gamma), np.sin(gamma)],
            [0.0, 0.0, 1.0],
        ]
    )  # outward normals of front, side, top
    if abs(np.linalg.det(n)) < 1e-9:
        raise GraspError("parallel-planes object: the three face normals are dependent")
    d = n @ L
    verts = [np.linalg.solve(n, d * np.array([1 - 2 * i, 1 - 2 * j, 1 - 2 * k]))
             for i, j, k in np.ndindex(2, 2, 2)]  # fmt: skip
    poly = from_vertices(np.array(verts))
    if np.any(poly.offsets <= 0):
        raise GraspError("parallel-planes object: the origin must be inside the object")
    names = []
    labels = ["front", "side", "top", "back", "other_side", "bottom"]
    targets = np.vstack([n, -n])
    for normal in poly.normals:
        names.append(labels[int(np.argmax(targets @ normal))])
    return dataclasses.replace(poly, face_names=tuple(names))


def line_interval_in_region(region: ContactRegion, s0, direction) -> tuple[float, float] | None:
    """Parameter interval ``[t0, t1]`` where ``s0 + t d`` lies in the region's closed polygon.

    Args:
        region: a seventh-contact region.
        s0: (2,) face coordinates of the line's point [m].
        direction: (2,) direction (normalised here).

    Returns:
        ``(t0, t1)`` [m] or ``None`` when the line misses the region.
    """
    if region.empty:
        return None
    d = as_array(direction, (2,), "direction")
    d = d / np.linalg.norm(d)
    s0 = as_array(s0, (2,), "s0")
    P = region.polygon
    e = np.roll(P, -1, axis=0) - P
    normals = np.column_stack([e[:, 1], -e[:, 0]])
    lo, hi = -np.inf, np.inf
    for nrm, p in zip(normals, P, strict=True):
        a, b = nrm @ d, nrm @ (p - s0)
        if abs(a) < 1e-15:
            if b < 0:
                return None
            continue
        t = b / a
        if a > 0:
            hi = min(hi, t)
        else:
            lo = max(lo, t)
    return (float(lo), float(hi)) if lo <= hi else None


def minimal_seventh_offset(grasp6: Grasp, face: str | int, start, direction) -> float:
    """Smallest distance [m] from ``start`` along ``direction`` on ``face`` to the region.

    The region of Eq 2.3 for the six contacts of ``grasp6`` is clipped to the face; the
    answer is where the ray ``start + t direction`` (t >= 0) first enters it.

    Args:
        grasp6: a grasp whose first six contacts are independent.
        face: the face of the seventh contact.
        start: (3,) object-frame point on the face [m] (e.g. the top contact).
        direction: (3,) in-face direction.

    Raises:
        GraspError: the ray never meets the region.
    """
    region = region_by_inverse(grasp6, face)
    s0 = region.to_face(as_array(start, (3,), "start"))[0]
    d = region.axes[:, :2].T @ as_array(direction, (3,), "direction")
    iv = line_interval_in_region(region, s0, d)
    if iv is None or iv[1] < 0:
        raise GraspError(f"the ray from {list(start)} along {list(direction)} misses the region")
    return max(iv[0], 0.0)
