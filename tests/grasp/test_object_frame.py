import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from multiarm_pin.exceptions import GraspError, SingularityError
from multiarm_pin.grasp.design import parallel_planes_object, two_corner_box_grasp
from multiarm_pin.grasp.object_frame import (
    object_frame_from_box_contacts,
    object_frame_lstsq,
    objfrm,
)
from multiarm_pin.model.polyhedron import box

from .conftest import random_face_point

FACES = ["+x", "-x", "+y", "-y", "+z", "-z"]


def _random_box_contacts(rng):
    size = rng.uniform(0.3, 3.0, 3)
    P = box(size)
    faces = list(rng.permutation(FACES)) + [str(rng.choice(FACES))]
    pts = np.array([random_face_point(P, f, rng, inset=0.1) for f in faces])
    return size, P, faces, pts


def test_objfrm_recovers_random_poses_of_random_boxes(rng):
    for _ in range(40):
        size, _, faces, pts = _random_box_contacts(rng)
        R = Rotation.random(random_state=rng).as_matrix()
        t = rng.normal(size=3)
        pose = object_frame_from_box_contacts(pts @ R.T + t, faces, size)
        np.testing.assert_allclose(pose.rotation, R, atol=1e-9)
        np.testing.assert_allclose(pose.position, t, atol=1e-9)
        assert pose.rms < 1e-9


def test_objfrm_thesis_signature_on_a_box():
    # thesis roles: p1, p7 on +x (n1), p2 on +y, p3 on +z, p4 -x, p5 -y, p6 -z; R2 = R3 = I
    R = Rotation.from_rotvec([0.3, -0.2, 0.5]).as_matrix()
    t = np.array([0.4, -1.0, 2.0])
    local = np.array([[1, .2, .1], [.3, .75, -.2], [-.4, .1, .5], [-1, -.3, .2],
                      [.1, -.75, .3], [.2, -.1, -.5], [1, -.4, -.3]])  # fmt: skip
    n, po = objfrm((local @ R.T + t).T, np.eye(3), np.eye(3), 2.0, 1.5, 1.0)
    np.testing.assert_allclose(n, R, atol=1e-12)
    np.testing.assert_allclose(po, t, atol=1e-12)
    with pytest.raises(SingularityError):
        same = np.tile(local[0], (7, 1))
        objfrm(same.T, np.eye(3), np.eye(3), 2.0, 1.5, 1.0)


def test_least_squares_degrades_gracefully_with_noise(rng):
    g = two_corner_box_grasp([2.0, 1.5, 1.0], 0.2, 0.1, 0.5)
    faces = [c.label for c in g.contacts]
    R = Rotation.random(random_state=rng).as_matrix()
    t = rng.normal(size=3)
    world = g.points @ R.T + t
    exact = object_frame_lstsq(world, faces, g.polyhedron)
    np.testing.assert_allclose(exact.rotation, R, atol=1e-9)
    np.testing.assert_allclose(exact.position, t, atol=1e-9)
    for sigma in (1e-5, 1e-4, 1e-3):
        errs = []
        for _ in range(5):
            noisy = world + sigma * rng.normal(size=world.shape)
            pose = object_frame_lstsq(
                noisy, faces, g.polyhedron, initial=(exact.rotation, exact.position)
            )
            err = max(np.abs(pose.position - t).max(), np.abs(pose.rotation - R).max())
            errs.append(err)
            assert pose.rms <= 3 * sigma
        # error of the order of the noise (well-conditioned grasp: amplification below 50)
        assert np.median(errs) < 50 * sigma
        assert np.median(errs) > 0.05 * sigma


def test_least_squares_on_a_general_polyhedron_and_many_contacts(rng):
    P = parallel_planes_object(np.radians(-20), np.radians(-15), np.radians(-10), [1.2, 1.0, 0.8])
    faces = list(P.face_names) * 2
    pts = np.array([random_face_point(P, f, rng, inset=0.2) for f in faces])
    R = Rotation.random(random_state=rng).as_matrix()
    t = rng.normal(size=3)
    pose = object_frame_lstsq(pts @ R.T + t, faces, P)
    np.testing.assert_allclose(pose.rotation, R, atol=1e-8)
    np.testing.assert_allclose(pose.position, t, atol=1e-8)
    assert pose.residuals.shape == (12,)


def test_object_frame_input_errors(rng):
    size, P, faces, pts = _random_box_contacts(rng)
    with pytest.raises(GraspError, match="every face needs a contact"):
        object_frame_from_box_contacts(pts, ["+x"] * 7, size)
    with pytest.raises(GraspError, match="seven face names"):
        object_frame_from_box_contacts(pts, faces[:6] + ["+w"], size)
    with pytest.raises(GraspError, match="N >= 6"):
        object_frame_lstsq(pts[:5], faces[:5], P)
    with pytest.raises(GraspError, match="unknown face"):
        object_frame_lstsq(pts, faces[:6] + ["+w"], P)
