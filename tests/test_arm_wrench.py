"""``SimulationResult.arm_wrench``: each arm's wrench on the object, against ``W_o μ``.

The reference is computed in the test from the blocks at the recorded states: ``W_o,i μ_i``
(the wrench the object's Newton-Euler equations receive from arm ``i``), with the recorded
multipliers; and the sum over the arms balances the object's equations of motion,
``M_o a_o = h_o + Σ_i W_o,i μ_i`` (a physical law, with the recorded acceleration).
"""

from __future__ import annotations

import numpy as np
import pytest
from closed_loop_cases import SCENARIOS, run_scenario

from multiarm_pin.app.scenario import build_scenario, load_scenario


@pytest.mark.parametrize("name", ["two_ur5_box", "two_gripper_form_closure"])
def test_arm_wrench_is_w_o_mu_and_balances_the_object(name, monkeypatch):
    result, _ = run_scenario(name, 0.06, True, monkeypatch)
    built = build_scenario(load_scenario(SCENARIOS / f"{name}.yaml"), load_visuals=False)
    system = built.system
    n = system.n_arms
    wrench = result.arm_wrench(n)
    assert wrench.shape == (len(result.t), n, 6)
    assert np.abs(wrench).max() > 1.0  # the arms carry the object
    for k in range(0, len(result.t), 10):
        b = system.blocks(result.state(k)).blocks
        for i in range(n):
            m = int(b.N[i])
            ref = b.W_o[i, :, :m] @ result.mu[k, i, :m]
            assert np.abs(wrench[k, i] - ref).max() < 1e-9 * max(1.0, np.abs(ref).max())
        if not system.supports.n_rows:  # Newton-Euler with the recorded acceleration
            lhs = b.M_o @ result.object_acceleration[k]
            rhs = b.h_o + wrench[k].sum(axis=0)
            assert np.abs(lhs - rhs).max() < 1e-8 * max(1.0, np.abs(rhs).max())
