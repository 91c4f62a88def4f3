import numpy as np
import pinocchio as pin
import pytest

from multiarm_pin.exceptions import InputError
from multiarm_pin.spatial import (
    as_array,
    as_se3,
    as_unit_quaternion,
    cross,
    integrate_quaternion,
    quaternion_derivative,
    quaternion_to_rotation,
    rotation_to_quaternion,
    rpy_to_rotation,
    se3_from,
    se3_to_pose,
    skew,
    wrench_transform,
)


def test_quaternion_conventions_match_pinocchio(rng):
    for _ in range(20):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        R = pin.Quaternion(q).toRotationMatrix()  # pin takes coeffs [x, y, z, w]
        assert np.allclose(quaternion_to_rotation(q), R)
        q2 = rotation_to_quaternion(R)
        assert np.allclose(q2, q) or np.allclose(q2, -q)


def test_quaternion_derivative_matches_integration(rng):
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w = rng.normal(size=3)
    dt = 1e-6
    fd = (integrate_quaternion(q, w, dt) - integrate_quaternion(q, w, -dt)) / (2 * dt)
    qd = quaternion_derivative(q, w)
    if np.dot(integrate_quaternion(q, w, dt), q) < 0:
        fd = -fd
    assert np.allclose(fd, qd, atol=1e-6) or np.allclose(-fd, qd, atol=1e-6)


def test_cross_skew_rpy_and_wrench_transform(rng):
    a, b = rng.normal(size=(5, 3)), rng.normal(size=(5, 3))
    assert np.allclose(cross(a, b), np.cross(a, b))
    assert np.allclose(skew(a[0]) @ b[0], np.cross(a[0], b[0]))
    r, p, y = 0.1, -0.4, 1.2
    Rx = pin.utils.rotate("x", r)
    Ry = pin.utils.rotate("y", p)
    Rz = pin.utils.rotate("z", y)
    assert np.allclose(rpy_to_rotation([r, p, y]), Rz @ Ry @ Rx)
    R = rpy_to_rotation([r, p, y])
    x = rng.normal(size=3)
    f = pin.Force(rng.normal(size=6))
    M = pin.SE3(R, x)
    assert np.allclose(wrench_transform(R, x) @ f.vector, M.act(f).vector)


def test_validation_messages():
    with pytest.raises(InputError, match=r"position: expected shape \(3,\), got shape \(2,\)"):
        as_array([1, 2], (3,), "position")
    with pytest.raises(InputError, match="expected numbers"):
        as_array(["a", "b"], (2,), "x")
    with pytest.raises(InputError, match="norm 2"):
        as_unit_quaternion([0, 0, 0, 2])
    with pytest.raises(InputError, match="only one of"):
        se3_from([0, 0, 0], rpy=[0, 0, 0], quaternion=[0, 0, 0, 1])
    with pytest.raises(InputError, match="rotation matrix"):
        se3_from([0, 0, 0], rotation=np.ones((3, 3)))


def test_se3_placements_round_trip_and_validation(rng):
    for _ in range(10):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        p = rng.normal(size=3)
        M = pin.XYZQUATToSE3(np.concatenate([p, q]))
        position, quaternion = se3_to_pose(as_se3(M))
        np.testing.assert_allclose(position, p, atol=1e-15)
        assert quaternion[3] >= 0  # the sign convention of rotation_to_quaternion
        np.testing.assert_allclose(quaternion, q if q[3] >= 0 else -q, atol=1e-12)
    M = pin.SE3.Random()
    copy = as_se3(M)
    copy.translation = np.zeros(3)
    assert not np.allclose(M.translation, 0)  # a copy, not the caller's placement
    with pytest.raises(InputError, match=r"base: expected a pinocchio.SE3, got tuple; build "
                                         r"one with pin.SE3\(rotation"):
        as_se3((np.zeros(3), np.array([0, 0, 0, 1.0])), "base")
    with pytest.raises(InputError, match="finite"):
        as_se3(pin.SE3(np.eye(3), np.array([0.0, np.nan, 0.0])), "base")
    with pytest.raises(InputError, match="not a rotation matrix"):
        as_se3(pin.SE3(-np.eye(3), np.zeros(3)), "base")  # det -1: a reflection


def test_small_vector_fast_paths_equal_the_array_paths_bit_for_bit(rng):
    """cross of two (3,) float64 vectors and quaternion_to_rotation of a float64 array
    (Python-float fast paths) equal the broadcast / NumPy-scalar paths exactly."""
    for _ in range(50):
        a, b = rng.normal(size=3), rng.normal(size=3)
        assert np.array_equal(cross(a, b), cross(a[None], b[None])[0])
        assert np.allclose(cross(a, b), np.cross(a, b), rtol=0, atol=1e-15)
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        assert np.array_equal(quaternion_to_rotation(q), quaternion_to_rotation(list(q)))
    assert cross(np.arange(3), np.arange(1, 4)).dtype == np.cross(np.arange(3),
                                                                   np.arange(1, 4)).dtype
