"""Shared builders for the grasp tests."""

from __future__ import annotations

import numpy as np
import pytest

from multiarm_pin.grasp import Grasp, contact_on_face
from multiarm_pin.model.polyhedron import box


def corner_grasp(size, a, b, c, d, e, f, seventh=None) -> Grasp:
    """Example 2.1: p1 = (lx, a, b) on +x, p2 = (c, ly, d) on +y, p3 = (e, f, lz) on +z,
    p4..6 = -p1..3, and optionally a seventh contact (x, y) on +z."""
    P = box(size)
    lx, ly, lz = np.asarray(size) / 2
    p1, p2, p3 = np.array([lx, a, b]), np.array([c, ly, d]), np.array([e, f, lz])
    specs = [("+x", p1), ("+y", p2), ("+z", p3), ("-x", -p1), ("-y", -p2), ("-z", -p3)]
    if seventh is not None:
        specs.append(("+z", np.array([seventh[0], seventh[1], lz])))
    return Grasp(tuple(contact_on_face(P, fc, p) for fc, p in specs), P)


def random_corner_parameters(rng: np.random.Generator):
    """Random box size and Example 2.1 offsets a..f strictly inside the faces."""
    size = rng.uniform(0.5, 3.0, 3)
    lx, ly, lz = size / 2
    a, f = rng.uniform(-0.95, 0.95, 2) * ly
    b, d = rng.uniform(-0.95, 0.95, 2) * lz
    c, e = rng.uniform(-0.95, 0.95, 2) * lx
    return size, (a, b, c, d, e, f)


def random_face_point(P, face, rng, inset=0.02):
    """A random point strictly inside a face of polyhedron P."""
    k = P.face_index(face)
    V = P.vertices[list(P.faces[k])]
    w = rng.dirichlet(np.ones(len(V)))
    c = V.mean(axis=0)
    return c + (1 - inset) * (w @ V - c)


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def random_form_closure_grasp(rng: np.random.Generator, n_contacts: int = 7,
                              min_margin: float = 0.01, tries: int = 500) -> Grasp:
    """A random form-closure grasp of a random box whose LP margin exceeds ``min_margin``.

    One contact on each face (in a random order) and the others on random faces, all strictly
    inside their faces; draws whose LP margin is not clearly positive are thrown away, so the
    verdict holds by construction (not by round-off).
    """
    from multiarm_pin.grasp import form_closure

    for _ in range(tries):
        P = box(rng.uniform(0.5, 2.5, 3))
        faces = list(P.face_names) + list(rng.choice(P.face_names, n_contacts - 6))
        rng.shuffle(faces)
        g = Grasp(tuple(contact_on_face(P, f, random_face_point(P, f, rng, inset=0.1))
                        for f in faces), P)
        if form_closure(g).margin > min_margin:
            return g
    raise RuntimeError(f"no form-closure grasp with margin > {min_margin} in {tries} draws")
