import numpy as np
import pytest

from multiarm_pin.exceptions import GraspError
from multiarm_pin.grasp import Grasp, form_closure
from multiarm_pin.grasp.design import (
    minimal_seventh_offset,
    parallel_planes_object,
    seventh_offset_min,
    two_corner_box_grasp,
)


def test_D_x_equals_2_A_minus_E_for_random_boxes(rng):
    for _ in range(15):
        size = rng.uniform(1.0, 4.0, 3)
        A = rng.uniform(0.05, 0.3)
        E = rng.uniform(0.05, 1.3 * A)  # keeps the seventh contact on the face when A < E
        Dx = seventh_offset_min(A, E)
        g = two_corner_box_grasp(size, A, E, 1.5 * Dx)
        six = Grasp(g.contacts[:6], g.polyhedron)
        direction = [-1.0, 0, 0] if A > E else [1.0, 0, 0]
        # from the region of Eq 2.3 ...
        assert abs(minimal_seventh_offset(six, "+z", g.contacts[2].point, direction) - Dx) < 1e-9
        # ... and from the LP on both sides of the boundary
        assert form_closure(two_corner_box_grasp(size, A, E, Dx * 1.01)).form_closure
        assert not form_closure(two_corner_box_grasp(size, A, E, Dx * 0.99)).form_closure


def test_same_grippers_grasp_boxes_of_any_large_size():
    A, E, D = 0.15, 0.05, 0.3
    for size in ([1.0, 1.0, 1.0], [3.0, 1.2, 0.8], [10.0, 7.0, 5.0]):
        assert form_closure(two_corner_box_grasp(size, A, E, D)).form_closure


def test_two_corner_grasp_errors():
    with pytest.raises(GraspError, match="A == E"):
        two_corner_box_grasp([2, 2, 2], 0.2, 0.2, 0.5)
    with pytest.raises(GraspError, match="outside the face"):
        two_corner_box_grasp([0.5, 2, 2], 0.2, 0.1, 0.5)


def test_parallel_planes_object_is_centrally_symmetric_with_named_faces():
    P = parallel_planes_object(np.radians(-20), np.radians(-15), np.radians(-10), [1.2, 1.0, 0.8])
    assert sorted(P.face_names) == sorted(["front", "side", "top", "back", "other_side", "bottom"])
    for name, opp in [("front", "back"), ("side", "other_side"), ("top", "bottom")]:
        i, j = P.face_index(name), P.face_index(opp)
        np.testing.assert_allclose(P.normals[i], -P.normals[j], atol=1e-12)
        assert abs(P.offsets[i] - P.offsets[j]) < 1e-12
    np.testing.assert_allclose(P.normals[P.face_index("top")], [0, 0, 1], atol=1e-12)
    assert P.contains(np.array([1.2, 1.0, 0.8]), 1e-9)
    with pytest.raises(GraspError, match="dependent"):
        parallel_planes_object(0.0, np.pi / 2, 0.0, [1, 1, 1])
