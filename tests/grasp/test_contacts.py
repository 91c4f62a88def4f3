import numpy as np
import pytest

from multiarm_pin.exceptions import GraspError, InputError
from multiarm_pin.grasp import contact_from_point_normal, contact_on_face, wrench_matrix
from multiarm_pin.model.polyhedron import box, from_vertices
from multiarm_pin.spatial import wrench_transform


def test_contact_on_box_face_has_inward_normal_and_zero_pitch_wrench():
    P = box([2.0, 1.5, 1.0])
    c = contact_on_face(P, "+x", [1.0, 0.3, 0.2])
    np.testing.assert_allclose(c.normal, [-1.0, 0.0, 0.0])
    w = c.wrench()
    # explicit cross product (1, .3, .2) x (-1, 0, 0) = (0, -0.2, 0.3)
    np.testing.assert_allclose(w, [-1, 0, 0, 0.0, -0.2, 0.3])
    assert abs(w[:3] @ w[3:]) < 1e-15  # zero pitch: force ⟂ moment
    assert c.face == 0 and c.label == "+x"


def test_wrench_about_another_origin_matches_spatial_transform(rng):
    P = np.array([[1.0, 0.2, -0.3], [0.1, 0.75, 0.4], [-0.5, 0.1, 0.5]])
    N = np.array([[-1.0, 0, 0], [0, -1.0, 0], [0, 0, -1.0]])
    o = rng.normal(size=3)
    W0 = wrench_matrix(P, N)
    Wo = wrench_matrix(P, N, origin=o)
    np.testing.assert_allclose(Wo, wrench_transform(np.eye(3), -o) @ W0, atol=1e-14)
    np.testing.assert_allclose(wrench_matrix(P, N, length_scale=2.0)[3:], W0[3:] / 2.0)


def test_point_off_its_face_is_rejected_with_distance():
    P = box([2.0, 1.5, 1.0])
    with pytest.raises(GraspError, match=r"not on face \+x.*\+0\.2 m"):
        contact_on_face(P, "+x", [1.2, 0.0, 0.0])
    with pytest.raises(GraspError, match="outside the face"):
        contact_on_face(P, "+x", [1.0, 0.9, 0.0])


def test_bad_face_index_or_name_is_rejected():
    P = box([2.0, 1.5, 1.0])
    with pytest.raises(GraspError, match="out of range 0..5"):
        contact_on_face(P, 6, [1.0, 0.0, 0.0])
    with pytest.raises(GraspError, match=r"unknown face '\+w'"):
        contact_on_face(P, "+w", [1.0, 0.0, 0.0])
    with pytest.raises(GraspError, match="contact point"):
        contact_on_face(P, "+x", [1.0, 0.0])


def test_point_normal_contact_is_matched_to_its_face():
    P = from_vertices([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    c = contact_from_point_normal([0.2, 0.2, 0.0], [0, 0, 2.0], P)
    np.testing.assert_allclose(c.normal, [0, 0, 1.0])
    assert c.face >= 0
    with pytest.raises(GraspError, match="no face"):
        contact_from_point_normal([0.2, 0.2, 0.0], [0, 1.0, 0], P)
    with pytest.raises(GraspError, match="non-zero"):
        contact_from_point_normal([0.2, 0.2, 0.0], [0, 0, 0], P)


def test_wrench_matrix_checks_shapes():
    with pytest.raises(InputError, match="2 points and 1 normals"):
        wrench_matrix(np.zeros((2, 3)), np.ones((1, 3)))
    with pytest.raises(InputError, match="length_scale"):
        wrench_matrix(np.zeros((1, 3)), np.ones((1, 3)), length_scale=0.0)
