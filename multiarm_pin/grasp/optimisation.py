"""Grasp optimisation (beyond the thesis): place the contacts for the most robust closure.

Each gripper has a contact layout: the faces its contacts touch and a reach, the largest
distance it can span between two of its contacts. The contacts slide on their faces; the
search maximises the closure displacement bound ``L ε(L)`` of
:mod:`multiarm_pin.grasp.stability` (Ferrari-Canny radius of the unit wrenches times the
length scale, i.e. how far every contact may move before closure can be lost), capped by the
contacts' distance to their face edges, subject to the reach of every gripper. It is a
seeded random search followed by Nelder-Mead refinement with penalties for the constraints.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from multiarm_pin.exceptions import GraspError
from multiarm_pin.grasp.contacts import Grasp, GraspContact
from multiarm_pin.grasp.form_closure import ferrari_canny_epsilon
from multiarm_pin.grasp.stability import closure_bound
from multiarm_pin.model.polyhedron import Polyhedron


@dataclass(frozen=True)
class GripperLayout:
    """Contact layout of one gripper.

    Attributes:
        faces: the face (name or index) touched by each of its contacts.
        reach: largest distance [m] between two of its contacts (``inf``: no limit).
    """

    faces: tuple[str | int, ...]
    reach: float = float("inf")


@dataclass(frozen=True)
class OptimisedGrasp:
    """Result of :func:`optimise_grasp`.

    Attributes:
        grasp: the best grasp found (contacts ordered gripper by gripper).
        objective: its objective ``min(L ε(L), min edge distance)`` [m] at the search's ``L``.
        bound: its closure displacement bound from :func:`closure_bound` [m].
        initial_objective: the objective of the starting placement [m].
        gripper_of_contact: (N,) index of the gripper holding each contact.
        evaluations: number of objective evaluations.
    """

    grasp: Grasp
    objective: float
    bound: float
    initial_objective: float
    gripper_of_contact: np.ndarray
    evaluations: int


def optimise_grasp(
    polyhedron: Polyhedron,
    grippers: Sequence[GripperLayout],
    seed: int = 0,
    samples: int = 300,
    refine: int = 3,
    maxiter: int = 400,
    initial: np.ndarray | None = None,
) -> OptimisedGrasp:
    """Search contact placements maximising the closure displacement bound.

    Args:
        polyhedron: the object's shape (object frame).
        grippers: the grippers' layouts; at least 7 contacts in total.
        seed: random seed (the search is deterministic for a given seed).
        samples: number of random feasible placements tried first.
        refine: how many of the best samples are refined with Nelder-Mead.
        maxiter: Nelder-Mead iterations per refinement.
        initial: optional (N, 2) starting face coordinates ``(s, t)`` of the contacts (in the
            faces' own frames), included among the starting points.

    Returns:
        An :class:`OptimisedGrasp`.

    Raises:
        GraspError: fewer than 7 contacts in total, unknown faces or a non-positive reach.
    """
    faces, owner = [], []
    for g, layout in enumerate(grippers):
        if not layout.reach > 0:
            raise GraspError(f"gripper {g}: reach must be positive [m], got {layout.reach}")
        for f in layout.faces:
            try:
                faces.append(polyhedron.face_index(f))
            except Exception as exc:
                raise GraspError(f"gripper {g}: {exc}") from exc
            owner.append(g)
    N = len(faces)
    if N < 7:
        raise GraspError(f"grasp optimisation: form closure needs >= 7 contacts, got {N}")
    frames = [polyhedron.face_frame(k) for k in faces]
    polys = [(polyhedron.vertices[list(polyhedron.faces[k])] - o) @ R[:, :2]
             for k, (o, R) in zip(faces, frames, strict=True)]  # fmt: skip
    halfplanes = [_halfplanes(P) for P in polys]
    owner_arr = np.array(owner)
    L = max(float(np.abs(polyhedron.vertices).max()), 1e-6)
    count = [0]

    def points(x: np.ndarray) -> np.ndarray:
        s = x.reshape(N, 2)
        return np.array([o + R[:, :2] @ si for (o, R), si in zip(frames, s, strict=True)])

    def violation(x: np.ndarray) -> float:
        s = x.reshape(N, 2)
        v = 0.0
        for (A, b), si in zip(halfplanes, s, strict=True):
            v += float(np.sum(np.maximum(A @ si - b, 0.0)))
        P = points(x)
        for g, layout in enumerate(grippers):
            idx = np.flatnonzero(owner_arr == g)
            for i in range(len(idx)):
                for j in range(i + 1, len(idx)):
                    v += max(np.linalg.norm(P[idx[i]] - P[idx[j]]) - layout.reach, 0.0)
        return v

    def objective(x: np.ndarray) -> float:
        count[0] += 1
        s = x.reshape(N, 2)
        edge = min(float(np.min(b - A @ si)) for (A, b), si in zip(halfplanes, s, strict=True))
        P = points(x)
        normals = np.array([-polyhedron.normals[k] for k in faces])
        W = np.vstack([normals.T, np.cross(P, normals).T / L])
        return min(L * ferrari_canny_epsilon(W), edge)

    def loss(x: np.ndarray) -> float:
        v = violation(x)
        return -objective(x) + 10.0 * v if v == 0 else 10.0 * v + 1.0

    rng = np.random.default_rng(seed)
    starts = []
    if initial is not None:
        starts.append(np.asarray(initial, dtype=float).reshape(-1))
    tries = 0
    while len(starts) < samples and tries < 50 * samples:
        tries += 1
        x = np.concatenate([_random_in(P, rng) for P in polys])
        if violation(x) == 0:
            starts.append(x)
    if not starts:
        raise GraspError("grasp optimisation: no placement satisfies the grippers' reach")
    init_obj = objective(starts[0]) if violation(starts[0]) == 0 else float("-inf")
    scored = sorted(starts, key=loss)
    best_x, best_loss = scored[0], loss(scored[0])
    for x0 in scored[:refine]:
        res = minimize(loss, x0, method="Nelder-Mead",
                       options={"maxiter": maxiter, "xatol": 1e-6, "fatol": 1e-9})  # fmt: skip
        if res.fun < best_loss and violation(res.x) == 0:
            best_x, best_loss = res.x, res.fun
    P = points(best_x)
    contacts = tuple(
        GraspContact(p, -polyhedron.normals[k].copy(), k, _name(polyhedron, k))
        for p, k in zip(P, faces, strict=True)
    )
    grasp = Grasp(contacts, polyhedron)
    return OptimisedGrasp(grasp, objective(best_x), closure_bound(grasp).bound, init_obj,
                          owner_arr, count[0])  # fmt: skip


def _halfplanes(P: np.ndarray):
    d = np.roll(P, -1, axis=0) - P
    n = np.column_stack([d[:, 1], -d[:, 0]])
    area = 0.5 * np.sum(P[:, 0] * np.roll(P[:, 1], -1) - np.roll(P[:, 0], -1) * P[:, 1])
    n = n / np.linalg.norm(n, axis=1)[:, None] * (1.0 if area > 0 else -1.0)
    return n, np.einsum("ij,ij->i", n, P)


def _random_in(P: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    w = rng.dirichlet(np.ones(len(P)))
    return w @ P


def _name(poly: Polyhedron, k: int) -> str:
    return poly.face_names[k] if poly.face_names else f"#{k}"
