"""Fused closed-loop evaluation (sim.closed_loop, _compiled.controller_kernels)
against the reference numpy path: controller.reference, then ``blocks.with_torques``, then
the numpy object-first solver, on reference blocks."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from closed_loop_cases import (
    EPS,
    JOINT_KINDS,
    TOL,
    TOL_RANK_DEFICIENT_HOLD,
    hold_task_conditions,
    object_pd,
    random_case,
    rel_err,
)

from multiarm_pin._compiled import controller_kernels
from multiarm_pin.app.runner import make_controller
from multiarm_pin.app.scenario import build_scenario, load_scenario
from multiarm_pin.dynamics import InverseDynamicsResult
from multiarm_pin.exceptions import DynamicsError
from multiarm_pin.sim.closed_loop import closed_loop_evaluation
from multiarm_pin.sim.simulation import simulate
from multiarm_pin.sim.trajectories import MinimumJerkTrajectory
from multiarm_pin.spatial import rotation_to_quaternion

SCENARIOS = Path(__file__).resolve().parent.parent / "scenarios"

CASES = [(seed, 1 + seed % 6) for seed in range(12)]


def hold_task_full_rank(ctrl, ev) -> np.ndarray:
    """(n,) bool: the hold rows have full column rank with margin (condition < 1e6)."""
    return hold_task_conditions(ctrl, ev) < 1e6


def evaluate_both(system, state, off, trajectory, t, baumgarte):
    fused_ctrl = object_pd(system, trajectory)
    ref_ctrl = object_pd(system, trajectory, compiled=False)
    out = []
    for ctrl, reference, solver in ((fused_ctrl, False, "auto"),
                                    (ref_ctrl, True, "object_first_numpy")):
        try:
            ctrl(0.0, state, system.blocks(state))  # fixes q_ref and the held points
            out.append(closed_loop_evaluation(system, ctrl, t, off, solver, baumgarte,
                                              reference=reference) + (ctrl,))
        except DynamicsError as exc:
            out.append(exc)
    return out


@pytest.mark.parametrize("seed,n_arms", CASES)
@pytest.mark.parametrize("baumgarte", [None, (5.0, 5.0)])
def test_fused_closed_loop_equals_reference(seed, n_arms, baumgarte):
    system, state, off, trajectory = random_case(seed, n_arms)
    fused, ref = evaluate_both(system, state, off, trajectory, 0.4, baumgarte)
    if isinstance(ref, Exception):  # e.g. fingertips alone cannot hold the margin
        assert isinstance(fused, DynamicsError) and str(fused) == str(ref)
        return
    sol, ev, tau, ctrl = fused
    sol_r, ev_r, tau_r, ctrl_r = ref
    cond = hold_task_conditions(ctrl, ev)
    full = cond < 1e6
    scale = max(1.0, np.abs(tau_r).max())
    for i in range(system.n_arms):  # torques arm by arm; both paths solve the normal
        # equations of the hold task, whose round-off grows as cond(A_i)²
        tol = max(TOL, 10 * EPS * cond[i] ** 2) if full[i] else TOL_RANK_DEFICIENT_HOLD
        err = np.abs(ctrl.last.tau[i] - ctrl_r.last.tau[i]).max() / scale
        assert err <= tol, (i, system.joints[i].kind, err)
    tol = max(TOL, 10 * EPS * cond.max() ** 2) if full.all() else TOL_RANK_DEFICIENT_HOLD
    assert rel_err(sol.a_o, sol_r.a_o) <= tol
    assert rel_err(sol.qdd, sol_r.qdd) <= tol
    assert rel_err(sol.mu, sol_r.mu) <= tol
    assert rel_err(ctrl.last.mu, ctrl_r.last.mu) <= TOL  # the force QP: no damped task
    assert rel_err(ctrl.last_point_acceleration[ctrl.hold_mask],
                   ctrl_r.last_point_acceleration[ctrl_r.hold_mask]) <= TOL
    # the torques realise the plan: the forward dynamics returns the desired a_o and μ
    assert rel_err(sol.a_o, ctrl.last.a_o) <= 1e-9
    assert rel_err(sol.mu, ctrl.last.mu) <= 1e-9
    assert sol.solver == "object_first"  # the fused kernel solved it


def test_cases_cover_every_joint_type_and_most_are_compared():
    seen, compared = set(), 0
    for seed, n in CASES:
        system, state, off, trajectory = random_case(seed, n)
        seen.update(j.kind for j in system.joints)
        fused, ref = evaluate_both(system, state, off, trajectory, 0.4, None)
        compared += not isinstance(ref, Exception)
    assert set(JOINT_KINDS) <= seen, set(JOINT_KINDS) - seen
    assert compared >= len(CASES) // 2, compared


def test_hold_rank_test_sees_both_kinds():
    """The 1e-12 comparison covers full-rank hold tasks (UR5), the looser one Pandas."""
    kinds = set()
    for seed, n in CASES[:6]:
        system, state, off, trajectory = random_case(seed, n)
        ctrl = object_pd(system, trajectory)
        ev = system.blocks(state)
        ctrl._init_hold(state, ev)
        full = hold_task_full_rank(ctrl, ev)
        kinds.update(zip([a.nv for a in system.arms], full.tolist(), strict=True))
    assert (6, True) in kinds and (7, False) in kinds


@pytest.mark.parametrize("name", ["two_ur5_box", "fingertips_form_closure"])
def test_object_pd_runs_are_unchanged_by_the_compiled_path(name):
    """A short run of a shipped scenario: compiled controller and fused solve vs the numpy
    controller (the run before this change) sample by sample."""
    sc = load_scenario(SCENARIOS / f"{name}.yaml")
    built = build_scenario(sc, load_visuals=False)
    sim = sc.simulation
    runs = []
    for compiled in (True, False):
        ctrl = make_controller(built)
        ctrl.compiled = compiled
        runs.append(simulate(built.system, built.initial_state, ctrl, 0.06, sim.dt,
                             integrator=sim.integrator, solver=sim.solver,
                             baumgarte=sim.baumgarte))
        if compiled:  # warm starts all the way (the first call may need the cold solve:
            # form closure from an empty active set)
            assert ctrl._forces is not None and ctrl._forces.cold_solves <= 1
    fast, ref = runs
    for field in ("q", "v", "object_position", "object_quaternion", "object_twist", "tau",
                  "mu"):
        assert rel_err(getattr(fast, field), getattr(ref, field)) <= 1e-9, field
    assert np.abs(ref.object_twist).max() > 1e-3  # it moved


def test_compiled_log3_equals_pinocchio_and_refuses_near_pi():
    rng = np.random.default_rng(4)
    out = np.empty(3)
    for angle in (0.0, 1e-12, 1e-7, 1e-3, 0.3, 1.0, 2.5, np.pi - 2e-3):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        R = pin.exp3(angle * axis)
        assert controller_kernels.log3(R, out)
        ref = pin.log3(R)
        assert np.abs(out - ref).max() <= 1e-12 * max(1.0, angle), angle
    assert not controller_kernels.log3(pin.exp3((np.pi - 5e-4) * axis), out)


def test_doubtful_cases_fall_back_to_the_reference():
    """An orientation error near π (where the compiled log3 refuses): the reference runs."""
    system, state, _, _ = random_case(3, 2, kinds=["weld", "weld"])
    o = state.obj
    turned = pin.exp3(np.array([0.0, 0.0, np.pi - 1e-4])) @ o.rotation
    target = MinimumJerkTrajectory.hold(o.position, rotation_to_quaternion(turned))
    fused, ref = object_pd(system, target), object_pd(system, target, compiled=False)
    sol, ev, tau = closed_loop_evaluation(system, fused, 0.0, state, "auto")
    assert isinstance(fused.last, InverseDynamicsResult)  # the reference planned it
    np.testing.assert_array_equal(tau, ref(0.0, state, ev))
    assert fused.closed_loop(0.0, state, ev, True) is None  # the kernel refuses this case
