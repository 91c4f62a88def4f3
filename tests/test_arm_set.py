import numpy as np
import pinocchio as pin

from multiarm_pin.model.arm import Arm
from multiarm_pin.model.arm_set import ArmSet


def test_combined_model_matches_each_arm(ur5, panda, rng):
    other = Arm.from_robot_name(
        "ur5",
        name="right",
        load_visuals=False,
        base_placement=pin.SE3(pin.rpy.rpyToMatrix(0, 0, 2.0), np.array([1.0, 0.5, 0.0])),
    )
    arms = [ur5, panda, other]
    s = ArmSet(arms)
    qs = [rng.uniform(-1.5, 1.5, a.nq) for a in arms]
    vs = [rng.normal(size=a.nv) for a in arms]
    terms = s.evaluate(s.stack_q(qs), s.stack_v(vs))
    assert terms.M.shape == (3, 7, 7)
    for i, arm in enumerate(arms):
        t = arm.terms(qs[i], vs[i])
        nv = arm.nv
        assert np.allclose(terms.M[i, :nv, :nv], t.M, atol=1e-12)
        assert np.allclose(terms.nle[i, :nv], t.nle, atol=1e-10)
        assert np.allclose(terms.J[i, :, :nv], t.J, atol=1e-12)
        assert np.allclose(terms.Jdot_qdot[i], t.Jdot_qdot, atol=1e-10)
        assert np.allclose(terms.tools.twist[i], t.tool_twist, atol=1e-12)
        assert np.allclose(terms.tools.position[i], t.tool_position, atol=1e-12)
        assert np.allclose(terms.tools.rotation[i], t.tool_rotation, atol=1e-12)
        # padding: identity mass, zero everything else
        assert np.allclose(terms.M[i, nv:, nv:], np.eye(7 - nv))
        assert np.all(terms.J[i, :, nv:] == 0) and np.all(terms.nle[i, nv:] == 0)
    g = s.gravity(s.stack_q(qs))
    assert np.allclose(g[0, :6], ur5.terms(qs[0]).gravity)


def test_round_trip_of_stacked_vectors(ur5, panda, rng):
    s = ArmSet([ur5, panda])
    v = rng.normal(size=s.nv)
    assert np.array_equal(s.unpad_v(s.pad_v(v)), v)
