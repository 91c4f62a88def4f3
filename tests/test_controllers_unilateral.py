"""object_pd with a grasp that cannot keep its margin: it plans least-norm forces instead."""

from __future__ import annotations

import numpy as np
import pytest

from multiarm_pin.arm import Arm
from multiarm_pin.controllers import ObjectPD
from multiarm_pin.dynamics.force_distribution import distribute_forces
from multiarm_pin.exceptions import DynamicsError
from multiarm_pin.rigid_object import RigidObject
from multiarm_pin.simulation import simulate
from multiarm_pin.system import MultiArmSystem


def test_infeasible_margin_falls_back_and_contacts_separate_instead_of_pulling():
    """One arm, two fingertips (under the box, and on its +x face): not form closure.

    Holding the box still needs no horizontal force, but a +x fingertip pushing with the
    1 N margin makes one that nothing balances: ``distribute_forces`` raises. object_pd
    then plans the least-norm forces (``margin_kept`` False) and the simulation goes on
    with unilateral contacts: no multiplier is ever negative (they push or separate).
    """
    arm = Arm.from_robot_name("ur5", name="ur5")
    q0 = np.array([0.0, -1.2, 1.6, -1.9, -1.57, 0.0])
    box = RigidObject.box([0.4, 0.3, 0.2], 1.0)
    tool = arm.tool_placement(q0).translation
    spec = {"type": "fingertips", "radius": 0.01,
            "contacts": [("-z", [0.0, 0.0, -0.1]), ("+x", [0.2, 0.0, 0.0])]}
    system, state = MultiArmSystem.from_initial_state([arm], box, [spec], [q0],
                                                      tool + [0.0, 0.0, 0.3])
    ev = system.blocks(state)
    b = ev.blocks
    with pytest.raises(DynamicsError, match="no internal force keeps"):
        distribute_forces(b, -b.h_o, system.unilateral, 1.0)
    ctrl = ObjectPD(system, margin=1.0)
    r = simulate(system, state, ctrl, 0.02, 0.002, "rk4")
    assert ctrl.margin_kept is False
    assert np.all(r.mu[:, r.unilateral] >= 0.0)
    assert np.all(np.isfinite(r.q))
