"""ArmSet.evaluate's reshape fast path (identical arms) equals its gather path and each Arm."""

import numpy as np
import pinocchio as pin

from multiarm_pin.model.arm import Arm
from multiarm_pin.model.arm_set import _EPS, ArmSet


def _ur5s(n):
    return [Arm.from_robot_name("ur5", name=f"u{i}", load_visuals=False,
                                base_placement=pin.SE3(pin.rpy.rpyToMatrix(0.1 * i, 0.2, 1.0 * i),
                                                       np.array([i, 0.3 * i, 0.1])))
            for i in range(n)]


def test_levi_civita_is_the_cross_product(rng):
    a, b = rng.normal(size=(2, 5, 3))
    assert np.allclose(np.einsum("abc,nb,nc->na", _EPS, a, b), np.cross(a, b), atol=1e-15)


def test_fast_path_matches_gather_path_and_single_arms(rng):
    arms = _ur5s(3)
    s = ArmSet(arms)
    assert s._uniform  # identical 6-joint arms take the reshape path
    q = s.stack_q([rng.uniform(-2, 2, 6) for _ in arms])
    v = rng.normal(size=s.nv)
    fast = s.evaluate(q, v)
    s._uniform = False
    slow = s.evaluate(q, v)
    for name in ("M", "nle", "J", "Jdot_qdot", "v"):
        assert np.allclose(getattr(fast, name), getattr(slow, name), atol=1e-12), name
    for name in ("position", "rotation", "twist"):
        assert np.allclose(getattr(fast.tools, name), getattr(slow.tools, name), atol=1e-12)
    for i, arm in enumerate(arms):
        t = arm.terms(q[6 * i:6 * i + 6], v[6 * i:6 * i + 6])
        assert np.allclose(fast.M[i], t.M, atol=1e-12)
        assert np.allclose(fast.nle[i], t.nle, atol=1e-10)
        assert np.allclose(fast.J[i], t.J, atol=1e-12)
        assert np.allclose(fast.Jdot_qdot[i], t.Jdot_qdot, atol=1e-10)
        assert np.allclose(fast.tools.twist[i], t.tool_twist, atol=1e-12)


def test_results_do_not_alias_pinocchio_buffers(rng):
    s = ArmSet(_ur5s(2))
    q1, q2 = rng.uniform(-2, 2, (2, s.nq))
    v1, v2 = rng.normal(size=(2, s.nv))
    first = s.evaluate(q1, v1)
    kept = {k: getattr(first, k).copy() for k in ("M", "nle", "J", "Jdot_qdot", "v")}
    s.evaluate(q2, v2)  # overwrites Pinocchio's data
    v1[:] = 0.0  # and the caller's input
    for k, val in kept.items():
        assert np.array_equal(getattr(first, k), val), k


def test_classical_tool_acceleration_by_finite_differences(rng):
    """J̇q̇ is the tool's classical acceleration at q̈ = 0: d/dt (J v) along q̇ = v, v constant."""
    s = ArmSet(_ur5s(2))
    q = rng.uniform(-2, 2, s.nq)
    v = rng.normal(size=s.nv)
    h = 1e-6
    tp = s.evaluate(pin.integrate(s.model, q, v * h), v).tools.twist
    tm = s.evaluate(pin.integrate(s.model, q, -v * h), v).tools.twist
    fd = (tp - tm) / (2 * h)
    assert np.allclose(s.evaluate(q, v).Jdot_qdot, fd, atol=1e-5)
