import numpy as np
import pytest

from multiarm_pin.exceptions import GraspError
from multiarm_pin.grasp import (
    Grasp,
    box_corner_region_lines,
    contact_on_face,
    form_closure,
    region_by_generators,
    region_by_inverse,
)
from multiarm_pin.grasp.design import parallel_planes_object, two_corner_box_grasp
from multiarm_pin.grasp.seventh_contact import polygon_area
from multiarm_pin.model.polyhedron import box

from .conftest import corner_grasp, random_corner_parameters, random_face_point


def _hausdorff(A, B):
    d = np.linalg.norm(A[:, None, :] - B[None, :, :], axis=2)
    return max(d.min(axis=1).max(), d.min(axis=0).max())


def test_example_2_1_closed_form_equals_both_methods_and_the_lp(rng):
    # Offsets of any sign. The closed form keeps two of the three independent inequalities of
    # Eq 2.3: it silently assumes a c > 0 (the thesis's a..f > 0), since the third component
    # of a_A z = p7 x e7 forces z2 = (a / c) z1. With a c < 0 the region is empty.
    nonempty = empty_by_sign = 0
    for _ in range(30):
        size, (a, b, c, d, e, f) = random_corner_parameters(rng)
        g = corner_grasp(size, a, b, c, d, e, f)
        try:
            r23 = region_by_inverse(g, "+z")
        except GraspError:
            continue  # dependent six (det(a_A) ~ 0)
        r24 = region_by_generators(g, "+z")
        assert r23.empty == r24.empty
        if not r23.empty:
            nonempty += 1
            assert _hausdorff(r23.polygon, r24.polygon) < 1e-7
            assert abs(r23.area - r24.area) < 1e-8 * max(1.0, r23.area)
        A, rhs = box_corner_region_lines(a, b, c, d, e, f)
        lx, ly, lz = size / 2
        xy = rng.uniform(-1, 1, (300, 2)) * [lx, ly]
        closed_form = np.all(xy @ A.T < rhs, axis=1)
        if a > 0 and c > 0:  # the thesis's two lines are the same region
            A2, rhs2 = box_corner_region_lines(a, b, c, d, e, f, thesis_form=True)
            assert np.array_equal(closed_form, np.all(xy @ A2.T < rhs2, axis=1))
        if a * c < 0:
            empty_by_sign += 1
            assert r23.empty and r24.empty and not closed_form.any()
        s = r23.to_face(np.column_stack([xy, np.full(len(xy), lz)]))
        # the LP on the seven wrenches, for a subset of the points (it is the slow part)
        W6 = g.wrenches()
        e7 = np.array([0.0, 0.0, -1.0])
        w7 = [np.r_[e7, np.cross([q[0], q[1], lz], e7)] for q in xy[:40]]
        lp = np.array([form_closure(np.column_stack([W6, w])).form_closure for w in w7])
        assert np.array_equal(closed_form[:40], lp)
        # polygon membership agrees away from its boundary
        depth = np.full(len(s), -1.0) if r23.empty else _depth(r23.polygon, s)
        clear = np.abs(depth) > 1e-9
        assert np.array_equal((depth > 0)[clear], closed_form[clear])
        assert np.array_equal(r24.contains(s)[clear], closed_form[clear])
    assert nonempty >= 8 and empty_by_sign >= 4


def _depth(poly, s):
    d = np.roll(poly, -1, axis=0) - poly
    n = np.column_stack([d[:, 1], -d[:, 0]])
    n /= np.linalg.norm(n, axis=1)[:, None]
    return np.min(np.einsum("ij,ij->i", n, poly)[None, :] - s @ n.T, axis=1)


def test_region_polygon_is_ccw_on_the_face_and_vertices_are_on_the_face():
    g = two_corner_box_grasp([2, 1.5, 1], 0.2, 0.1, 0.5)
    r = region_by_inverse(g, "+z")
    assert polygon_area(r.polygon) > 0
    assert not r.bounded
    for v in r.vertices_3d:
        assert g.polyhedron.point_on_face(v, "+z", 1e-9)


def test_more_than_seven_contacts_region_by_eq_2_4_matches_lp(rng):
    P = box([2.0, 1.5, 1.0])
    g7 = two_corner_box_grasp([2, 1.5, 1], 0.2, 0.1, 0.5)
    extra = contact_on_face(P, "-x", [-1.0, 0.5, 0.3])
    fixed = Grasp(g7.contacts[:6] + (extra,), P)
    for face in ("+z", "+y", "-z"):
        r = region_by_generators(fixed, face)
        hits = compared = 0
        for _ in range(60):
            p = random_face_point(P, face, rng, inset=0.0)
            closes = form_closure(
                fixed.with_contacts(fixed.contacts + (contact_on_face(P, face, p),))
            ).form_closure
            depth = -1.0 if r.empty else _depth(r.polygon, r.to_face(p))[0]
            if abs(depth) > 1e-9:
                assert closes == (depth > 0)
                hits += closes
                compared += 1
        # compared, both verdicts (every point here is at least 4e-3 from the boundary)
        assert compared >= 50 and 10 <= hits <= compared - 10, (face, compared, hits)
        # with seven fixed contacts the region grows: it contains Eq 2.3's region of the six
        r6 = region_by_generators(g7.with_contacts(g7.contacts[:6]), face)
        if not r6.empty:
            assert r.area >= r6.area - 1e-9


def test_empty_region_is_reported_clearly(rng):
    # a narrow box: the +y contact lies beyond the centre (c = l_x - A < 0 while a > 0), so
    # the two inequalities z1 < 0 and z2 = (a / c) z1 < 0 of Eq 2.3 exclude each other
    size = [0.8, 2.0, 2.0]
    A, E = 0.45, 0.05
    lx, ly, lz = np.array(size) / 2
    g = corner_grasp(size, ly - A, lz - A, lx - A, lz - A, lx - E, ly - A)
    r23, r24 = region_by_inverse(g, "+z"), region_by_generators(g, "+z")
    assert r23.empty and r24.empty
    assert r23.polygon.shape == (0, 2) and r23.vertices_3d.shape == (0, 3)
    assert "do not meet" in r23.reason and r24.reason
    for _ in range(50):
        p = random_face_point(g.polyhedron, "+z", rng, inset=0.0)
        assert not form_closure(
            g.with_contacts(g.contacts + (contact_on_face(g.polyhedron, "+z", p),))
        ).form_closure


def test_general_polyhedron_both_methods_agree():
    P = parallel_planes_object(np.radians(-20), np.radians(-15), np.radians(-10), [1.2, 1.0, 0.8])
    corner = P.vertices[np.argmax(P.vertices.sum(axis=1))]

    def near(face, frac, c):
        k = P.face_index(face)
        V = P.vertices[list(P.faces[k])]
        v = V[np.argmin(np.linalg.norm(V - c, axis=1))]
        return v + frac * (V.mean(axis=0) - v)

    cs = [
        contact_on_face(P, f, near(f, fr, corner))
        for f, fr in [("front", 0.3), ("side", 0.3), ("top", 0.2)]
    ]
    cs += [
        contact_on_face(P, f, near(f, fr, -corner))
        for f, fr in [("back", 0.3), ("other_side", 0.3), ("bottom", 0.2)]
    ]
    g = Grasp(tuple(cs), P)
    for face in ("top", "front", "bottom"):
        r23, r24 = region_by_inverse(g, face), region_by_generators(g, face)
        assert r23.empty == r24.empty
        if not r23.empty:
            assert _hausdorff(r23.polygon, r24.polygon) < 1e-7


def test_region_input_errors():
    g = two_corner_box_grasp([2, 1.5, 1], 0.2, 0.1, 0.5)
    with pytest.raises(GraspError, match="face"):
        region_by_inverse(g, "+q")
    with pytest.raises(GraspError, match="exactly six"):
        region_by_inverse(g, "+z", fixed=(0, 1, 2, 3, 4))
    with pytest.raises(GraspError, match="at least six"):
        region_by_generators(g, "+z", fixed=(0, 1, 2))
    with pytest.raises(GraspError, match="polyhedron"):
        region_by_inverse(Grasp(g.contacts), "+z")
    with pytest.raises(GraspError, match="det"):
        box_corner_region_lines(1, 1, 1, 1, 1, 1)
