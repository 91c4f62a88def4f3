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
from multiarm_pin.app.runner import scenario_controller
from multiarm_pin.app.scenario import build_scenario, load_scenario
from multiarm_pin.dynamics import InverseDynamicsResult
from multiarm_pin.exceptions import DynamicsError
from multiarm_pin.sim.closed_loop import closed_loop_evaluation
from multiarm_pin.sim.simulation import simulate
from multiarm_pin.sim.trajectories import MinimumJerkTrajectory
from multiarm_pin.spatial import rotation_to_quaternion

SCENARIOS = Path(__file__).resolve().parent.parent / "scenarios"

CASES = [(seed, 1 + seed % 6) for seed in range(12)]
WELD_CASES = [(2, 3), (6, 4)]
"""Welds only: Pandas (6 rows, 7 joints: the hold task decides their null motion) next to
UR5s (6 rows, 6 joints: square ``W_i``, the rows alone fix ``q̈_i``)."""


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


@pytest.mark.parametrize("seed,n_arms,kinds", [(s, n, None) for s, n in CASES]
                         + [(s, n, ["weld"] * n) for s, n in WELD_CASES])
@pytest.mark.parametrize("baumgarte", [None, (5.0, 5.0)])
def test_fused_closed_loop_equals_reference(seed, n_arms, kinds, baumgarte):
    system, state, off, trajectory = random_case(seed, n_arms, kinds)
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


def record_statuses(monkeypatch) -> list[int]:
    """The statuses of every compiled ``object_pd_step`` call from here on (in call order)."""
    statuses = []
    step = controller_kernels.object_pd_step

    def recording(*args):
        out = step(*args)
        statuses.append(int(out))
        return out

    monkeypatch.setattr(controller_kernels, "object_pd_step", recording)
    return statuses


def square_arms(system) -> np.ndarray:
    """(n,) bool: the arm has as many constraint rows as joints (``W_i`` square)."""
    return np.array([system.compiled.N[i] == arm.nv for i, arm in enumerate(system.arms)])


def test_weld_cases_mix_square_and_task_arms():
    for seed, n in WELD_CASES:
        square = square_arms(random_case(seed, n, ["weld"] * n)[0])
        assert square.any() and not square.all(), (seed, square)


def test_square_rows_fix_the_arm_without_its_hold_task(monkeypatch):
    """A square full-rank ``W_i`` gives ``q̈_i = W_i⁻ᵀ (c_i - W_o,iᵀ a_d)`` (solved here by
    numpy), and neither the answer nor the status depends on the arm's hold task: without
    held points its ``AᵀA + ε I`` is zero, yet the kernel plans the same torques."""
    system, state, off, trajectory = random_case(2, 3, ["weld"] * 3)
    square = square_arms(system)
    ctrl = object_pd(system, trajectory)
    ev = system.blocks(off)
    statuses = record_statuses(monkeypatch)
    tau = ctrl(0.4, off, ev)
    plan = ctrl.last
    b = ev.blocks
    for i in np.flatnonzero(square):
        nv = system.arms[i].nv
        expected = np.linalg.solve(b.W[i, :nv, :nv].T, b.c[i, :nv] - b.W_o[i, :, :nv].T @ plan.a_o)
        assert rel_err(plan.qdd[i, :nv], expected) <= TOL, i
    ctrl._hold_n[square] = 0  # the square arms' hold tasks are empty from now on
    np.testing.assert_array_equal(ctrl(0.4, off, ev), tau)
    assert statuses == [controller_kernels.PD_OK] * 2


def test_square_rank_deficient_rows_hand_back_to_the_reference(monkeypatch):
    """A square ``W_i`` with one constraint row twice (structurally singular: its last QR
    pivot is round-off, far below the rank margin on any CPU): the kernel reports
    ``PD_ARM_RANK`` and the reference's pseudo-inverse plans the torques."""
    system, state, off, trajectory = random_case(2, 3, ["weld"] * 3)
    i = int(np.flatnonzero(square_arms(system))[0])
    ev = system.blocks(off)
    b = ev.blocks
    for block in (b.W[i], b.W_o[i]):  # views of the evaluation's buffer
        block[:, 5] = block[:, 4]
    b.c[i, 5] = b.c[i, 4]
    fused, ref = object_pd(system, trajectory), object_pd(system, trajectory, compiled=False)
    statuses = record_statuses(monkeypatch)
    tau = fused(0.4, off, ev)
    assert statuses == [controller_kernels.PD_ARM_RANK]
    assert isinstance(fused.last, InverseDynamicsResult)  # the reference planned it
    np.testing.assert_array_equal(tau, ref(0.4, off, ev))


@pytest.mark.parametrize("name", ["two_ur5_box", "fingertips_form_closure"])
def test_object_pd_runs_are_unchanged_by_the_compiled_path(name):
    """A short run of a shipped scenario: compiled controller and fused solve vs the numpy
    controller (the run before this change) sample by sample."""
    sc = load_scenario(SCENARIOS / f"{name}.yaml")
    built = build_scenario(sc, load_visuals=False)
    sim = sc.simulation
    runs = []
    for compiled in (True, False):
        ctrl = scenario_controller(built)
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
