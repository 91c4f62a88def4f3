"""Configuration stability of form-closure grasps (thesis Sec 2.3).

How far may the contacts slide on their faces before the grasp is lost?

* :func:`independence_bound` (Sec 2.3.1): displacing the six independent contacts by
  ``p̄_k`` (normals fixed on a polyhedron) changes ``a = a_A T1 + a_B`` by
  ``Δ = ā_A T1 + ā_B`` with columns of ``ā`` equal to ``p̄_k × e_k``. Column j of ``Δ`` has
  norm at most ``δ (1 + Σ_i |T1_ij|)`` when every ``|p̄_k| <= δ``, and ``a + Δ`` stays
  nonsingular while ``||Δ||_2 <= ||Δ||_F < σ_min(a)``. Hence the six contacts stay
  independent for every displacement below
  ``δ_ind = σ_min(a) / sqrt(Σ_j (1 + Σ_i |T1_ij|)^2)``.
* :func:`closure_bound`: a rigorous bound for the whole grasp. With moments divided by a
  length ``L`` the unit wrenches move by at most ``δ / L`` when the contacts move by ``δ``;
  the hull of the wrenches keeps the origin inside while that is below its Ferrari-Canny
  radius ``ε(L)``. So closure survives any displacements below ``max_L L ε(L)``.
* :func:`linearised_margins` (Sec 2.3.2, Example 2.4): the measures ``g = W6^-1 w7`` of
  Eq 2.3 (all negative inside the region), their gradients with respect to the in-face
  coordinates of every contact, the thesis's estimate ``Σ |∂g/∂x| δ`` of their change and the
  displacement at which that estimate reaches the measure.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multiarm_pin.exceptions import GraspError
from multiarm_pin.grasp.contacts import Grasp
from multiarm_pin.grasp.form_closure import ferrari_canny_epsilon
from multiarm_pin.grasp.independence import block_decomposition


@dataclass(frozen=True)
class ClosureBound:
    """Displacement bound keeping form closure.

    Attributes:
        bound: ``max_L L ε(L)`` [m]: any contact displacements along their faces smaller than
            this keep form closure (0 when the grasp is not closed).
        length_scale: the ``L`` [m] achieving it.
        epsilon: Ferrari-Canny radius ``ε(L)`` of the scaled wrenches (dimensionless).
        edge_distances: (N,) distance [m] of each contact to the edges of its face (``inf``
            when the contact has no face); beyond it the contact leaves the face.
    """

    bound: float
    length_scale: float
    epsilon: float
    edge_distances: np.ndarray


@dataclass(frozen=True)
class LinearisedMargins:
    """Linearised measures of the last contact's region (Example 2.4).

    Attributes:
        measures: (6,) ``g = W6^-1 w7``; all negative when the grasp is closed.
        gradients: (6, 7, 2) ``∂g / ∂(s, t)`` for the in-face coordinates of each contact
            [1/m] (contacts 0..5 fixed, 6 the last one).
        sensitivity: (6,) ``Σ |∂g/∂x|`` over all 14 in-face coordinates [1/m].
        tolerance: (6,) ``-g / sensitivity`` [m]: displacement per coordinate at which the
            linear estimate of a measure's change equals its margin (negative if violated).
        min_tolerance: the smallest of ``tolerance`` [m].
    """

    measures: np.ndarray
    gradients: np.ndarray
    sensitivity: np.ndarray
    tolerance: np.ndarray
    min_tolerance: float


def independence_bound(grasp: Grasp, indices=(0, 1, 2, 3, 4, 5)) -> float:
    """Largest displacement [m] of each of six contacts that provably keeps them independent.

    Args:
        grasp: the grasp (contacts on polyhedron faces, normals fixed under displacement).
        indices: the six independent contacts.

    Returns:
        ``σ_min(a) / sqrt(Σ_j (1 + Σ_i |T1_ij|)^2)`` [m]; 0 when they are not independent.
    """
    idx = list(indices)
    if len(idx) != 6:
        raise GraspError(f"independence bound: expected six contact indices, got {idx}")
    dec = block_decomposition(grasp.points[idx], grasp.normals[idx])
    if not dec.independent:
        return 0.0
    sigma = np.linalg.svd(dec.a, compute_uv=False)[-1]
    col = 1.0 + np.abs(dec.T1).sum(axis=0)
    return float(sigma / np.sqrt(np.sum(col**2)))


def closure_bound(grasp: Grasp, length_scales=None) -> ClosureBound:
    """Displacement bound keeping form closure (Ferrari-Canny radius times length scale).

    Args:
        grasp: the grasp (at least 7 contacts).
        length_scales: candidate ``L`` [m] (default: 25 values from 0.05 to 20 times the
            largest contact distance from the origin); the best is kept.

    Returns:
        A :class:`ClosureBound`.
    """
    pts = grasp.points
    char = max(float(np.linalg.norm(pts, axis=1).max(initial=0.0)), 1e-6)
    Ls = np.geomspace(0.05, 20.0, 25) * char if length_scales is None else np.asarray(length_scales)
    best = (0.0, float(Ls[0]), 0.0)
    for L in Ls:
        eps = ferrari_canny_epsilon(grasp.wrenches(None, float(L)))
        if L * eps > best[0]:
            best = (float(L * eps), float(L), float(eps))
    return ClosureBound(best[0], best[1], best[2], edge_distances(grasp))


def edge_distances(grasp: Grasp) -> np.ndarray:
    """(N,) distance [m] from each contact to the boundary of its face (``inf`` if no face)."""
    poly = grasp.polyhedron
    out = np.full(len(grasp), np.inf)
    if poly is None:
        return out
    for i, c in enumerate(grasp.contacts):
        if c.face < 0:
            continue
        origin, R = poly.face_frame(c.face)
        V = (poly.vertices[list(poly.faces[c.face])] - origin) @ R[:, :2]
        s = (c.point - origin) @ R[:, :2]
        d = np.roll(V, -1, axis=0) - V
        nrm = np.column_stack([d[:, 1], -d[:, 0]])
        nrm /= np.linalg.norm(nrm, axis=1)[:, None]
        sign = 1.0 if _area(V) > 0 else -1.0
        out[i] = float(np.min(sign * np.einsum("ij,ij->i", nrm, V - s)))
    return out


def tangent_basis(grasp: Grasp, k: int) -> np.ndarray:
    """(3, 2) in-face unit axes of contact k (its face's ``u, v``; any tangent pair if none)."""
    c = grasp.contacts[k]
    if grasp.polyhedron is not None and c.face >= 0:
        return grasp.polyhedron.face_frame(c.face)[1][:, :2]
    n = c.normal
    a = np.eye(3)[int(np.argmin(np.abs(n)))]
    u = np.cross(n, a)
    u /= np.linalg.norm(u)
    return np.column_stack([u, np.cross(n, u)])


def linearised_margins(grasp: Grasp, fixed=(0, 1, 2, 3, 4, 5), last: int = 6) -> LinearisedMargins:
    """Measures of Eq 2.3 for the last contact and their linearised change (Example 2.4).

    Args:
        grasp: grasp with at least seven contacts.
        fixed: the six independent contacts.
        last: index of the contact whose region is examined.

    Returns:
        A :class:`LinearisedMargins`.

    Raises:
        GraspError: wrong indices or dependent fixed contacts.
    """
    idx = list(fixed)
    if len(idx) != 6 or last in idx or not 0 <= last < len(grasp):
        raise GraspError(
            f"linearised margins: expected six fixed contacts and a different last one in "
            f"0..{len(grasp) - 1}, got fixed={idx}, last={last}"
        )
    P, N = grasp.points, grasp.normals
    dec = block_decomposition(P[idx], N[idx])
    if not dec.independent:
        raise GraspError("linearised margins: the six fixed contacts are not independent")
    order = [idx[i] for i in dec.order]
    Winv = dec.inverse()  # rows follow `order`
    e7, p7 = N[last], P[last]
    g = Winv @ np.concatenate([e7, np.cross(p7, e7)])
    grads = np.zeros((6, 7, 2))
    for j, k in enumerate(order):
        T = tangent_basis(grasp, k)
        for a in range(2):
            dcol = np.cross(T[:, a], N[k])
            grads[:, idx.index(k), a] = -Winv[:, 3:] @ dcol * g[j]
    T = tangent_basis(grasp, last)
    for a in range(2):
        grads[:, 6, a] = Winv[:, 3:] @ np.cross(T[:, a], e7)
    # rows of g follow `order`; report them in the order of `fixed`
    perm = [order.index(k) for k in idx]
    g, grads = g[perm], grads[perm]
    sens = np.abs(grads).reshape(6, -1).sum(axis=1)
    tol = np.where(sens > 0, -g / np.where(sens > 0, sens, 1.0), np.inf)
    return LinearisedMargins(g, grads, sens, tol, float(np.min(tol)))


def _area(V: np.ndarray) -> float:
    x, y = V[:, 0], V[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))
