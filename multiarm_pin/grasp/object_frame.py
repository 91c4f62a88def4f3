"""The object's pose from the contact points of a form-closure grasp (thesis Sec 2.4, App. B).

* :func:`objfrm` is the thesis's exact algorithm (Eq 2.5-2.17, Matlab ``objfrm``) for an
  object with three pairs of parallel faces: from the contact points ``p1..p7`` (``p1, p7``
  on the face with outward normal ``n1``, ``p4`` on the opposite face, ``p2/p5`` and
  ``p3/p6`` on the other two pairs) and the distances ``l1, l2, l3`` between the pairs, it
  finds ``n1`` from two linear equations and ``|n1| = 1`` (a quadratic: two candidates), then
  ``R2 n2`` from Eq 2.11-2.13 for each candidate, keeps the candidate giving a unit vector
  (Eq 2.14), and solves Eq 2.15-2.17 for the origin. Two OCR errors are corrected: the
  quadratic's middle coefficient is ``2 (AB + CD)`` (as in the Matlab, not ``AB + DC``) and
  Eq 2.17 uses ``p3``. The pivot component of ``n1`` is chosen for the best-conditioned 2 x 2
  solve instead of always ``x``.
* :func:`object_frame_from_box_contacts` wraps it for a box given contacts labelled by face.
* :func:`object_frame_lstsq` fits the pose to any number of contacts on any convex polyhedron
  by nonlinear least squares on the point-to-face distances, accepts noisy measurements and
  returns the residuals.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from multiarm_pin.exceptions import GraspError, SingularityError
from multiarm_pin.model.polyhedron import Polyhedron, box
from multiarm_pin.spatial import as_array, skew


@dataclass(frozen=True)
class ObjectPose:
    """Pose of the object frame in the world (measurement) frame.

    Attributes:
        rotation: (3, 3) object axes -> world axes.
        position: (3,) object-frame origin in world coordinates [m].
        residuals: (N,) signed distance [m] of each contact point to its face at this pose.
        rms: root mean square of ``residuals`` [m].
    """

    rotation: np.ndarray
    position: np.ndarray
    residuals: np.ndarray
    rms: float


def objfrm(
    p: np.ndarray, R2: np.ndarray, R3: np.ndarray, l1: float, l2: float, l3: float
) -> tuple[np.ndarray, np.ndarray]:
    """The thesis's ``objfrm`` (Appendix B): object axes and origin from seven contacts.

    Args:
        p: (3, 7) contact points as columns, world frame [m], in the thesis's roles: ``p1``
            and ``p7`` on the face with outward normal ``n1``, ``p2`` on ``n2``, ``p3`` on
            ``n3``, ``p4, p5, p6`` on the faces parallel to those of ``p1, p2, p3``.
        R2: (3, 3) constant rotation, the object's y axis is ``R2 n2`` (identity for a box).
        R3: (3, 3) constant rotation, the z axis is ``R3 n3`` (identity for a box).
        l1: distance [m] between the faces of ``p1`` and ``p4``.
        l2: distance [m] between the faces of ``p2`` and ``p5``.
        l3: distance [m] between the faces of ``p3`` and ``p6``.

    Returns:
        ``(n, po)``: ``n`` (3, 3) with columns ``n1, R2 n2, n1 × R2 n2`` (object axes in
        the world) and ``po`` (3,) the point equidistant from each pair of faces [m].

    Raises:
        SingularityError: the contact points do not determine the frame (e.g. ``p1, p7, p4``
            aligned with ``n1``).
    """
    P = as_array(p, (3, 7), "objfrm contact points")
    d1 = P[:, 0] - P[:, 3]
    d2 = P[:, 6] - P[:, 3]
    d3 = P[:, 1] - P[:, 4]
    d4 = P[:, 2] - P[:, 5]
    # Eq 2.5-2.6: [d1; d2] n1 = [l1; l1]; pick the free component giving the best 2x2 solve
    D = np.vstack([d1, d2])
    best = max(range(3), key=lambda i: abs(np.linalg.det(np.delete(D, i, axis=1))))
    others = [j for j in range(3) if j != best]
    M2 = D[:, others]
    if abs(np.linalg.det(M2)) < 1e-14 * max(1.0, np.abs(D).max() ** 2):
        raise SingularityError(
            "objfrm: [p1 - p4; p7 - p4]", np.inf, "contacts p1, p7, p4 degenerate"
        )
    # n1[others] = u + v n1[best]   (Eq 2.10)
    u = np.linalg.solve(M2, np.array([l1, l1]))
    v = np.linalg.solve(M2, -D[:, best])
    # Eq 2.9: x^2 + |u + v x|^2 = 1
    qa = 1.0 + v @ v
    qb = 2.0 * (u @ v)
    qc = u @ u - 1.0
    disc = max(qb * qb - 4 * qa * qc, 0.0)
    cands = []
    for x in ((-qb + np.sqrt(disc)) / (2 * qa), (-qb - np.sqrt(disc)) / (2 * qa)):
        n1 = np.zeros(3)
        n1[best] = x
        n1[others] = u + v * x
        cands.append(n1)
    sols = []
    for n1 in cands:
        # Eq 2.11-2.13: d3ᵀ R2ᵀ y = l2, n1ᵀ y = 0, d4ᵀ R3ᵀ (n1 × y) = l3, y = R2 n2
        A = np.vstack([d3 @ R2.T, n1, d4 @ R3.T @ skew(n1)])
        try:
            y = np.linalg.solve(A, np.array([l2, 0.0, l3]))
        except np.linalg.LinAlgError:
            y = np.full(3, np.nan)
        sols.append((n1, y))
    errs = [abs(y @ y - 1.0) if np.all(np.isfinite(y)) else np.inf for _, y in sols]
    n1, y = sols[int(np.argmin(errs))]  # Eq 2.14
    if not np.isfinite(min(errs)):
        raise SingularityError("objfrm: Eq 2.11-2.13", np.inf, "n2 cannot be determined")
    n = np.column_stack([n1, y, np.cross(n1, y)])
    # Eq 2.15-2.17
    A = np.vstack([n[:, 0], n[:, 1] @ R2, n[:, 2] @ R3])
    b = np.array(
        [
            n[:, 0] @ P[:, 0] - l1 / 2,
            n[:, 1] @ R2 @ P[:, 1] - l2 / 2,
            n[:, 2] @ R3 @ P[:, 2] - l3 / 2,
        ]
    )
    return n, np.linalg.solve(A, b)


def object_frame_from_box_contacts(points, faces: Sequence[str], size) -> ObjectPose:
    """Pose of a box from seven contact points labelled by face, with the exact ``objfrm``.

    Args:
        points: (7, 3) contact points in the world frame [m].
        faces: seven face names (``+x -x +y -y +z -z``): one face holds two contacts, every
            face at least one.
        size: (3,) box edge lengths [m] (the box is centred on its frame).

    Returns:
        The :class:`ObjectPose` (residuals: distance of each point to its face).

    Raises:
        GraspError: wrong number of points, unknown face names or a face without contact.
    """
    P = as_array(points, (7, 3), "contact points")
    s = as_array(size, (3,), "box size")
    names = list(faces)
    valid = ("+x", "-x", "+y", "-y", "+z", "-z")
    if len(names) != 7 or any(f not in valid for f in names):
        raise GraspError(f"objfrm: expected seven face names among {valid}, got {names}")
    count = {f: names.count(f) for f in valid}
    if min(count.values()) < 1:
        missing = [f for f in valid if count[f] == 0]
        raise GraspError(f"objfrm: every face needs a contact; none on {missing}")
    doubled = next(f for f in valid if count[f] == 2)
    i = "xyz".index(doubled[1])
    si = 1.0 if doubled[0] == "+" else -1.0
    j, k = (i + 1) % 3, (i + 2) % 3
    sign = {1.0: "+", -1.0: "-"}

    def pick(face: str, nth: int = 0) -> np.ndarray:
        return P[[m for m, f in enumerate(names) if f == face][nth]]

    opp = sign[-si] + "xyz"[i]
    kface, kopp = sign[si] + "xyz"[k], sign[-si] + "xyz"[k]
    roles = [
        pick(doubled, 0), pick("+" + "xyz"[j]), pick(kface), pick(opp),
        pick("-" + "xyz"[j]), pick(kopp), pick(doubled, 1),
    ]  # fmt: skip
    n, po = objfrm(np.array(roles).T, np.eye(3), np.eye(3), s[i], s[j], s[k])
    R = np.zeros((3, 3))
    R[:, i] = si * n[:, 0]
    R[:, j] = n[:, 1]
    R[:, k] = si * n[:, 2]
    poly = box(s)
    idx = [poly.face_index(f) for f in names]
    res = _residuals(R, po, P, poly, idx)
    return ObjectPose(R, po, res, float(np.sqrt(np.mean(res**2))))


def object_frame_lstsq(
    points,
    faces: Sequence[int | str],
    polyhedron: Polyhedron,
    initial: tuple[np.ndarray, np.ndarray] | None = None,
    restarts: int = 8,
    seed: int = 0,
) -> ObjectPose:
    """Least-squares pose of a polyhedron from N >= 6 contact points labelled by face.

    Minimises ``Σ_j (n_kjᵀ Rᵀ (p_j - t) - d_kj)^2`` over the rotation ``R`` and position
    ``t``: the distances of the measured points to their faces.

    Args:
        points: (N, 3) measured contact points, world frame [m].
        faces: N face indices or names of ``polyhedron``.
        polyhedron: the object's shape in its own frame.
        initial: optional ``(R (3, 3), t (3,))`` starting pose; otherwise the identity and
            ``restarts`` seeded random rotations are tried and the best fit kept.
        restarts: number of random starting rotations when ``initial`` is None.
        seed: seed of those rotations.

    Returns:
        The best :class:`ObjectPose` found.

    Raises:
        GraspError: fewer than 6 points, or unknown faces.
    """
    P = as_array(points, (None, 3), "contact points")
    if len(P) < 6 or len(faces) != len(P):
        raise GraspError(
            f"object frame: expected N >= 6 points and N face labels, got {len(P)} points and "
            f"{len(faces)} labels"
        )
    try:
        idx = [polyhedron.face_index(f) for f in faces]
    except Exception as exc:
        raise GraspError(f"object frame: {exc}") from exc
    if initial is not None:
        starts = [(np.asarray(initial[0], float), np.asarray(initial[1], float))]
    else:
        rng = np.random.default_rng(seed)
        c = P.mean(axis=0)
        starts = [(np.eye(3), c)] + [
            (Rotation.random(random_state=rng).as_matrix(), c) for _ in range(restarts)
        ]
    best = None
    for R0, t0 in starts:

        def fun(x, R0=R0):
            R = Rotation.from_rotvec(x[:3]).as_matrix() @ R0
            return _residuals(R, x[3:], P, polyhedron, idx)

        sol = least_squares(
            fun, np.concatenate([np.zeros(3), t0]), xtol=1e-15, ftol=1e-15, gtol=1e-15
        )
        if best is None or sol.cost < best[0]:
            R = Rotation.from_rotvec(sol.x[:3]).as_matrix() @ R0
            best = (sol.cost, R, sol.x[3:].copy())
    _, R, t = best
    res = _residuals(R, t, P, polyhedron, idx)
    return ObjectPose(R, t, res, float(np.sqrt(np.mean(res**2))))


def _residuals(R, t, P, poly: Polyhedron, idx) -> np.ndarray:
    q = (P - t) @ R  # object-frame coordinates
    return np.einsum("ij,ij->i", poly.normals[idx], q) - poly.offsets[idx]

