"""Convex polygons in a face's 2-D coordinates: area, clipping by half-planes, hulls.

The geometry under the seventh-contact regions (:mod:`multiarm_pin.grasp.seventh_contact`):
a polygon is a (V, 2) array of vertices [m], counter-clockwise unless said otherwise; a set of
half-planes is ``(A (k, 2), b (k,))`` meaning ``A s <= b``.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError


def polygon_area(poly2d: np.ndarray) -> float:
    """Signed area [m^2] of a polygon (V, 2) (positive when counter-clockwise)."""
    P = np.asarray(poly2d, dtype=float).reshape(-1, 2)
    if len(P) < 3:
        return 0.0
    x, y = P[:, 0], P[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def signed_inside_distance(poly2d: np.ndarray, s: np.ndarray) -> np.ndarray:
    """For a convex CCW polygon (V, 2): min over edges of the distance inside (k,) [m]."""
    A, b = edges_to_halfplanes(poly2d)
    s = np.asarray(s, dtype=float).reshape(-1, 2)
    return np.min(b[None, :] - s @ A.T, axis=1)


def halfplanes_bounded(A: np.ndarray) -> bool:
    """Whether {s: A s <= b} is bounded (when non-empty): its recession cone is {0}."""
    if len(A) == 0:
        return False
    for a in A:
        for d in (np.array([-a[1], a[0]]), np.array([a[1], -a[0]])):
            if np.all(A @ d <= 1e-12):
                return False
    return True


def clip_polygon(polygon: np.ndarray, halfplanes) -> np.ndarray:
    """Sutherland-Hodgman: convex polygon (V, 2) ∩ {s: A s <= b}."""
    A, b = halfplanes
    P = np.asarray(polygon, dtype=float)
    for a, beta in zip(A, b, strict=True):
        if len(P) == 0:
            break
        val = P @ a - beta
        out = []
        for i in range(len(P)):
            j = (i + 1) % len(P)
            vi, vj = val[i], val[j]
            if vi <= 0:
                out.append(P[i])
            if (vi < 0 < vj) or (vj < 0 < vi):
                t = vi / (vi - vj)
                out.append(P[i] + t * (P[j] - P[i]))
        P = np.array(out).reshape(-1, 2)
    return _drop_collinear(_unique_rows_ordered(P, 1e-12))


def _drop_collinear(P: np.ndarray, tol: float = 1e-10) -> np.ndarray:
    """Remove vertices lying on the segment between their neighbours (round-off leftovers)."""
    changed = True
    while changed and len(P) > 3:
        changed = False
        for i in range(len(P)):
            a, b, c = P[i - 1], P[i], P[(i + 1) % len(P)]
            ab, bc = b - a, c - b
            scale = max(np.linalg.norm(ab) * np.linalg.norm(bc), 1e-300)
            if abs(ab[0] * bc[1] - ab[1] * bc[0]) <= tol * scale and ab @ bc >= 0:
                P = np.delete(P, i, axis=0)
                changed = True
                break
    return P


def edges_to_halfplanes(poly2d: np.ndarray):
    """Half-planes ``A s <= b`` (unit rows) of a CCW convex polygon's edges."""
    P = np.asarray(poly2d, dtype=float)
    d = np.roll(P, -1, axis=0) - P
    normals = np.column_stack([d[:, 1], -d[:, 0]])  # outward for CCW
    lens = np.linalg.norm(normals, axis=1)
    keep = lens > 1e-15
    normals = normals[keep] / lens[keep, None]
    return normals, np.einsum("ij,ij->i", normals, P[keep])


def convex_hull_2d(points: np.ndarray) -> np.ndarray:
    """Vertices (H, 2) of the convex hull of points (P, 2), CCW; empty when degenerate."""
    pts = np.asarray(points, dtype=float)
    if len(pts) < 3:
        return np.zeros((0, 2))
    try:
        hull = ConvexHull(pts)
    except QhullError:
        return np.zeros((0, 2))
    return pts[hull.vertices]  # CCW in 2-D


def unique_rows(X: np.ndarray, tol: float) -> np.ndarray:
    """The rows of ``X`` (k, d) without repeats within ``tol`` (first occurrence kept)."""
    out: list[np.ndarray] = []
    for x in np.asarray(X, dtype=float).reshape(len(X), -1):
        if not any(np.linalg.norm(x - y) <= tol for y in out):
            out.append(x)
    return np.array(out).reshape(-1, np.asarray(X).shape[1] if np.ndim(X) == 2 else 2)


def _unique_rows_ordered(P: np.ndarray, tol: float) -> np.ndarray:
    out: list[np.ndarray] = []
    for x in P:
        if not out or np.linalg.norm(x - out[-1]) > tol:
            out.append(x)
    if len(out) > 1 and np.linalg.norm(out[0] - out[-1]) <= tol:
        out.pop()
    return np.array(out).reshape(-1, 2)
