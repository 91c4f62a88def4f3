"""Where on a flat face a further contact completes form closure (thesis Sec 2.2.2).

Two methods give the region, both as a convex polygon in the face's own 2-D coordinates
(``Polyhedron.face_frame``: a face point is ``origin + s u + t v``):

* :func:`region_by_inverse` (Eq 2.3): with six independent contacts ``W6``, a seventh contact
  at ``p7`` with inward normal ``e7`` closes the grasp iff every entry of
  ``W6^-1 [e7; p7 × e7]`` is negative. ``p7 × e7 = (e7×)ᵀ p7`` is linear in ``p7``, so on the
  face this is an intersection of (up to six) open half-planes ``A s < b``. The inverse is
  formed with the blocks of Eq 2.2.
* :func:`region_by_generators` (Eq 2.4), which accepts any number K >= 6 of fixed contacts:
  closure needs ``e7 = -Σ λ_k e_k`` and ``p7 × e7 = -Σ λ_k (p_k × e_k)`` with all ``λ_k > 0``.
  The ``λ`` with ``Σ λ_k e_k = -e7, λ >= 0`` form a polyhedron whose vertices (the thesis's
  ``b_i``) and extreme rays (its ``c_j``) map to generators of the admissible moments; Eq 2.4
  keeps the combinations perpendicular to ``e7`` (a double-description step), and
  ``p7 = proj + e7 × m`` (Appendix A.3: the moment is the in-plane offset from the projected
  origin turned by -90° about ``e7``) turns moments into face points.

Which contacts are fixed is the caller's choice in those two; :func:`seventh_contact_regions`
makes it independent of the order of the contacts: each contact in turn moves on its face,
the others held fixed, and its region is computed when they are independent (rank 6, decided
with the margin :data:`RANK_MARGIN` on ``σ_6 / σ_1`` so that no order's round-off changes
the verdict); the report and ``multiarm-pin grasp`` use it.

The region is open (strict inequalities); the polygon returned is its closure clipped to the
face, and it is reported empty when it has no area. The 2-D polygon geometry (area, clipping,
hulls) is :mod:`multiarm_pin.grasp.polygon2d`; ``polygon_area`` and ``signed_inside_distance``
are re-exported here.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

import numpy as np
from scipy.optimize import linprog

from multiarm_pin.exceptions import GraspError
from multiarm_pin.grasp.contacts import Grasp
from multiarm_pin.grasp.independence import block_decomposition
from multiarm_pin.grasp.polygon2d import (
    clip_polygon,
    convex_hull_2d,
    edges_to_halfplanes,
    halfplanes_bounded,
    polygon_area,
    signed_inside_distance,
    unique_rows,
)
from multiarm_pin.model.polyhedron import Polyhedron
from multiarm_pin.spatial import skew

AREA_TOLERANCE = 1e-12
"""Regions with less area than this times the face's area count as empty."""


@dataclass(frozen=True)
class ContactRegion:
    """The region of a face where one more contact completes form closure.

    Attributes:
        face: face index.
        face_name: face name (or ``#k``).
        origin: (3,) origin of the face coordinates (object frame) [m].
        axes: (3, 3) columns ``u, v, n``: in-face axes and the outward normal.
        polygon: (V, 2) closure of the region clipped to the face, counter-clockwise in
            face coordinates ``(s, t)`` [m]; shape (0, 2) when empty.
        bounded: the region on the whole (unbounded) plane of the face is bounded.
        method: ``"inverse"`` (Eq 2.3) or ``"generators"`` (Eq 2.4).
        halfplanes: ``(A (m, 2), b (m,))`` with the region ``A s < b`` on the plane
            (method ``"inverse"``; also derived for ``"generators"`` from the polygon's edges
            when bounded), or ``None``.
        points: (k, 2) generator points (method ``"generators"``), face coordinates [m].
        rays: (r, 2) generator directions (method ``"generators"``), unit length.
        reason: why the region is empty, or ``""``.
    """

    face: int
    face_name: str
    origin: np.ndarray
    axes: np.ndarray
    polygon: np.ndarray
    bounded: bool
    method: str
    halfplanes: tuple[np.ndarray, np.ndarray] | None = None
    points: np.ndarray | None = None
    rays: np.ndarray | None = None
    reason: str = ""

    @property
    def empty(self) -> bool:
        """True when no point of the face completes form closure."""
        return len(self.polygon) == 0

    @property
    def vertices_3d(self) -> np.ndarray:
        """(V, 3) polygon vertices in the object frame [m], in order around the polygon."""
        return self.to_object(self.polygon)

    @property
    def area(self) -> float:
        """Area of the clipped region [m^2]."""
        return polygon_area(self.polygon)

    def to_object(self, s: np.ndarray) -> np.ndarray:
        """Face coordinates (k, 2) -> object-frame points (k, 3) [m]."""
        s = np.asarray(s, dtype=float).reshape(-1, 2)
        return self.origin + s @ self.axes[:, :2].T

    def to_face(self, p: np.ndarray) -> np.ndarray:
        """Object-frame points (k, 3) -> face coordinates (k, 2) [m] (projected on the face)."""
        p = np.asarray(p, dtype=float).reshape(-1, 3)
        return (p - self.origin) @ self.axes[:, :2]

    def contains(self, s: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Whether face points (k, 2) lie inside the clipped polygon by more than ``margin`` m.

        Returns:
            (k,) bool.
        """
        s = np.asarray(s, dtype=float).reshape(-1, 2)
        if self.empty:
            return np.zeros(len(s), dtype=bool)
        return signed_inside_distance(self.polygon, s) > margin


def region_by_inverse(grasp: Grasp, face: int | str, fixed=(0, 1, 2, 3, 4, 5)) -> ContactRegion:
    """Region for a seventh contact on ``face`` by Eq 2.3.

    Args:
        grasp: grasp with a polyhedron; ``fixed`` selects its six independent contacts.
        face: face index or name for the new contact.
        fixed: indices of the six fixed contacts.

    Returns:
        A :class:`ContactRegion` (method ``"inverse"``) whose ``halfplanes`` are the six
        inequalities of Eq 2.3 restricted to the face's plane.

    Raises:
        GraspError: no polyhedron, not six fixed contacts, or the six are not independent.
    """
    poly, k, origin, R = _face_setup(grasp, face)
    idx = list(fixed)
    if len(idx) != 6:
        raise GraspError(f"Eq 2.3 needs exactly six fixed contacts, got {len(idx)}")
    _check_indices(grasp, idx)
    dec = block_decomposition(grasp.points[idx], grasp.normals[idx])
    if not dec.independent:
        raise GraspError(
            "Eq 2.3 needs six independent contacts: e_A or a = a_A T1 + a_B is singular "
            f"(cond e_A = {dec.cond_e_A:.3g}, cond a = {dec.cond_a:.3g})"
        )
    Winv = dec.inverse()
    e7 = -poly.normals[k]
    U = R[:, :2]
    S = skew(e7).T  # (e7×)ᵀ p = p × e7
    A = Winv[:, 3:] @ S @ U
    b = -(Winv @ np.concatenate([e7, S @ origin]))
    return _region_from_halfplanes(poly, k, origin, R, A, b)


def region_by_generators(grasp: Grasp, face: int | str, fixed=None) -> ContactRegion:
    """Region for one more contact on ``face`` by the polyhedral method (Eq 2.4).

    Args:
        grasp: grasp with a polyhedron.
        face: face index or name for the new contact.
        fixed: indices of the fixed contacts (any number >= 6; default: all of them).

    Returns:
        A :class:`ContactRegion` (method ``"generators"``) with the generator points and rays
        in face coordinates.

    Raises:
        GraspError: no polyhedron or fewer than six fixed contacts.
    """
    poly, k, origin, R = _face_setup(grasp, face)
    idx = list(range(len(grasp))) if fixed is None else list(fixed)
    if len(idx) < 6:
        raise GraspError(f"the region needs at least six fixed contacts, got {len(idx)}")
    _check_indices(grasp, idx)
    p, n = grasp.points[idx], grasp.normals[idx]
    E, M = n.T, np.cross(p, n).T
    e7 = -poly.normals[k]
    name = _name(poly, k)
    W = np.vstack([E, M])
    scale = max(1.0, float(np.abs(p).max()))

    def empty(reason: str) -> ContactRegion:
        return ContactRegion(
            k,
            name,
            origin,
            R,
            np.zeros((0, 2)),
            True,
            "generators",
            None,
            np.zeros((0, 2)),
            np.zeros((0, 2)),
            reason,
        )

    if np.linalg.matrix_rank(W, tol=1e-9 * max(1.0, np.abs(W).max())) < 6:
        return empty("the fixed contacts' wrenches have rank < 6")
    if not _strictly_positive_force_solution(E, e7):
        return empty(
            f"the normal of face {name} is not a strictly negative combination of the "
            "fixed contacts' normals with all of them pushing"
        )
    verts, rays = _force_generators(E, e7)
    Q_pts = [-(M @ lam) for lam in verts]
    Q_rays = [-(M @ rho) for rho in rays]
    pts, dirs = _cut_with_plane(Q_pts, Q_rays, e7, 1e-12 * scale)
    proj = poly.offsets[k] * poly.normals[k]  # projection of the frame origin on the plane
    U = R[:, :2]
    s_pts = np.array([U.T @ (proj + np.cross(e7, m) - origin) for m in pts]).reshape(-1, 2)
    s_dirs = np.array([U.T @ np.cross(e7, r) for r in dirs]).reshape(-1, 2)
    norms = np.linalg.norm(s_dirs, axis=1)
    s_dirs = s_dirs[norms > 1e-12] / norms[norms > 1e-12, None] if len(s_dirs) else s_dirs
    s_dirs = unique_rows(s_dirs, 1e-9)
    s_pts = unique_rows(s_pts, 1e-12 * scale)
    face2d = _face_polygon(poly, k, origin, R)
    if len(s_pts) == 0:
        return empty("no admissible moment lies in the face's plane (Eq 2.4 has no solution)")
    reach = 10.0 * (np.abs(face2d).max() + np.abs(s_pts).max() + 1.0)
    big = np.vstack([s_pts] + [s_pts + 1e3 * reach * d for d in s_dirs])
    hull = convex_hull_2d(big)
    polygon = (clip_polygon(face2d, edges_to_halfplanes(hull)) if len(hull) >= 3
               else np.zeros((0, 2)))
    face_area = polygon_area(face2d)
    reason = ""
    if len(polygon) < 3 or polygon_area(polygon) <= AREA_TOLERANCE * face_area:
        polygon = np.zeros((0, 2))
        reason = "the admissible region does not meet the face with positive area"
    halfplanes = edges_to_halfplanes(hull) if len(s_dirs) == 0 and len(hull) >= 3 else None
    return ContactRegion(
        k,
        name,
        origin,
        R,
        polygon,
        len(s_dirs) == 0,
        "generators",
        halfplanes,
        s_pts,
        s_dirs,
        reason,
    )


RANK_MARGIN = 1e-6
"""Fixed contacts count as independent (rank 6) when ``σ_6 / σ_1`` of their wrench matrix
(moments divided by the grasp's size) exceeds this. Generic independent sets sit orders of
magnitude above it and structurally dependent ones (a contact whose force vanishes in a
marginal grasp, parallel normals) at round-off, far below: the verdict does not hang on
round-off, so it is the same in every order of the contacts."""

INSIDE_MARGIN = 1e-9
"""A contact counts as inside its region when it is deeper than this times the object's size;
a contact on the region's boundary (a marginal grasp) is not inside, in every order."""


@dataclass(frozen=True)
class SeventhContactRegion:
    """The region of one moving contact, the others held fixed.

    Attributes:
        contact: index (0-based) of the contact that moves, or -1 for one more contact
            added to the grasp.
        fixed: indices (0-based, increasing) of the contacts held fixed.
        face: index of the face the region lies on.
        sigma_ratio: ``σ_6 / σ_1`` of the fixed contacts' wrench matrix (moments divided by
            the object's size); they are independent when it exceeds :data:`RANK_MARGIN`.
        region: the region (Eq 2.3 with six fixed independent contacts, checked against
            Eq 2.4; Eq 2.4 with more), or None when it is not computed (``reason`` says why).
        methods_agree: Eq 2.3 and Eq 2.4 give the same area (six fixed contacts), else None.
        inside: the moving contact lies inside the region by more than :data:`INSIDE_MARGIN`
            times the object's size (None for a new contact or one on another face).
        reason: why the region is not computed or is empty, or ``""``.
    """

    contact: int
    fixed: tuple[int, ...]
    face: int
    sigma_ratio: float
    region: ContactRegion | None
    methods_agree: bool | None = None
    inside: bool | None = None
    reason: str = ""

    @property
    def independent(self) -> bool:
        """The fixed contacts' wrenches have rank 6 (by :data:`RANK_MARGIN`)."""
        return self.sigma_ratio > RANK_MARGIN


def fixed_sigma_ratio(grasp: Grasp, fixed) -> float:
    """``σ_6 / σ_1`` of the wrench matrix of the contacts ``fixed`` (0 below six of them).

    Moments are divided by the object's size (its largest vertex or contact distance from the
    origin) so that forces and moments weigh alike; the ratio does not depend on the order.
    """
    idx = list(fixed)
    if len(idx) < 6:
        return 0.0
    W = grasp.wrenches(None, _size(grasp))[:, idx]
    sv = np.linalg.svd(W, compute_uv=False)
    return float(sv[5] / sv[0]) if sv[0] > 0 else 0.0


def seventh_contact_regions(
    grasp: Grasp, seventh: int | None = None, face: int | str | None = None
) -> tuple[SeventhContactRegion, ...]:
    """Where each contact may lie on its face, the others fixed, for form closure.

    The region does not depend on the order of the contacts: with ``N >= 7`` contacts, each
    contact ``k`` in turn is the moving ("seventh") one and the other ``N - 1`` are held
    fixed; its region is computed when those have rank 6 (:data:`RANK_MARGIN`; with six
    fixed, they are the independent six of Eq 2.3). For a form-closure grasp of seven
    contacts, every six are independent and every region holds its contact.

    Args:
        grasp: grasp with a polyhedron.
        seventh: the one moving contact (0-based index), or None for every contact.
        face: the face of the region. None: each moving contact's own face. Given without
            ``seventh``: the contacts on that face move; when none lies on it (or the grasp
            has six contacts), the region is for one more contact on it, all contacts fixed.
            Given with ``seventh``: where on that face the contact could go instead.

    Returns:
        One :class:`SeventhContactRegion` per moving contact, in the order of the contacts
        (empty for fewer than six contacts, and for six without a ``face``).

    Raises:
        GraspError: no polyhedron, ``seventh`` out of range (or given with fewer than seven
            contacts), or an unknown face.
    """
    N = len(grasp)
    poly = grasp.polyhedron
    if poly is None:
        raise GraspError("the contact region needs the object's polyhedron (grasp.polyhedron)")
    if seventh is not None and not 0 <= int(seventh) < N:
        raise GraspError(f"seventh contact: expected a contact number in 1..{N}, got "
                         f"{int(seventh) + 1}")
    if seventh is not None and N < 7:
        raise GraspError(f"seventh contact {int(seventh) + 1}: a contact moves with six others "
                         f"held fixed, and the grasp has {N} contacts; name a face for one "
                         "more contact instead")
    k_face = None
    if face is not None:
        k_face = _face_setup(grasp, face)[1]
    if N < 6:
        return ()
    if seventh is not None and N >= 7:
        moving = [int(seventh)]
    elif k_face is not None:
        moving = [k for k, c in enumerate(grasp.contacts) if c.face == k_face] if N >= 7 else []
        if not moving:
            return (_region_of(grasp, -1, tuple(range(N)), k_face),)
    elif N >= 7:
        moving = list(range(N))
    else:
        return ()
    out = []
    for k in moving:
        fixed = tuple(i for i in range(N) if i != k)
        target = k_face if k_face is not None else grasp.contacts[k].face
        out.append(_region_of(grasp, k, fixed, target))
    return tuple(out)


def _region_of(grasp: Grasp, k: int, fixed: tuple[int, ...], face: int) -> SeventhContactRegion:
    """The region of contact ``k`` (-1: a new contact) on ``face``, ``fixed`` held fixed."""
    ratio = fixed_sigma_ratio(grasp, fixed)
    who = f"contact {k + 1}" if k >= 0 else "one more contact"
    if face < 0:
        return SeventhContactRegion(k, fixed, face, ratio, None,
                                    reason=f"{who} lies on no face of the object")
    if ratio <= RANK_MARGIN:
        others = "the other contacts" if k >= 0 else "the contacts"
        return SeventhContactRegion(
            k, fixed, face, ratio, None,
            reason=f"{others} are not independent: their wrenches have rank < 6 "
                   f"(σ6/σ1 = {ratio:.3g} <= {RANK_MARGIN:g}), so {who} cannot complete "
                   "form closure alone")
    region = region_by_generators(grasp, face, fixed)
    agree = None
    if len(fixed) == 6:
        dec = block_decomposition(grasp.points[list(fixed)], grasp.normals[list(fixed)])
        if dec.independent:
            r23 = region_by_inverse(grasp, face, fixed)
            agree = bool(abs(r23.area - region.area) <= 1e-6 * max(1.0, r23.area))
            region = r23
    inside = None
    if k >= 0 and grasp.contacts[k].face == face:
        s = region.to_face(grasp.contacts[k].point)
        inside = bool(region.contains(s, INSIDE_MARGIN * _size(grasp))[0])
    return SeventhContactRegion(k, fixed, face, ratio, region, agree, inside, region.reason)


def _size(grasp: Grasp) -> float:
    """The object's size [m]: its largest vertex (or contact) distance from the origin."""
    pts = grasp.polyhedron.vertices if grasp.polyhedron is not None else grasp.points
    return max(float(np.linalg.norm(pts, axis=1).max(initial=0.0)), 1e-9)


def box_corner_region_lines(
    a: float, b: float, c: float, d: float, e: float, f: float, thesis_form: bool = False
):
    """Closed form of Example 2.1 for the top face of a box.

    Contacts at ``(l_x, a, b)`` on +x, ``(c, l_y, d)`` on +y, ``(e, f, l_z)`` on +z and the
    mirrored points ``-p1, -p2, -p3`` on the opposite faces; ``det = det(a_A) = ade - bcf``.
    Solving ``a_A z = p7 × e7`` (Eq 2.3 reduces to ``z1 < 0, z2 < 0, z3 < -1`` here) gives
    ``z1 = c (f x - e y) / det``, ``z2 = a (f x - e y) / det``, ``z3 = (ad x - bc y) / det``.
    The thesis states ``(f x - e y) / det < 0`` and ``(ad x - bc y) / det < -1``, which is the
    same only when ``a > 0`` and ``c > 0`` (contacts on the corner's side of the centre, as in
    its figures); in general the factors ``c`` and ``a`` matter (and ``a c < 0`` makes the
    region empty).

    Args:
        a: y coordinate [m] of the +x contact ``(l_x, a, b)``.
        b: z coordinate [m] of the +x contact.
        c: x coordinate [m] of the +y contact ``(c, l_y, d)``.
        d: z coordinate [m] of the +y contact.
        e: x coordinate [m] of the +z contact ``(e, f, l_z)``.
        f: y coordinate [m] of the +z contact.
        thesis_form: return the thesis's two rows instead of the general three.

    Returns:
        ``(A (3, 2), rhs (3,))`` (or (2, 2), (2,)) with the region ``A [x; y] < rhs`` in the
        object's x-y coordinates [m].

    Raises:
        GraspError: ``det(a_A) = 0`` (the six contacts are dependent).
    """
    det = a * d * e - b * c * f
    if abs(det) < 1e-15:
        raise GraspError("Example 2.1: det(a_A) = ade - bcf is zero; the contacts are dependent")
    if thesis_form:
        return np.array([[f, -e], [a * d, -b * c]]) / det, np.array([0.0, -1.0])
    A = np.array([[c * f, -c * e], [a * f, -a * e], [a * d, -b * c]]) / det
    return A, np.array([0.0, 0.0, -1.0])


# --- helpers ---------------------------------------------------------------------------------


def _face_setup(grasp: Grasp, face):
    poly = grasp.polyhedron
    if poly is None:
        raise GraspError("the contact region needs the object's polyhedron (grasp.polyhedron)")
    try:
        k = poly.face_index(face)
    except Exception as exc:  # InputError from the polyhedron
        raise GraspError(f"seventh-contact face: {exc}") from exc
    origin, R = poly.face_frame(k)
    return poly, k, origin, R


def _check_indices(grasp: Grasp, idx) -> None:
    if len(set(idx)) != len(idx) or not all(0 <= i < len(grasp) for i in idx):
        raise GraspError(
            f"fixed contacts: expected distinct indices in 0..{len(grasp) - 1}, got {list(idx)}"
        )


def _name(poly: Polyhedron, k: int) -> str:
    return poly.face_names[k] if poly.face_names else f"#{k}"


def _face_polygon(poly: Polyhedron, k: int, origin, R) -> np.ndarray:
    V = poly.vertices[list(poly.faces[k])]
    P = (V - origin) @ R[:, :2]
    return P if polygon_area(P) > 0 else P[::-1]


def _region_from_halfplanes(poly, k, origin, R, A, b) -> ContactRegion:
    name = _name(poly, k)
    row = np.linalg.norm(A, axis=1)
    scale = max(1.0, float(np.abs(b).max(initial=0.0)))
    const = row <= 1e-12 * scale
    if np.any(b[const] <= 0):
        polygon = np.zeros((0, 2))
        reason = "a constant inequality of Eq 2.3 fails: the face's normal cannot close the grasp"
        return ContactRegion(
            k, name, origin, R, polygon, True, "inverse", (A, b), None, None, reason
        )
    An, bn = A[~const] / row[~const, None], b[~const] / row[~const]
    face2d = _face_polygon(poly, k, origin, R)
    polygon = clip_polygon(face2d, (An, bn))
    reason = ""
    if len(polygon) < 3 or polygon_area(polygon) <= AREA_TOLERANCE * polygon_area(face2d):
        polygon = np.zeros((0, 2))
        reason = "the half-planes of Eq 2.3 do not meet inside the face"
    bounded = halfplanes_bounded(An)
    return ContactRegion(
        k, name, origin, R, polygon, bounded, "inverse", (An, bn), None, None, reason
    )


def _strictly_positive_force_solution(E: np.ndarray, e7: np.ndarray) -> bool:
    """Exists ``λ > 0`` with ``E λ = -e7`` (the forces of Eq 2.1 with every contact pushing)."""
    K = E.shape[1]
    # max t  s.t.  E λ + e7 s = 0, λ >= t, s >= t, Σλ + s = 1
    c = np.zeros(K + 2)
    c[-1] = -1.0
    A_eq = np.zeros((4, K + 2))
    A_eq[:3, :K] = E
    A_eq[:3, K] = e7
    A_eq[3, : K + 1] = 1.0
    b_eq = np.array([0.0, 0.0, 0.0, 1.0])
    A_ub = np.hstack([-np.eye(K + 1), np.ones((K + 1, 1))])
    res = linprog(
        c,
        A_ub=A_ub,
        b_ub=np.zeros(K + 1),
        A_eq=A_eq,
        b_eq=b_eq,
        bounds=[(0, None)] * (K + 1) + [(None, None)],
        method="highs",
    )
    return bool(res.status == 0 and res.x[-1] > 1e-10)


def _force_generators(E: np.ndarray, e7: np.ndarray):
    """Vertices and extreme rays of ``{λ >= 0 : E λ = -e7}`` (E is 3 x K).

    Vertices are basic solutions on 3 independent columns; rays are the non-negative null
    vectors of minimal supports (2 to 4 columns). These are the thesis's ``B̃`` and ``C̃``.
    """
    K = E.shape[1]
    verts: list[np.ndarray] = []
    for S in combinations(range(K), 3):
        ES = E[:, S]
        if np.linalg.cond(ES) > 1e10:
            continue
        lam_S = np.linalg.solve(ES, -e7)
        if np.all(lam_S >= -1e-12):
            lam = np.zeros(K)
            lam[list(S)] = np.maximum(lam_S, 0.0)
            if not any(np.allclose(lam, v, atol=1e-12) for v in verts):
                verts.append(lam)
    rays: list[np.ndarray] = []
    for size in (2, 3, 4):
        for S in combinations(range(K), size):
            ES = E[:, S]
            _, sv, Vt = np.linalg.svd(ES)
            rank = int(np.sum(sv > 1e-10))
            if rank != size - 1:
                continue
            v = Vt[-1]
            if np.all(v < 0):
                v = -v
            if np.all(v > 1e-12):
                rho = np.zeros(K)
                rho[list(S)] = v / v.sum()
                if not any(np.allclose(rho, r, atol=1e-10) for r in rays):
                    rays.append(rho)
    return verts, rays


def _cut_with_plane(points, rays, h, tol):
    """Generators of (conv(points) + cone(rays)) ∩ {x : h·x = 0} (one double-description step)."""
    hp = [float(h @ q) for q in points]
    hr = [float(h @ r) for r in rays]
    out_pts, out_rays = [], []
    for q, v in zip(points, hp, strict=True):
        if abs(v) <= tol:
            out_pts.append(q)
    for (qi, vi), (qj, vj) in combinations(list(zip(points, hp, strict=True)), 2):
        if (vi > tol and vj < -tol) or (vi < -tol and vj > tol):
            out_pts.append((vi * qj - vj * qi) / (vi - vj))
    for q, v in zip(points, hp, strict=True):
        for r, w in zip(rays, hr, strict=True):
            if (v > tol and w < -tol) or (v < -tol and w > tol):
                out_pts.append(q - (v / w) * r)
    for r, w in zip(rays, hr, strict=True):
        if abs(w) <= tol:
            out_rays.append(r)
    for (ri, wi), (rj, wj) in combinations(list(zip(rays, hr, strict=True)), 2):
        if (wi > tol and wj < -tol) or (wi < -tol and wj > tol):
            out_rays.append(
                (wi * rj - wj * ri) / (wi - wj) if wi > 0 else (wj * ri - wi * rj) / (wj - wi)
            )
    return out_pts, out_rays


__all__ = [
    "AREA_TOLERANCE",
    "INSIDE_MARGIN",
    "RANK_MARGIN",
    "ContactRegion",
    "SeventhContactRegion",
    "box_corner_region_lines",
    "fixed_sigma_ratio",
    "polygon_area",
    "region_by_generators",
    "region_by_inverse",
    "seventh_contact_regions",
    "signed_inside_distance",
]
