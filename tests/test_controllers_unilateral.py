"""object_pd with a grasp that cannot keep its margin: it plans least-norm forces instead."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from system_builders import two_gripper_system

from multiarm_pin.dynamics.force_distribution import distribute_forces
from multiarm_pin.exceptions import DynamicsError
from multiarm_pin.model.arm import Arm
from multiarm_pin.model.rigid_object import RigidObject
from multiarm_pin.sim.controllers import ObjectPD
from multiarm_pin.sim.simulation import simulate
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
    system, state = MultiArmSystem.from_initial_state(
        [arm], box, [spec], [q0], pin.SE3(np.eye(3), tool + [0.0, 0.0, 0.3]))
    ev = system.blocks(state)
    b = ev.blocks
    with pytest.raises(DynamicsError, match="no internal force keeps"):
        distribute_forces(b, -b.h_o, system.unilateral, 1.0)
    ctrl = ObjectPD(system, margin=1.0)
    r = simulate(system, state, ctrl, 0.02, 0.002, "rk4")
    assert ctrl.margin_kept is False
    assert np.all(r.mu[:, r.unilateral] >= 0.0)
    assert np.all(np.isfinite(r.q))


def test_object_pd_plans_forces_on_the_touching_contacts_only():
    """With four_finger:tip[2] separated, its planned force is 0 and the rest realise a_d.

    Reference: the simulator's own mixed LCP (``solve_unilateral``) on the *full* blocks
    with the torques applied and that row inactive (no use of the restricted blocks): the
    object acceleration must be the controller's desired one and the multipliers the
    planned ones (every remaining contact pushes with the 1 N margin, here at least 17 N,
    so the LCP is the bilateral solve on the active rows). The six remaining contacts
    still span every wrench: their unit-column ``W_o`` has 6 singular values above 1e-3 of
    the largest, far above ``GRASP_RANK_TOLERANCE``.
    """
    from multiarm_pin.dynamics.blocks import restrict_rows
    from multiarm_pin.dynamics.unilateral import solve_unilateral
    from multiarm_pin.sim.controllers import grasp_rank

    system, state = two_gripper_system()
    active = system.contact_mask.copy()
    active[0, 2] = False
    ev = system.blocks(state).with_active(active[:system.n_arms, :system.N_max])
    sub, _ = restrict_rows(ev.blocks, ev.active)
    W_o = sub.stacked_W_o()
    sv = np.linalg.svd(W_o / np.linalg.norm(W_o, axis=0), compute_uv=False)
    assert grasp_rank(sub) == 6 and sv[-1] > 1e-3 * sv[0]
    ctrl = ObjectPD(system, margin=1.0)
    tau = ctrl(0.0, state, ev)
    assert not ctrl.holding and ctrl.margin_kept
    assert ctrl.last.mu[0, 2] == 0.0
    assert ctrl.last.mu[ev.active & system.unilateral[:, :system.N_max]].min() >= 1.0 - 1e-9
    full, _ = system.contact_blocks(state, ev.blocks.with_torques(system.pad(tau)),
                                    ev.constraints, None, None)
    sol = solve_unilateral(full, system.contact_unilateral, active)
    np.testing.assert_allclose(sol.a_o, ctrl.desired_acceleration(0.0, state), atol=1e-8)
    np.testing.assert_allclose(sol.mu[:system.n_arms, :system.N_max], ctrl.last.mu,
                               atol=1e-7)


def test_object_pd_holds_the_arms_still_when_the_touching_contacts_lose_the_grasp():
    """Only the three-finger gripper touches: rank 3 < 6, so hold the arms, warn once.

    Three fingertips make forces along three normals only (rank of ``W_o`` 3, decided by
    SVD with a 1e-9 threshold while the three singular values are O(1)). The fallback is a
    computed-torque joint PD toward the onset's configuration; at the onset (``q = q_h``)
    and at rest (``v = 0``) it is pure gravity compensation, ``τ = g(q)``, which Pinocchio's
    RNEA (``pin.rnea(q, 0, 0)`` per arm) gives independently. A second call does not add
    a warning; with every contact touching again the controller plans forces again.
    """
    import pinocchio as pin

    system, state = two_gripper_system()
    active = system.contact_mask[:system.n_arms, :system.N_max].copy()
    active[0] = False
    ev = system.blocks(state).with_active(active)
    ctrl = ObjectPD(system, margin=1.0)
    tau = ctrl(0.0, state, ev)
    assert ctrl.holding and len(ctrl.warnings) == 1
    assert ctrl.warnings[0].startswith("t = 0 s: object_pd:") and "rank 3 < 6" in ctrl.warnings[0]
    assert not np.any(state.v)
    expected, k = [], 0
    for arm in system.arms:
        nv = arm.model.nv
        data = arm.model.createData()
        expected.append(pin.rnea(arm.model, data, state.q[k:k + arm.model.nq], np.zeros(nv),
                                 np.zeros(nv)))
        k += arm.model.nq
    np.testing.assert_allclose(tau, np.concatenate(expected), rtol=1e-10, atol=1e-10)
    ctrl(0.001, state, ev)
    assert len(ctrl.warnings) == 1
    ctrl(0.002, state, system.blocks(state).with_active(
        system.contact_mask[:system.n_arms, :system.N_max]))
    assert not ctrl.holding and ctrl.last.mu[0, :4].min() >= 1.0 - 1e-9
