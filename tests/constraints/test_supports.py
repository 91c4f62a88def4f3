"""Supports: rows against finite differences of the gap along a rigid motion; bad input."""

from __future__ import annotations

import numpy as np
import pytest

from multiarm_pin.constraints import Support, SupportSet
from multiarm_pin.exceptions import ConstraintError

from .trajectories import RigidTrajectory


def test_rows_match_finite_differences_of_the_gap(rng):
    """``φ̇ = G·[ẋ; ω]`` and ``φ̈ = G·[ẍ; ω̇] + κ`` against central differences of ``φ(t)``.

    The gap of a plane ``(a, n)`` and an object point ``p`` is ``n·(x + R p - a)`` along a
    smooth rigid trajectory; differences with step 1e-4 s (error ~1e-8 relative, 4th order
    for the rate, 2nd for the acceleration) are compared at 1e-6 relative.
    """
    traj = RigidTrajectory(rng)
    pts = rng.normal(size=(5, 3)) * 0.3
    normal = rng.normal(size=3)
    s = SupportSet([Support("a", rng.normal(size=3), normal, pts[:3], 0.3),
                    Support("b", [0, 0, 0.1], [0, 0, 2.0], pts[3:], 1.0)])
    assert s.labels == ("a[0]", "a[1]", "a[2]", "b[0]", "b[1]")
    np.testing.assert_allclose(s.restitution, [0.3, 0.3, 0.3, 1.0, 1.0])

    def phi(t):
        k = traj.kinematics(t)
        return s.evaluate(k.position[0], k.rotation[0], k.twist[0]).phi

    t, h = 0.37, 1e-4
    k = traj.kinematics(t)
    acc = traj.state(t)[3]
    st = s.evaluate(k.position[0], k.rotation[0], k.twist[0])
    rate = (phi(t - 2 * h) - 8 * phi(t - h) + 8 * phi(t + h) - phi(t + 2 * h)) / (12 * h)
    second = (phi(t - h) - 2 * phi(t) + phi(t + h)) / (h * h)
    np.testing.assert_allclose(st.phi_dot, st.G_object @ k.twist[0], rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(st.phi_dot, rate, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(st.G_object @ acc + st.kappa, second, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(st.normals, axis=1), 1.0)


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"normal": [0, 0, 0]}, "zero length"),
    ({"restitution": 1.5}, r"restitution must be in \[0, 1\]"),
    ({"restitution": -0.1}, r"restitution must be in \[0, 1\]"),
    ({"points": [[0, 0]]}, "3-vectors"),
    ({"points": np.zeros((0, 3))}, "3-vectors"),
])
def test_bad_supports_raise(kwargs, match):
    args = {"name": "t", "point": [0, 0, 0], "normal": [0, 0, 1], "points": [[0, 0, 0]],
            "restitution": 0.0, **kwargs}
    with pytest.raises(ConstraintError, match=match):
        Support(**args)


def test_duplicate_support_names_raise():
    s = Support("t", [0, 0, 0], [0, 0, 1], [[0, 0, 0]])
    with pytest.raises(ConstraintError, match="duplicate"):
        SupportSet([s, s])


def test_rows_equal_the_np_cross_formula(rng):
    """The written-out cross products equal ``np.cross`` bit for bit (the same products).

    Reference: ``G = [n, r × n]``, ``κ = n·(ω × (ω × r))``, ``φ = n·(x + r - a)``,
    ``φ̇ = G·[ẋ; ω]`` with ``np.cross`` on random poses, twists and planes.
    """
    s = SupportSet([Support("a", rng.normal(size=3), rng.normal(size=3), rng.normal(size=(8, 3))),
                    Support("b", rng.normal(size=3), rng.normal(size=3), rng.normal(size=(5, 3)))])
    p = np.concatenate([sp.points for sp in s.supports])
    n = s.supports_array("normal")
    a = s.supports_array("point")
    for _ in range(50):
        rotation = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        x, twist = rng.normal(size=3), 3.0 * rng.normal(size=6)
        r = p @ rotation.T
        G = np.concatenate([n, np.cross(r, n)], axis=1)
        kappa = np.einsum("ki,ki->k", n, np.cross(twist[3:], np.cross(twist[3:], r)))
        st = s.evaluate(x, rotation, twist)
        np.testing.assert_array_equal(st.G_object, G)
        np.testing.assert_array_equal(st.kappa, kappa)
        np.testing.assert_array_equal(st.phi, np.einsum("ki,ki->k", n, x + r - a))
        np.testing.assert_array_equal(st.phi_dot, G @ twist)
        np.testing.assert_array_equal(st.contact_points, x + r)
        np.testing.assert_array_equal(st.normals, n)


def _frame(normal, x_axis):
    """Orthonormal ``(e_x, e_y, n)`` built here by Gram-Schmidt (the test's own reference)."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    x = np.asarray(x_axis, float)
    x = x - (x @ n) * n
    x = x / np.linalg.norm(x)
    return x, np.cross(n, x), n


def test_edge_margins_of_points_placed_by_their_plane_coordinates(rng):
    """Points built as ``a + u e_x + v e_y + w n`` have margin ``min(lx/2 - |u|, ly/2 - |v|)``.

    A tilted plane, a rectangle ``[0.8, 0.3]`` whose x side is a given direction (not in the
    plane: it is projected); the height ``w`` above the plane does not change the margin.
    Points inside have margin > 0, outside < 0; an infinite support's rows are ``+inf``.
    """
    a, normal, x_axis = np.array([0.3, -0.2, 0.5]), np.array([0.2, -0.3, 1.0]), [1, 0.5, 0.4]
    ex, ey, n = _frame(normal, x_axis)
    lx, ly = 0.8, 0.3
    uv = rng.uniform(-0.6, 0.6, size=(40, 2))
    w = rng.uniform(-0.2, 0.2, size=40)
    pts = a + uv[:, :1] * ex + uv[:, 1:] * ey + w[:, None] * n
    sup = Support("t", a, normal, pts, extent=[lx, ly], x_axis=x_axis)
    np.testing.assert_allclose(sup.x_axis, ex, atol=1e-15)
    np.testing.assert_allclose(sup.y_axis, ey, atol=1e-15)
    expected = np.minimum(lx / 2 - np.abs(uv[:, 0]), ly / 2 - np.abs(uv[:, 1]))
    np.testing.assert_allclose(sup.edge_margins(pts), expected, atol=1e-14)
    inside = (np.abs(uv[:, 0]) < lx / 2) & (np.abs(uv[:, 1]) < ly / 2)
    assert inside.any() and (~inside).any()
    s = SupportSet([sup, Support("floor", [0, 0, 0], [0, 0, 1], pts[:3])])
    assert s.finite and s.finite_rows.tolist() == [True] * 40 + [False] * 3
    all_pts = np.concatenate([pts, pts[:3]])
    m = s.edge_margins(all_pts)
    np.testing.assert_allclose(m[:40], sup.edge_margins(pts), atol=1e-15)
    assert np.all(m[40:] == np.inf)
    assert ((m[:40] > 0) == inside).all()
    assert not SupportSet([Support("floor", [0, 0, 0], [0, 0, 1], pts)]).finite


def test_the_rectangle_turns_with_its_x_axis():
    """A table 2 m by 1 m: with ``x_axis = +y`` its long side runs along y."""
    pts = [[0.9, 0.0, 0.0], [0.0, 0.9, 0.0]]
    along_x = Support("t", [0, 0, 0], [0, 0, 1], pts, extent=[2.0, 1.0])
    along_y = Support("t", [0, 0, 0], [0, 0, 1], pts, extent=[2.0, 1.0], x_axis=[0, 3, 0])
    np.testing.assert_allclose(along_x.edge_margins(np.array(pts)), [0.1, -0.4])
    np.testing.assert_allclose(along_y.edge_margins(np.array(pts)), [-0.4, 0.1])


@pytest.mark.parametrize(("normal", "expected"), [
    ([0, 0, 1], [1, 0, 0]),              # a table: world x
    ([0, 0, -1], [1, 0, 0]),             # a ceiling
    ([0.6, 0, 0.8], [0.8, 0, -0.6]),     # a ramp: world x projected onto it
    ([0.8, 0, 0.6], [0, 1, 0]),          # normal within 45 degrees of x: world y
    ([-1, 0, 0], [0, 1, 0]),             # a wall facing -x
])
def test_default_x_axis(normal, expected):
    sup = Support("t", [0, 0, 0], normal, [[0, 0, 0]], extent=[1.0, 1.0])
    np.testing.assert_allclose(sup.x_axis, expected, atol=1e-15)
    assert abs(sup.x_axis @ sup.normal) < 1e-15


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"extent": [-1.0, 1.0]}, "extent must be 2 positive"),
    ({"extent": [0.0, 1.0]}, "extent must be 2 positive"),
    ({"extent": [1.0, 1.0, 1.0]}, "extent must be 2 positive"),
    ({"extent": [np.nan, 1.0]}, "extent must be 2 positive"),
    ({"extent": [1.0, 1.0], "x_axis": [0, 0, 2]}, "parallel to the plane's normal"),
    ({"extent": [1.0, 1.0], "x_axis": [0, 0, 0]}, "parallel to the plane's normal"),
    ({"extent": [1.0, 1.0], "x_axis": [1, 0]}, "x_axis must be 3 finite numbers"),
])
def test_bad_extents_raise(kwargs, match):
    with pytest.raises(ConstraintError, match=match):
        Support("t", [0, 0, 0], [0, 0, 1], [[0, 0, 0]], **kwargs)
