"""Six independent contacts (thesis Sec 2.2.1, Eq 2.2, Appendix A.1-A.2).

Six frictionless contacts are *independent* when their six wrenches are linearly
independent. With the wrench matrix split into 3 x 3 blocks

    [[e_A, e_B],      e_A = [e1 e2 e3],            e_B = [e4 e5 e6]
     [a_A, a_B]]      a_A = [p1×e1 p2×e2 p3×e3],   a_B = [p4×e4 p5×e5 p6×e6]

and ``T1 = -e_A^-1 e_B``, ``a = a_A T1 + a_B``, ``T2 = -a^-1 a_A``, its inverse is (Eq 2.2)

    [[(I + T1 T2) e_A^-1, T1 a^-1],
     [T2 e_A^-1,          a^-1   ]],

so the six contacts are independent iff ``e_A`` and ``a`` are nonsingular. The geometric
necessary conditions of Sec 2.2.1 (proved in Appendix A.2) are checked one by one and each
violation is reported by name.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import combinations

import numpy as np

from multiarm_pin.exceptions import GraspError, SingularityError
from multiarm_pin.grasp.contacts import Grasp

SINGULAR_CONDITION = 1e10
"""A 3x3 block with a larger condition number counts as singular."""

GEOMETRY_TOLERANCE = 1e-9
"""Relative tolerance of the line tests (concurrent, parallel, coplanar), times the size."""

CONDITION_NAMES = {
    "four_normals_concurrent": "no more than 3 contact normals may intersect at one point",
    "four_normals_parallel": "no more than 3 contact normals may be parallel",
    "four_normals_coplanar": "no more than 3 contact normals may lie in one plane",
    "three_concurrent_rest_parallel": (
        "if 3 normals intersect at one point, the remaining normals must not all be parallel"
    ),
    "three_concurrent_rest_concurrent": (
        "if 3 normals intersect at one point, the remaining normals must not intersect at one point"
    ),
    "three_concurrent_point_on_rest_plane": (
        "if 3 normals intersect at one point, that point must not lie on a plane formed by two "
        "of the remaining normals"
    ),
    "three_parallel_rest_concurrent": (
        "if 3 normals are parallel, the other 3 must not intersect at one point"
    ),
    "three_coplanar_rest_meet_on_plane": (
        "if 3 normals lie in one plane, no intersection of the remaining normals may lie on it"
    ),
}
"""Names and statements of the necessary conditions of Sec 2.2.1 / Appendix A.2."""


@dataclass(frozen=True)
class BlockDecomposition:
    """The blocks of Eq 2.2 for six contacts, in the order ``order``.

    Attributes:
        order: (6,) contact indices used: the first three form ``e_A`` (independent normals).
        e_A, e_B: (3, 3) contact normals (columns), object frame.
        a_A, a_B: (3, 3) moments ``p × e`` (columns) about the origin [m].
        T1: (3, 3) ``-e_A^-1 e_B``.
        a: (3, 3) ``a_A T1 + a_B`` [m].
        T2: (3, 3) ``-a^-1 a_A`` (NaN when ``a`` is singular).
        cond_e_A, cond_a: condition numbers of ``e_A`` and ``a``.
    """

    order: tuple[int, ...]
    e_A: np.ndarray
    e_B: np.ndarray
    a_A: np.ndarray
    a_B: np.ndarray
    T1: np.ndarray
    a: np.ndarray
    T2: np.ndarray
    cond_e_A: float
    cond_a: float

    @property
    def independent(self) -> bool:
        """``e_A`` and ``a`` are both nonsingular."""
        return self.cond_e_A < SINGULAR_CONDITION and self.cond_a < SINGULAR_CONDITION

    def inverse(self) -> np.ndarray:
        """The inverse (6, 6) of ``[[e_A, e_B], [a_A, a_B]]`` by Eq 2.2.

        Its rows follow ``order``: row k gives the coefficient of contact ``order[k]``.

        Raises:
            SingularityError: the contacts are not independent.
        """
        if not self.independent:
            raise SingularityError(
                "the six-contact wrench matrix",
                max(self.cond_e_A, self.cond_a),
                "the six contacts are not independent",
            )
        eAi = np.linalg.inv(self.e_A)
        ai = np.linalg.inv(self.a)
        return np.block(
            [[(np.eye(3) + self.T1 @ self.T2) @ eAi, self.T1 @ ai], [self.T2 @ eAi, ai]]
        )


@dataclass(frozen=True)
class IndependenceReport:
    """Whether six contacts are independent, and why not.

    Attributes:
        independent: the six wrenches are linearly independent.
        decomposition: the blocks of Eq 2.2 (``None`` when no three normals are independent).
        sigma_min: smallest singular value of the 6x6 wrench matrix.
        violated: names (keys of :data:`CONDITION_NAMES`) of the violated necessary conditions,
            each with the contact indices involved.
        messages: human-readable lines, one per problem found.
    """

    independent: bool
    decomposition: BlockDecomposition | None
    sigma_min: float
    violated: list[tuple[str, tuple[int, ...]]] = field(default_factory=list)
    messages: list[str] = field(default_factory=list)


def block_decomposition(points: np.ndarray, normals: np.ndarray) -> BlockDecomposition:
    """Blocks of Eq 2.2 for six contacts.

    The first three contacts form ``e_A`` when their normals are independent; otherwise the
    best-conditioned triple is moved to the front (``order`` records the permutation).

    Args:
        points: (6, 3) contact points [m], object frame.
        normals: (6, 3) inward unit normals.

    Raises:
        GraspError: not six contacts, or no three normals are linearly independent.
    """
    p = np.asarray(points, dtype=float)
    n = np.asarray(normals, dtype=float)
    if p.shape != (6, 3) or n.shape != (6, 3):
        raise GraspError(
            f"independence needs exactly six contacts (6, 3), got points {p.shape}, normals "
            f"{n.shape}"
        )
    order = list(range(6))
    if np.linalg.cond(n[:3].T) >= SINGULAR_CONDITION:
        best = min(combinations(range(6), 3), key=lambda c: np.linalg.cond(n[list(c)].T))
        if np.linalg.cond(n[list(best)].T) >= SINGULAR_CONDITION:
            raise GraspError(
                "no three of the six contact normals are linearly independent (e_A of Eq 2.2 "
                "cannot be formed): the contacts cannot be independent"
            )
        order = list(best) + [k for k in range(6) if k not in best]
    p, n = p[order], n[order]
    m = np.cross(p, n)
    e_A, e_B, a_A, a_B = n[:3].T, n[3:].T, m[:3].T, m[3:].T
    T1 = -np.linalg.solve(e_A, e_B)
    a = a_A @ T1 + a_B
    cond_a = float(np.linalg.cond(a))
    T2 = -np.linalg.solve(a, a_A) if cond_a < SINGULAR_CONDITION else np.full((3, 3), np.nan)
    return BlockDecomposition(
        tuple(order), e_A, e_B, a_A, a_B, T1, a, T2, float(np.linalg.cond(e_A)), cond_a
    )


def check_independence(
    grasp: Grasp, indices: tuple[int, ...] = (0, 1, 2, 3, 4, 5)
) -> IndependenceReport:
    """Check that six contacts of ``grasp`` are independent (Sec 2.2.1).

    Args:
        grasp: the grasp.
        indices: the six contacts to test (default: the first six).

    Returns:
        An :class:`IndependenceReport` with the decomposition, the smallest singular value of
        the wrench matrix and every violated necessary condition by name.

    Raises:
        GraspError: fewer than six contacts or ``indices`` not six distinct valid indices.
    """
    idx = tuple(int(i) for i in indices)
    if len(idx) != 6 or len(set(idx)) != 6 or not all(0 <= i < len(grasp) for i in idx):
        raise GraspError(
            f"independence: expected six distinct contact indices in 0..{len(grasp) - 1}, got "
            f"{list(idx)} (the grasp has {len(grasp)} contacts)"
        )
    p, n = grasp.points[list(idx)], grasp.normals[list(idx)]
    W = np.vstack([n.T, np.cross(p, n).T])
    sv = np.linalg.svd(W, compute_uv=False)
    sigma_min = float(sv[-1])
    messages: list[str] = []
    try:
        dec = block_decomposition(p, n)
    except GraspError as exc:
        dec = None
        messages.append(str(exc))
    scale = max(1.0, float(np.abs(p).max()))
    violated = [(name, tuple(idx[k] for k in ks)) for name, ks in necessary_conditions(p, n, scale)]
    for name, ks in violated:
        messages.append(f"{name}: {CONDITION_NAMES[name]} (contacts {list(ks)})")
    independent = dec is not None and dec.independent and sigma_min > 1e-9 * max(1.0, sv[0])
    if dec is not None and not dec.independent:
        which = "e_A" if dec.cond_e_A >= SINGULAR_CONDITION else "a = a_A T1 + a_B"
        messages.append(f"{which} is singular (Eq 2.2): the six wrenches are dependent")
    return IndependenceReport(independent, dec, sigma_min, violated, messages)


# --- geometry of the normal lines (line k: through p_k along n_k) -------------------------


def necessary_conditions(
    points: np.ndarray, normals: np.ndarray, scale: float = 1.0
) -> list[tuple[str, tuple[int, ...]]]:
    """The necessary conditions of Sec 2.2.1 violated by six contact normal lines.

    Args:
        points: (6, 3) contact points [m].
        normals: (6, 3) unit normals.
        scale: length [m] setting the absolute tolerance of the geometric tests.

    Returns:
        A list of ``(name, contact positions 0..5)`` for each violation found.
    """
    tol = GEOMETRY_TOLERANCE * scale
    lines = [(points[k], normals[k]) for k in range(6)]
    out: list[tuple[str, tuple[int, ...]]] = []
    for four in combinations(range(6), 4):
        sub = [lines[k] for k in four]
        if _concurrent(sub, tol) is not None:
            out.append(("four_normals_concurrent", four))
        if _parallel(sub):
            out.append(("four_normals_parallel", four))
        if _coplanar(sub, tol):
            out.append(("four_normals_coplanar", four))
    for three in combinations(range(6), 3):
        rest = tuple(k for k in range(6) if k not in three)
        sub = [lines[k] for k in three]
        others = [lines[k] for k in rest]
        point = _concurrent(sub, tol)
        if point is not None:
            if _parallel(others):
                out.append(("three_concurrent_rest_parallel", three + rest))
            if _concurrent(others, tol) is not None:
                out.append(("three_concurrent_rest_concurrent", three + rest))
            for i, j in combinations(range(3), 2):
                plane = _plane_of_two(others[i], others[j])
                if plane is not None and abs(plane[0] @ point - plane[1]) <= tol:
                    out.append(("three_concurrent_point_on_rest_plane", three + (rest[i], rest[j])))
        if _parallel(sub) and _concurrent(others, tol) is not None:
            out.append(("three_parallel_rest_concurrent", three + rest))
        if _coplanar(sub, tol):
            plane = _plane_of_lines(sub)
            for i, j in combinations(range(3), 2):
                x = _intersection(others[i], others[j], tol)
                if x is not None and abs(plane[0] @ x - plane[1]) <= tol:
                    out.append(("three_coplanar_rest_meet_on_plane", three + (rest[i], rest[j])))
    return out


def _concurrent(lines, tol: float) -> np.ndarray | None:
    """Common point of the lines (all through one finite point), else None."""
    A = np.zeros((3, 3))
    b = np.zeros(3)
    for p, n in lines:
        P = np.eye(3) - np.outer(n, n)
        A += P
        b += P @ p
    if np.linalg.cond(A) > 1e12:  # all parallel: no finite common point
        return None
    x = np.linalg.solve(A, b)
    dist = max(np.linalg.norm(np.cross(x - p, n)) for p, n in lines)
    return x if dist <= tol else None


def _parallel(lines) -> bool:
    n0 = lines[0][1]
    return all(np.linalg.norm(np.cross(n0, n)) <= 1e-9 for _, n in lines[1:])


def _coplanar(lines, tol: float) -> bool:
    p0 = lines[0][0]
    vecs = [n for _, n in lines] + [p - p0 for p, _ in lines[1:]]
    M = np.array(vecs)
    sv = np.linalg.svd(M, compute_uv=False)
    return bool(len(sv) >= 3 and sv[2] <= tol)


def _plane_of_lines(lines) -> tuple[np.ndarray, float]:
    p0 = lines[0][0]
    M = np.array([n for _, n in lines] + [p - p0 for p, _ in lines[1:]])
    normal = np.linalg.svd(M)[2][-1]
    return normal, float(normal @ p0)


def _plane_of_two(l1, l2) -> tuple[np.ndarray, float] | None:
    """The plane containing two coplanar (intersecting or parallel) lines, else None."""
    (p1, n1), (p2, n2) = l1, l2
    c = np.cross(n1, n2)
    if np.linalg.norm(c) > 1e-9:
        if abs((p2 - p1) @ c) > GEOMETRY_TOLERANCE * max(1.0, np.linalg.norm(p2 - p1)):
            return None  # skew lines
        normal = c / np.linalg.norm(c)
    else:
        d = np.cross(n1, p2 - p1)
        if np.linalg.norm(d) < 1e-12:
            return None  # the same line: planes through it are not unique
        normal = d / np.linalg.norm(d)
    return normal, float(normal @ p1)


def _intersection(l1, l2, tol: float) -> np.ndarray | None:
    x = _concurrent([l1, l2], tol)
    return x
