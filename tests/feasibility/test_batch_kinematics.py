"""Joint placements at many configurations at once (feasibility/batch_kinematics.py)."""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import pytest

from multiarm_pin.app.scenario import build_scenario, load_scenario
from multiarm_pin.exceptions import UnsupportedJointError
from multiarm_pin.feasibility import CollisionScene
from multiarm_pin.feasibility.batch_kinematics import joint_placements, placement_plan
from tests.feasibility.collision_cases import REPO


@pytest.mark.parametrize("compiled", [True, False])
@pytest.mark.parametrize("name", ["two_ur5_box", "fingertips_form_closure", "revolute_handle"])
def test_joint_placements_equal_pinocchios_forward_kinematics(name, compiled):
    # a scene's model: arms (revolute joints of several axes) and the object's free flyer
    built = build_scenario(load_scenario(REPO / "scenarios" / f"{name}.yaml"),
                           load_visuals=False)
    model = CollisionScene(built.system, built.initial_state).model
    np.random.seed(3)  # pin.randomConfiguration draws from numpy's global generator
    qs = np.array([pin.randomConfiguration(model, -np.full(model.nq, 3.0),
                                           np.full(model.nq, 3.0)) for _ in range(20)])
    plan = placement_plan(model)
    assert plan.tables is not None  # revolute arms and the object's last free flyer
    R, p = joint_placements(model, qs, plan, compiled)
    data = model.createData()
    assert R.shape == (20, model.njoints, 3, 3) and p.shape == (20, model.njoints, 3)
    for t, q in enumerate(qs):
        pin.forwardKinematics(model, data, q)
        for j in range(model.njoints):
            np.testing.assert_allclose(R[t, j], data.oMi[j].rotation, rtol=0, atol=1e-13)
            np.testing.assert_allclose(p[t, j], data.oMi[j].translation, rtol=0, atol=1e-13)


def _random_model(joints) -> pin.Model:
    """A chain of the given joint models at random placements (seeded)."""
    np.random.seed(5)
    model = pin.Model()
    for j, joint in enumerate(joints):
        model.addJoint(j, joint, pin.SE3.Random(), f"j{j}")
    return model


KERNEL_JOINTS = [pin.JointModelRX(), pin.JointModelRY(), pin.JointModelRZ(),
                 pin.JointModelRevoluteUnaligned(np.array([0.6, 0.0, 0.8])),
                 pin.JointModelPX(), pin.JointModelPrismaticUnaligned(np.array([0.0, 0.8, 0.6])),
                 pin.JointModelRUBZ(), pin.JointModelRUBX()]


@pytest.mark.parametrize("last_free_flyer", [False, True])
def test_the_kernel_places_every_joint_kind_it_takes_as_pinocchio(last_free_flyer):
    # revolute, prismatic and continuous joints about x, y, z and unaligned axes, and a
    # last free flyer on the universe (a scene's object): the kernel against Pinocchio's
    # forwardKinematics and, for a geometry on each joint, updateGeometryPlacements
    model = _random_model(KERNEL_JOINTS)
    if last_free_flyer:
        model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "object")
    geom = pin.GeometryModel()
    for j in range(1, model.njoints):
        geom.addGeometryObject(pin.GeometryObject(f"g{j}", j, 0, pin.SE3.Random(),
                                                  coal.Sphere(0.1)))
    plan = placement_plan(model)
    assert plan.tables is not None
    qs = np.array([pin.randomConfiguration(model, -np.full(model.nq, 2.0),
                                           np.full(model.nq, 2.0)) for _ in range(8)])
    R, p = joint_placements(model, qs, plan)
    data, gdata = model.createData(), pin.GeometryData(geom)
    for t, q in enumerate(qs):
        pin.forwardKinematics(model, data, q)
        pin.updateGeometryPlacements(model, data, geom, gdata)
        for j in range(model.njoints):
            np.testing.assert_allclose(R[t, j], data.oMi[j].rotation, rtol=0, atol=1e-12)
            np.testing.assert_allclose(p[t, j], data.oMi[j].translation, rtol=0, atol=1e-12)
        for g, o in enumerate(geom.geometryObjects):
            M = o.placement
            np.testing.assert_allclose(R[t, o.parentJoint] @ M.rotation,
                                       gdata.oMg[g].rotation, rtol=0, atol=1e-12)
            np.testing.assert_allclose(p[t, o.parentJoint] + R[t, o.parentJoint]
                                       @ M.translation, gdata.oMg[g].translation, rtol=0,
                                       atol=1e-12)


@pytest.mark.parametrize("case", ["free_flyer_first", "free_flyer_placed", "spherical"])
def test_models_the_kernel_does_not_take_keep_the_numpy_path(case):
    # decided by joint type and place: a free flyer not last or not at the identity, or
    # a joint kind outside the compiled tables' (spherical: outside the numpy path too)
    if case == "free_flyer_first":
        model = _random_model([pin.JointModelFreeFlyer(), pin.JointModelRZ()])
    elif case == "free_flyer_placed":
        model = _random_model([pin.JointModelRZ(), pin.JointModelFreeFlyer()])
    else:
        model = _random_model([pin.JointModelRZ(), pin.JointModelSpherical()])
        with pytest.raises(UnsupportedJointError):
            placement_plan(model)
        return
    plan = placement_plan(model)
    assert plan.tables is None
    qs = np.array([pin.randomConfiguration(model, -np.full(model.nq, 2.0),
                                           np.full(model.nq, 2.0)) for _ in range(4)])
    R, p = joint_placements(model, qs, plan)
    data = model.createData()
    for t, q in enumerate(qs):
        pin.forwardKinematics(model, data, q)
        for j in range(model.njoints):
            np.testing.assert_allclose(R[t, j], data.oMi[j].rotation, rtol=0, atol=1e-12)
            np.testing.assert_allclose(p[t, j], data.oMi[j].translation, rtol=0, atol=1e-12)
