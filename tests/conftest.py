"""Shared fixtures: arms are loaded once per session (URDF parsing is the slow part)."""

import numpy as np
import pinocchio as pin
import pytest

from multiarm_pin.model.arm import Arm


@pytest.fixture(scope="session")
def ur5() -> Arm:
    base = pin.SE3(pin.rpy.rpyToMatrix(0.1, -0.2, 0.7), np.array([0.3, -0.4, 0.2]))
    return Arm.from_robot_name("ur5", name="ur5", base_placement=base)


@pytest.fixture(scope="session")
def panda() -> Arm:
    return Arm.from_robot_name("panda", name="panda")


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)

