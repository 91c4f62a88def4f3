"""The compiled loop's evaluation (``_compiled.contact_loop.contact_stage``, called by
``ContactLoop.evaluate``) against the Python path on random systems of 1-6 arms, and a few
steps of two runs (also run without JIT, bounds-checked; the long runs are in
``test_compiled_loop_runs.py`` and ``test_contact_loop.py``)."""

from __future__ import annotations

import numpy as np
import pytest
from closed_loop_cases import (
    EPS,
    RUN_FIELDS,
    TOL,
    TOL_RANK_DEFICIENT_HOLD,
    hold_task_conditions,
    object_pd,
    random_case,
    rel_err,
    run_scenario,
    run_tolerance,
)

from multiarm_pin._compiled import contact_loop as kernels
from multiarm_pin.exceptions import MultiArmError
from multiarm_pin.sim.closed_loop import closed_loop_evaluation
from multiarm_pin.sim.contact_loop import ContactLoop
from multiarm_pin.sim.controllers.object_pd import ObjectPDPlan
from multiarm_pin.sim.stepper import Stepper

CASES = [(seed, 1 + seed % 6) for seed in range(12)]
BAUMGARTE = (5.0, 5.0)


def fused_case(seed, n_arms):
    """A random case whose fused Python evaluation succeeds, with its controller fixed at rest.

    Returns ``(system, off_state, controller, stepper, python (sol, ev, tau), warm start,
    numpy reference (sol, ev, tau), planned by the compiled controller)`` or None when the
    Python path raises at that state (those cases are the other tests' business).
    """
    system, state, off, trajectory = random_case(seed, n_arms)
    ctrl = object_pd(system, trajectory)
    ref = object_pd(system, trajectory, compiled=False)
    stepper = Stepper(system, ctrl, "object_first", BAUMGARTE)
    try:
        closed_loop_evaluation(system, ctrl, 0.0, state, "object_first", stepper.baumgarte)
        inputs = ctrl.kernel_inputs()
        warm = None if inputs is None else inputs[7].copy()
        out = closed_loop_evaluation(system, ctrl, 0.4, off, "object_first", stepper.baumgarte)
        ref(0.0, state, system.blocks(state, reference=True))
        out_ref = closed_loop_evaluation(system, ref, 0.4, off, "object_first_numpy",
                                         stepper.baumgarte, reference=True)
    except MultiArmError:  # singular here, or no inverse dynamics: other tests' business
        return None
    if warm is None:
        return None  # no compiled inputs: nothing compiled to compare
    return system, off, ctrl, stepper, out, warm, out_ref, isinstance(ctrl.last, ObjectPDPlan)


def hands_back(seed, n_arms) -> bool:
    """True if the compiled loop's evaluation at the off state hands back (not STAGE_OK)."""
    system, state, off, trajectory = random_case(seed, n_arms)
    ctrl = object_pd(system, trajectory)
    stepper = Stepper(system, ctrl, "object_first", BAUMGARTE)
    loop = ContactLoop(stepper)
    assert loop.ready(state)
    return loop.evaluate(0.4, off)[0] != kernels.STAGE_OK


@pytest.mark.parametrize("seed,n_arms", CASES)
def test_one_evaluation_equals_the_python_path(seed, n_arms):
    """The loop's stage (the compiled rigid-body pass, blocks, ``object_pd`` and solve) gives
    the torques and tangent of the Python fused evaluation (Pinocchio's arm terms) and of the
    numpy reference (``ObjectPD.reference``, reference blocks, ``with_torques``, the numpy
    solver)."""
    case = fused_case(seed, n_arms)
    if case is None:  # the Python path raises or its compiled controller refused: so does
        assert hands_back(seed, n_arms)  # the loop's kernel, handing the step back
        return
    system, off, ctrl, stepper, (sol, ev, tau), warm, (sol_n, _, tau_n), planned = case
    d_ref = stepper.derivative(off, sol)
    d_numpy = stepper.derivative(off, sol_n)
    cond = hold_task_conditions(ctrl, ev)  # the hold task's round-off grows as cond(A_i)²
    tol = max(TOL, 10 * EPS * cond.max() ** 2) if np.all(cond < 1e6) else \
        TOL_RANK_DEFICIENT_HOLD
    ctrl.kernel_inputs()[7][:] = warm  # the force QP's warm start of the Python call
    status, d, tau_k = ContactLoop(stepper).evaluate(0.4, off)
    if not planned and status != kernels.STAGE_OK:
        return  # a doubtful case of the compiled controller: the reference's, handed back
    # (or decided as the reference decides it: object_pd's least-norm forces without margin)
    assert status == kernels.STAGE_OK
    assert rel_err(tau_k, tau) <= tol
    if (sol.mu[system.unilateral[:, :system.N_max]] < 0.0).any():
        # a unilateral row would pull: the loop's stage solves the mixed LCP on the active
        # set, as the stepper's evaluation does (the fused evaluation holds every row)
        ctrl.kernel_inputs()[7][:] = warm
        sol_s, _, tau_s, _ = stepper.evaluate(0.4, off)
        assert rel_err(tau_s, tau) <= tol
        d_ref = d_numpy = stepper.derivative(off, sol_s)
    assert rel_err(d, d_ref) <= tol
    assert rel_err(tau_k, tau_n) <= tol
    assert rel_err(d, d_numpy) <= tol


def test_cases_are_mostly_compared():
    assert sum(fused_case(seed, n) is not None for seed, n in CASES) >= len(CASES) // 2


@pytest.mark.parametrize("name", ["two_ur5_box", "fingertips_form_closure"])
def test_a_few_steps_equal_the_python_loop(name, monkeypatch):
    fast, calls = run_scenario(name, 0.006, True, monkeypatch)
    ref, _ = run_scenario(name, 0.006, False, monkeypatch)
    assert calls == [(k, k + 1) for k in range(4)]  # every sample by the kernel (stretches
    # of n_steps // 100 steps, at least 1, for the progress reports)
    for field in RUN_FIELDS:
        assert rel_err(getattr(fast, field), getattr(ref, field)) <= run_tolerance(field), field
    assert list(fast.solver) == list(ref.solver)



def test_evaluate_keeps_its_arguments_and_follows_a_changed_gain():
    """The controller hands the loop the same inputs while they hold (so ``evaluate`` does not
    rebuild its kernel arguments every call), and a changed null-space gain reaches the
    kernel: the torques change, and equal the Python path's with the new gain."""
    case = next(c for c in (fused_case(seed, n) for seed, n in CASES) if c is not None and c[-1])
    system, off, ctrl, stepper, _, warm, _, _ = case
    assert ctrl.kernel_inputs() is ctrl.kernel_inputs()
    loop = ContactLoop(stepper)
    ctrl.kernel_inputs()[7][:] = warm
    status, _, tau_before = loop.evaluate(0.4, off)
    kept = loop._evaluator
    ctrl.kernel_inputs()[7][:] = warm
    loop.evaluate(0.4, off)
    assert loop._evaluator is kept
    ctrl.null_kp *= 3.0
    ctrl.kernel_inputs()[7][:] = warm
    status_k, _, tau_k = loop.evaluate(0.4, off)
    ctrl.kernel_inputs()[7][:] = warm
    _, _, tau_py = closed_loop_evaluation(system, ctrl, 0.4, off, "object_first",
                                          stepper.baumgarte)
    assert status == status_k == kernels.STAGE_OK
    assert rel_err(tau_k, tau_before) > 1e-6
    assert rel_err(tau_k, tau_py) <= TOL_RANK_DEFICIENT_HOLD
