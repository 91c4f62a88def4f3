from pathlib import Path

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

GRASPS = Path(__file__).resolve().parents[2] / "scenarios" / "grasps"


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


# --- the regions do not depend on the order of the contacts (issue 25) ----------------------


def _orders(n: int, rng: np.random.Generator, n_random: int,
            reversed_too: bool = True) -> list[list[int]]:
    """Every rotation of the contacts, each reversed, and ``n_random`` random orders."""
    rot = [[(i + r) % n for i in range(n)] for r in range(n)]
    rev = [o[::-1] for o in rot] if reversed_too else [rot[0][::-1]]
    return rot + rev + [list(rng.permutation(n)) for _ in range(n_random)]


def _regions_by_contact(grasp, order, face=None):
    """The regions of ``grasp`` with its contacts listed in ``order``, keyed by the original
    index of the moving contact (-1: one more contact), with the fixed ones as original
    indices: ``{k: (fixed, computed, area, vertices (V, 3), inside)}``, and the verdict."""
    from multiarm_pin.grasp import seventh_contact_regions

    g = grasp.with_contacts([grasp.contacts[i] for i in order])
    out = {}
    for r in seventh_contact_regions(g, face=face):
        k = order[r.contact] if r.contact >= 0 else -1
        reg = r.region
        out[k] = (tuple(sorted(order[i] for i in r.fixed)), reg is not None,
                  0.0 if reg is None else reg.area,
                  np.zeros((0, 3)) if reg is None else reg.vertices_3d, r.inside)
    return out, form_closure(g, allow_fewer=True).form_closure


def _assert_same_regions(a, b):
    assert a.keys() == b.keys()
    for k in a:
        (fa, ca, Aa, Va, ia), (fb, cb, Ab, Vb, ib) = a[k], b[k]
        assert (fa, ca, ia) == (fb, cb, ib), k
        assert Aa == pytest.approx(Ab, rel=1e-9, abs=1e-12), k
        assert len(Va) == len(Vb), k
        if len(Va):
            assert _hausdorff(Va, Vb) < 1e-9, k


def _assert_order_free(grasp, rng, n_random, face=None, reversed_too=True):
    ref, verdict = _regions_by_contact(grasp, list(range(len(grasp))), face)
    for order in _orders(len(grasp), rng, n_random, reversed_too):
        got, v = _regions_by_contact(grasp, order, face)
        assert v == verdict, order
        _assert_same_regions(ref, got)
    return ref, verdict


@pytest.mark.parametrize("name", ["box_form_closure", "box_marginal", "hexahedron_point_normal"])
@pytest.mark.parametrize("with_face", [False, True])
def test_shipped_grasps_same_regions_in_every_order(name, with_face):
    from multiarm_pin.grasp import load_grasp_file

    gf = load_grasp_file(GRASPS / f"{name}.yaml")
    rng = np.random.default_rng(25)
    face = gf.seventh_contact_face if with_face else None
    ref, verdict = _assert_order_free(gf.grasp, rng, 4 if with_face else 2, face)
    assert verdict == (name != "box_marginal")
    computed = [k for k, v in ref.items() if v[1]]
    if verdict:  # seven contacts in form closure: every six are independent, every region
        assert sorted(ref) == sorted(computed)  # holds its contact
        assert all(v[2] > 0 and v[4] for v in ref.values())
    else:  # the marginal seventh is on its region's boundary; contact 3's force vanishes
        assert all(v[4] is False for v in ref.values() if v[1])
        assert 2 in ref and not ref[2][1]


@pytest.mark.parametrize("n_contacts, n_grasps", [(7, 3), (8, 1)])
def test_random_form_closure_grasps_same_regions_in_every_order(n_contacts, n_grasps):
    from .conftest import random_form_closure_grasp

    rng = np.random.default_rng(2025 + n_contacts)
    for _ in range(n_grasps):
        g = random_form_closure_grasp(rng, n_contacts, min_margin=0.01)
        ref, verdict = _assert_order_free(g, rng, 2, reversed_too=n_contacts == 7)
        assert verdict
        for k, (_, computed, area, _, inside) in ref.items():
            if n_contacts == 7:  # a seven-contact closure: every six independent
                assert computed
            if computed:  # closure holds at the contact itself: its region holds it
                assert area > 0 and inside, k


def test_regions_agree_with_the_lp_when_the_contact_moves(rng):
    """Each contact's region (others fixed) against the LP with the contact moved there."""
    from multiarm_pin.grasp import seventh_contact_regions

    from .conftest import random_form_closure_grasp

    g = random_form_closure_grasp(np.random.default_rng(7), 7, min_margin=0.01)
    P = g.polyhedron
    checked = 0
    for r in seventh_contact_regions(g):
        face = r.region.face
        for _ in range(12):
            p = random_face_point(P, face, rng, inset=0.0)
            moved = list(g.contacts)
            moved[r.contact] = contact_on_face(P, face, p)
            depth = -1.0 if r.region.empty else _depth(r.region.polygon, r.region.to_face(p))[0]
            if abs(depth) > 1e-6:
                assert form_closure(g.with_contacts(moved)).form_closure == (depth > 0)
                checked += 1
    assert checked >= 70


def test_named_seventh_contact_and_face():
    from multiarm_pin.grasp import load_grasp_file, seventh_contact_regions

    g = load_grasp_file(GRASPS / "box_form_closure.yaml").grasp
    (r,) = seventh_contact_regions(g, seventh=3)  # the -x contact
    assert r.contact == 3 and r.fixed == (0, 1, 2, 4, 5, 6) and r.inside
    assert g.polyhedron.face_names[r.face] == "-x"
    # with a face: where on +z a contact could replace the -x one (nowhere: nothing would
    # push along +x)
    (r,) = seventh_contact_regions(g, seventh=3, face="+z")
    assert r.region.empty and r.inside is None
    (r,) = seventh_contact_regions(g, face="-z")  # the contacts on -z: contact 6 alone
    assert r.contact == 5 and r.inside
    with pytest.raises(GraspError, match="1..7"):
        seventh_contact_regions(g, seventh=7)


def test_a_named_seventh_needs_six_others():
    from multiarm_pin.grasp import load_grasp_file, seventh_contact_regions

    g = load_grasp_file(GRASPS / "box_form_closure.yaml").grasp
    six = g.with_contacts(g.contacts[:6])
    with pytest.raises(GraspError, match="six others held fixed, and the grasp has 6"):
        seventh_contact_regions(six, seventh=2)
    assert seventh_contact_regions(six) == ()


def test_eq_2_3_in_all_720_orders_of_the_six_fixed_contacts():
    """Eq 2.3's blocks depend on the order (e_A is the first three normals, or the best
    triple when those are dependent): all 6! orders of the fixed six give one region."""
    from itertools import permutations

    from multiarm_pin.grasp import load_grasp_file

    g = load_grasp_file(GRASPS / "box_form_closure.yaml").grasp
    six, seventh = g.contacts[:6], g.contacts[6]
    ref = region_by_inverse(g, "+z")
    assert ref.area > 1.0
    for order in permutations(range(6)):
        r = region_by_inverse(g.with_contacts([six[i] for i in order] + [seventh]), "+z")
        assert r.area == pytest.approx(ref.area, rel=1e-9)
        assert len(r.polygon) == len(ref.polygon) and _hausdorff(r.polygon, ref.polygon) < 1e-9
