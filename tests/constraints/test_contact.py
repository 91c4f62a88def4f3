"""Contact primitive: gap rates and accelerations against finite differences of the gap."""

import numpy as np
import pytest

from multiarm_pin.constraints import Contact, Cylinder, Plane, Sphere
from multiarm_pin.exceptions import ConstraintError

from .trajectories import RigidTrajectory


def _surfaces(rng):
    return [
        Plane(rng.normal(size=3) * 0.1, rng.normal(size=3)),
        Sphere(rng.normal(size=3) * 0.05, 0.2),
        Sphere(rng.normal(size=3) * 0.05, 0.3, inside=True),
        Cylinder(center=rng.normal(size=3) * 0.05, radius=0.15, axis=rng.normal(size=3)),
        Cylinder(center=rng.normal(size=3) * 0.05, radius=0.4, axis=rng.normal(size=3),
                 inside=True),
    ]


def _cases(seed=1):
    rng = np.random.default_rng(seed)
    for surface in _surfaces(rng):
        for point_on in ("tool", "object"):
            tip = rng.normal(size=3) * 0.2
            contact = Contact(tip, surface, radius=rng.uniform(0, 0.02), point_on=point_on)
            tool = RigidTrajectory(rng, rng.normal(size=3) * 0.1)
            obj = RigidTrajectory(rng, rng.normal(size=3) * 0.1)
            yield contact, tool, obj, rng.uniform(-0.2, 0.2)


def _case_id(case):
    return f"{case[0].surface.kind}-{case[0].point_on}"


def _phi(contact, tool, obj, t):
    return contact.evaluate(tool.kinematics(t), obj.kinematics(t)).phi


@pytest.mark.parametrize("case", list(_cases()), ids=_case_id)
def test_phi_dot_and_phi_ddot_match_finite_differences(case):
    contact, tool, obj, t = case
    s = contact.evaluate(tool.kinematics(t), obj.kinematics(t))
    a_tool, a_obj = tool.state(t)[3], obj.state(t)[3]
    h = 1e-5
    fd1 = (_phi(contact, tool, obj, t + h) - _phi(contact, tool, obj, t - h)) / (2 * h)
    assert abs(fd1 - s.phi_dot) < 1e-7 * max(1.0, abs(s.phi_dot))
    phi_ddot = s.G_tool @ a_tool + s.G_object @ a_obj + s.kappa
    errors = []
    for h in (4e-3, 2e-3, 1e-3):
        fd2 = (_phi(contact, tool, obj, t + h) - 2 * s.phi + _phi(contact, tool, obj, t - h)) / h**2
        errors.append(abs(fd2 - phi_ddot))
    assert errors[-1] < 1e-4 * max(1.0, abs(phi_ddot))
    # discretisation error O(h^2): halving h divides it by about 4
    assert errors[2] < 0.35 * errors[1] + 1e-9 and errors[1] < 0.35 * errors[0] + 1e-9
    # kappa matters: dropping it breaks the identity (the test can fail)
    assert abs(s.kappa) > 10 * errors[-1]


@pytest.mark.parametrize("case", list(_cases(2)), ids=_case_id)
def test_normal_rate_and_tip_velocity_match_finite_differences(case):
    contact, tool, obj, t = case
    h = 1e-6
    sp = contact.evaluate(tool.kinematics(t + h), obj.kinematics(t + h))
    sm = contact.evaluate(tool.kinematics(t - h), obj.kinematics(t - h))
    s = contact.evaluate(tool.kinematics(t), obj.kinematics(t))
    assert np.allclose((sp.normal - sm.normal) / (2 * h), s.normal_rate, atol=1e-6)
    assert np.allclose((sp.tip_center - sm.tip_center) / (2 * h), s.tip_velocity, atol=1e-7)


def test_common_rigid_motion_leaves_gap_unchanged():
    """φ̇ = 0 when both bodies move as one rigid body (twists transported to each origin)."""
    rng = np.random.default_rng(3)
    for contact, tool, obj, t in _cases(3):
        kt, ko = tool.kinematics(t), obj.kinematics(t)
        v_o = rng.normal(size=6)
        v_t = v_o.copy()
        v_t[:3] += np.cross(v_o[3:], kt.position[0] - ko.position[0])
        kt = type(kt)(kt.position, kt.rotation, v_t[None])
        ko = type(ko)(ko.position, ko.rotation, v_o[None])
        s = contact.evaluate(kt, ko)
        assert abs(s.phi_dot) < 1e-12
        assert abs(s.G_tool @ v_t) > 1e-3  # each row alone is not zero


def test_push_direction_and_moment_follow_architecture_convention():
    rng = np.random.default_rng(4)
    plane = Plane([0, 0, 0.1], [0, 0, 1])  # a top face of the object, outward +z
    c = Contact([0, 0, 0], plane, radius=0.02)  # tip centre at the tool origin, radius 2 cm
    tool = RigidTrajectory(rng, [0.3, 0.2, 0.12], np.eye(3)).kinematics(0.0)
    obj = RigidTrajectory(rng, np.zeros(3), np.eye(3)).kinematics(0.0)
    s = c.evaluate(tool, obj)
    assert s.phi == pytest.approx(0.0, abs=1e-12)
    assert np.allclose(s.normal, [0, 0, -1])  # pushes the object inward
    assert np.allclose(s.point, [0.3, 0.2, 0.1])
    moment = np.cross([0.3, 0.2, 0.1], [0, 0, -1])
    assert np.allclose(s.G_object, np.concatenate([[0, 0, -1], moment]))
    # lifting the tool 1 cm opens the gap by 1 cm
    lifted = type(tool)(tool.position + [0, 0, 0.01], tool.rotation, tool.twist)
    assert c.evaluate(lifted, obj).phi == pytest.approx(0.01)


def test_bad_surface_and_contact_definitions_raise():
    with pytest.raises(ConstraintError, match="non-zero direction"):
        Plane([0, 0, 0], [0, 0, 0])
    with pytest.raises(ConstraintError, match="non-zero direction"):
        Cylinder(center=[0, 0, 0], radius=1.0, axis=[0, 0, 0])
    with pytest.raises(ConstraintError, match="positive length"):
        Sphere([0, 0, 0], -1.0)
    with pytest.raises(ConstraintError, match="shape"):
        Plane([0, 0], [0, 0, 1])
    with pytest.raises(ConstraintError, match="point_on"):
        Contact([0, 0, 0], Plane([0, 0, 0], [0, 0, 1]), point_on="arm")
    with pytest.raises(ConstraintError, match="radius"):
        Contact([0, 0, 0], Plane([0, 0, 0], [0, 0, 1]), radius=-0.1)
    with pytest.raises(ConstraintError, match="Plane, Sphere or Cylinder"):
        Contact([0, 0, 0], "plane")
    with pytest.raises(ConstraintError, match="undefined"):
        Sphere([0, 0, 0], 1.0).local(np.zeros(3))
