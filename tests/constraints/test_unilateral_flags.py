"""Unilaterality belongs to each contact: library defaults, overrides, the system's mask."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from multiarm_pin.constraints import (
    ConstraintSet,
    Contact,
    Plane,
    corner_gripper,
    custom,
    fingertips_on_faces,
    revolute,
    weld,
)
from multiarm_pin.exceptions import ConstraintError
from multiarm_pin.model.polyhedron import box


def _box():
    return box([0.4, 0.3, 0.2])


def test_defaults_fingertips_and_corner_gripper_push_mechanical_joints_hold():
    J = pin.SE3.Identity()
    assert not weld(J).unilateral.any() and len(weld(J).unilateral) == 6
    assert not revolute(J).unilateral.any()
    assert corner_gripper(J).unilateral.all() and len(corner_gripper(J).unilateral) == 4
    tips = fingertips_on_faces(_box(), [("+x", [0.2, 0.0, 0.0]), ("-z", [0.0, 0.0, -0.1])],
                               0.01, [[0.21, 0.0, 0.0], [0.0, 0.0, -0.11]])
    assert tips.unilateral.tolist() == [True, True]


def test_overrides_per_joint_and_per_contact():
    J = pin.SE3.Identity()
    assert weld(J, unilateral=True).unilateral.all()
    assert not corner_gripper(J, unilateral=False).unilateral.any()
    plane = {"type": "plane", "point": [0, 0, 0], "normal": [0, 0, 1]}
    contacts = [{"point": [0.1, 0.0, 0.0], "surface": plane},
                {"point": [0.0, 0.1, 0.0], "surface": plane, "unilateral": True}]
    assert custom(contacts, J).unilateral.tolist() == [False, True]
    assert custom(contacts, J, unilateral=True).unilateral.tolist() == [True, True]
    with pytest.raises(ConstraintError, match="unilateral must be True or False"):
        Contact([0, 0, 0], Plane([0, 0, 0], [0, 0, 1]), unilateral="yes")


def test_constraint_set_mask_is_per_row_with_padding():
    J = pin.SE3.Identity()
    cs = ConstraintSet([weld(J), corner_gripper(J)])
    expected = np.zeros((2, 6), dtype=bool)
    expected[1, :4] = True
    np.testing.assert_array_equal(cs.unilateral, expected)
    assert not cs.unilateral.flags.writeable
