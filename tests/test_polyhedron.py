import numpy as np
import pytest

from multiarm_pin.exceptions import InputError
from multiarm_pin.model.polyhedron import box, from_vertices


def test_box_faces_and_frames():
    b = box([2.0, 1.5, 1.0])
    assert b.face_names == ("+x", "-x", "+y", "-y", "+z", "-z")
    assert b.face_index("-y") == 3
    assert b.point_on_face(np.array([1.0, 0.3, 0.2]), "+x")
    assert not b.point_on_face(np.array([1.0, 0.9, 0.2]), "+x")  # outside the face
    origin, R = b.face_frame("+z")
    assert np.allclose(origin, [0, 0, 0.5]) and np.allclose(R[:, 2], [0, 0, 1])
    assert np.allclose(R.T @ R, np.eye(3))
    for k, face in enumerate(b.faces):  # counter-clockwise about the outward normal
        p = b.vertices[list(face)]
        area = sum(np.cross(p[i], p[(i + 1) % len(p)]) for i in range(len(p)))
        assert area @ b.normals[k] > 0


def test_hull_of_octahedron_mass_properties():
    verts = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1.0]])
    p = from_vertices(np.vstack([verts, [[0.1, 0.1, 0.1]]]))  # interior point dropped
    assert p.n_faces == 8 and len(p.vertices) == 6
    assert p.volume == pytest.approx(4.0 / 3.0)
    com, inertia = p.mass_properties(2.0)
    assert np.allclose(com, 0) and np.allclose(inertia, np.eye(3) * 2.0 * 2 / 10)


def test_polyhedron_errors():
    b = box([1, 1, 1])
    with pytest.raises(InputError, match="unknown face"):
        b.face_index("+w")
    with pytest.raises(InputError, match="out of range"):
        b.face_index(6)
    with pytest.raises(InputError, match="coplanar"):
        from_vertices([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
