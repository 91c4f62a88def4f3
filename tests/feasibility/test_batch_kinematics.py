"""Joint placements at many configurations at once (feasibility/batch_kinematics.py)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from multiarm_pin.app.scenario import build_scenario, load_scenario
from multiarm_pin.feasibility import CollisionScene
from multiarm_pin.feasibility.batch_kinematics import joint_placements
from tests.feasibility.collision_cases import REPO


@pytest.mark.parametrize("name", ["two_ur5_box", "fingertips_form_closure", "revolute_handle"])
def test_joint_placements_equal_pinocchios_forward_kinematics(name):
    # a scene's model: arms (revolute joints of several axes) and the object's free flyer
    built = build_scenario(load_scenario(REPO / "scenarios" / f"{name}.yaml"),
                           load_visuals=False)
    model = CollisionScene(built.system, built.initial_state).model
    np.random.seed(3)  # pin.randomConfiguration draws from numpy's global generator
    qs = np.array([pin.randomConfiguration(model, -np.full(model.nq, 3.0),
                                           np.full(model.nq, 3.0)) for _ in range(20)])
    R, p = joint_placements(model, qs)
    data = model.createData()
    assert R.shape == (20, model.njoints, 3, 3) and p.shape == (20, model.njoints, 3)
    for t, q in enumerate(qs):
        pin.forwardKinematics(model, data, q)
        for j in range(model.njoints):
            np.testing.assert_allclose(R[t, j], data.oMi[j].rotation, rtol=0, atol=1e-13)
            np.testing.assert_allclose(p[t, j], data.oMi[j].translation, rtol=0, atol=1e-13)
