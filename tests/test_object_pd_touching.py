"""``object_pd`` on the touching contacts only, compiled: ``controller_kernels.touching_torques``
and ``hold_still_torques`` (through ``ObjectPD.closed_loop``) against ``ObjectPD.reference``."""

from __future__ import annotations

import numpy as np
import pytest
from closed_loop_cases import (
    EPS,
    SCENARIOS,
    TOL,
    TOL_RANK_DEFICIENT_HOLD,
    hold_task_conditions,
    random_case,
)
from numba.core import config
from system_builders import moving_state, two_gripper_system

from multiarm_pin._compiled import controller_kernels, function_pointers
from multiarm_pin.app.runner import scenario_controller, simulate_built
from multiarm_pin.app.scenario import build_scenario, load_scenario
from multiarm_pin.dynamics.blocks import restrict_rows
from multiarm_pin.sim.controllers import ObjectPD, grasp_rank
from multiarm_pin.sim.controllers.object_pd import ObjectPDPlan
from multiarm_pin.system import SystemState


@pytest.fixture(scope="module")
def two_gripper():
    return two_gripper_system()


@pytest.fixture
def statuses(monkeypatch):
    """The ``(status, rank)`` of every ``touching_torques`` call from here on."""
    seen = []
    kernel = controller_kernels.touching_torques

    def recording(*args):
        out = kernel(*args)
        seen.append((int(out[0]), int(out[1])))
        return out

    monkeypatch.setattr(controller_kernels, "touching_torques", recording)
    return seen


def touching(system, separated) -> np.ndarray:
    """(n, N_max) active set: every real row but the ``separated`` ``(arm, row)`` pairs."""
    active = system.contact_mask[:system.n_arms, :system.N_max].copy()
    for i, k in separated:
        active[i, k] = False
    return active


def both(system, first, state, active, t=0.3, trajectory=None, margin=1.0):
    """Fresh compiled and reference controllers, the same first call (every contact touching,
    at ``first``), then ``closed_loop`` and ``reference`` at ``state`` with ``active``.

    Returns ``(out, tau_ref, fast, ref)``, ``out`` what ``closed_loop`` returned.
    """
    fast, ref = (ObjectPD(system, trajectory, margin=margin, null_kp=25.0, null_kd=10.0,
                          compiled=compiled) for compiled in (True, False))
    for ctrl in (fast, ref):
        ctrl(0.0, first, system.blocks(first))
    out = fast.closed_loop(t, state, system.blocks(state).with_active(active), False)
    tau_ref = ref(t, state, system.blocks(state).with_active(active))
    return out, tau_ref, fast, ref


def off_manifold(system, state, rng, speed):
    """``state`` moving (velocities projected) and slightly off the constraints."""
    moving = moving_state(system, state, rng, speed)
    return SystemState(moving.q + 1e-4 * rng.normal(size=system.nq), moving.v, moving.obj)


def assert_plans_equal(system, fast, ref, out, tau_ref, active, ev):
    """Torques arm by arm (tolerance of the hold task's conditioning, as in
    ``test_closed_loop``), planned multipliers to 1e-12 and zero on separated rows.

    Returns the (n,) bool of arms compared at the 1e-12 level (full-rank hold task).
    """
    assert out is not None and out[1] == -1, "the compiled path did not serve this case"
    assert isinstance(fast.last, ObjectPDPlan) and not fast.holding and not ref.holding
    assert ref.margin_kept  # the reference kept the margin: the compiled QP is its equal
    cond = hold_task_conditions(fast, ev)
    full = cond < 1e6
    scale = max(1.0, np.abs(tau_ref).max())
    tau, tau_r = system.pad(out[0]), system.pad(tau_ref)
    for i in range(system.n_arms):
        tol = max(TOL, 10 * EPS * cond[i] ** 2) if full[i] else TOL_RANK_DEFICIENT_HOLD
        assert np.abs(tau[i] - tau_r[i]).max() / scale <= tol, (i, system.joints[i].kind)
    mu_scale = max(1.0, np.abs(ref.last.mu).max())
    assert np.abs(fast.last.mu - ref.last.mu).max() / mu_scale <= TOL
    real = system.contact_mask[:system.n_arms, :system.N_max]
    assert np.all(fast.last.mu[real & ~active] == 0.0)
    assert np.all(fast.last.mu[real & active & system.unilateral] >= fast.margin - 1e-9)
    np.testing.assert_allclose(fast.last.a_o, ref.last.a_o, rtol=0, atol=TOL * max(
        1.0, np.abs(ref.last.a_o).max()))
    return full


@pytest.mark.parametrize("seed", range(4))
def test_two_gripper_torques_equal_the_reference(two_gripper, statuses, seed):
    """four_finger:tip[2] separated (the six others still make every wrench), moving states
    off the constraints: the compiled plan is the reference's."""
    system, state = two_gripper
    active = touching(system, [(0, 2)])
    moving = off_manifold(system, state, np.random.default_rng(seed), 0.1)
    out, tau_ref, fast, ref = both(system, state, moving, active)
    full = assert_plans_equal(system, fast, ref, out, tau_ref, active,
                              system.blocks(moving))
    assert full.all()  # MP6 arms with four / three held points: compared to 1e-12
    assert statuses == [(controller_kernels.PD_OK, 6)]


MIXED = [(0, ["fingertips", "weld"], [[(0, 2)], [(0, 2), (0, 1)], [(0, 0), (0, 1), (0, 2)]]),
         (1, ["fingertips", "fingertips", "weld"], [[(0, 2)], [(0, 2), (1, 1)],
                                                    [(1, 1), (0, 0), (1, 2)]]),
         (2, ["weld", "fingertips", "fingertips"], [[(2, 2)], [(1, 0), (1, 1)],
                                                    [(2, 1), (1, 2), (1, 1)]]),
         (6, ["fingertips", "revolute", "universal"], [[(0, 1)], [(0, 0), (0, 2)],
                                                       [(0, 0), (0, 1), (0, 2)]])]
"""Random systems (``closed_loop_cases.random_case``: UR5s and Pandas) with fingertips
(unilateral rows) next to framed joints that keep the grasp rank 6; 1-3 separated
fingertips, up to all of one arm's (that arm then plans no force: ``N_i = 0``)."""


@pytest.mark.parametrize("seed,kinds,separations", MIXED)
def test_mixed_systems_torques_equal_the_reference(statuses, seed, kinds, separations):
    system, state, off, trajectory = random_case(seed, len(kinds), kinds)
    compared = []
    for separated in separations:
        active = touching(system, separated)
        ev = system.blocks(off).with_active(active)
        assert grasp_rank(restrict_rows(ev.blocks, active)[0]) == 6
        out, tau_ref, fast, ref = both(system, state, off, active, 0.4, trajectory, 0.5)
        full = assert_plans_equal(system, fast, ref, out, tau_ref, active, ev)
        compared += [full[i] for i, _ in separated]
    assert statuses == [(controller_kernels.PD_OK, 6)] * len(separations)
    if seed in (1, 2, 6):  # UR5 fingertip arms among the separated ones: the 1e-12 level
        assert any(compared)


def test_every_mixed_case_is_a_kind_the_tests_mean():
    """The cases above: fingertips next to other joints, UR5s and Pandas, every separated
    row unilateral and real."""
    robots = set()
    for seed, kinds, separations in MIXED:
        system, *_ = random_case(seed, len(kinds), kinds)
        assert [j.kind for j in system.joints] == kinds
        robots.update(a.nv for a in system.arms)
        for separated in separations:
            for i, k in separated:
                assert system.unilateral[i, k] and system.contact_mask[i, k]
    assert robots == {6, 7}


HOLD_CASES = [([(0, 0), (0, 1), (0, 2), (0, 3)], 3),  # only the three-finger gripper
              ([(1, 0), (1, 1), (1, 2)], 4),  # only the four-finger gripper
              ([(0, 2), (0, 3)], 5)]  # five contacts (grasp_failure after 0.243 s)
"""Separations that remove rank structurally: at most as many columns as the rank given."""


@pytest.mark.parametrize("separated,columns", HOLD_CASES)
def test_lost_rank_holds_the_arms_still_like_the_reference(two_gripper, statuses, separated,
                                                           columns):
    system, state = two_gripper
    active = touching(system, separated)
    rng = np.random.default_rng(7)
    first = off_manifold(system, state, rng, 0.1)
    later = off_manifold(system, state, rng, 0.1)
    out, tau_ref, fast, ref = both(system, state, first, active)
    rank = grasp_rank(restrict_rows(system.blocks(first).blocks, active)[0])
    assert rank <= columns < 6
    assert statuses == [(controller_kernels.PD_HOLD, rank)]
    assert out is not None and out[1] == -1
    assert fast.holding and ref.holding
    assert fast.warnings == ref.warnings and len(fast.warnings) == 1
    assert f"(rank {rank} < 6)" in fast.warnings[0]
    np.testing.assert_array_equal(fast._q_hold, first.q)
    scale = max(1.0, np.abs(tau_ref).max())
    assert np.abs(out[0] - tau_ref).max() / scale <= TOL
    assert not np.allclose(out[0], 0.0)
    # later in the hold: no new warning, the PD toward the onset's configuration
    out = fast.closed_loop(0.31, later, system.blocks(later).with_active(active), False)
    tau_ref = ref(0.31, later, system.blocks(later).with_active(active))
    assert len(fast.warnings) == len(ref.warnings) == 1
    np.testing.assert_array_equal(fast._q_hold, first.q)
    assert np.abs(out[0] - tau_ref).max() / max(1.0, np.abs(tau_ref).max()) <= TOL


def test_rank_six_is_decided_with_margin(two_gripper, statuses):
    """The rank-6 case of the two-gripper tests is far from the threshold: its smallest
    normalised singular value is above 1e-3 of the largest (the tolerance is 1e-9)."""
    system, state = two_gripper
    active = touching(system, [(0, 2)])
    sub, _ = restrict_rows(system.blocks(state).blocks, active)
    W_o = sub.stacked_W_o()
    sv = np.linalg.svd(W_o / np.linalg.norm(W_o, axis=0), compute_uv=False)
    assert sv[-1] > 1e-3 * sv[0] and grasp_rank(sub) == 6
    sub_k = np.ascontiguousarray(sub.W_o)
    assert controller_kernels.touching_rank(sub_k, sub.N.astype(np.int64)) == 6
    lost, _ = restrict_rows(system.blocks(state).blocks, touching(system, [(0, 2), (0, 3)]))
    assert controller_kernels.touching_rank(np.ascontiguousarray(lost.W_o),
                                            lost.N.astype(np.int64)) == grasp_rank(lost) == 5


def test_hold_still_torques_are_gravity_compensation_at_rest(two_gripper):
    """``τ = M z - h`` with ``z = 0`` at rest is ``g(q)`` (``-h`` at zero velocity), checked
    against the reference blocks' ``h``; zero on padding."""
    system, state = two_gripper
    ev = system.blocks(state)
    path = system.compiled
    tau = np.full((system.n_arms, system.arm_set.nv_max), np.nan)
    z = np.zeros_like(tau)
    controller_kernels.hold_still_torques(ev.buffer, path.dims, path.nv_arm, z, tau)
    ref = system.blocks(state, reference=True).blocks
    np.testing.assert_allclose(tau, np.where(ref.dof_mask, -ref.h, 0.0), rtol=0, atol=1e-10)
    assert np.abs(tau).max() > 1.0


def test_a_partial_active_set_is_not_solved_by_the_fused_path(two_gripper):
    """With contacts separated the forward dynamics is the stepper's mixed LCP."""
    system, state = two_gripper
    ctrl = ObjectPD(system, margin=1.0)
    ev = system.blocks(state).with_active(touching(system, [(0, 2)]))
    assert ctrl.closed_loop(0.0, state, ev, True) is None
    out = ctrl.closed_loop(0.0, state, ev, False)
    assert out is not None and out[1] == -1


def test_a_failing_margin_goes_to_the_reference(two_gripper, statuses):
    """A separation that leaves no internal force keeping every margin (four_finger:tip[0]
    off: six contacts, no form closure): the kernel reports it, the reference plans
    least-norm forces."""
    system, state = two_gripper
    active = touching(system, [(0, 0)])
    ctrl = ObjectPD(system, margin=1.0)
    tau = ctrl(0.0, state, system.blocks(state).with_active(active))
    assert statuses == [(controller_kernels.PD_FORCES_FAILED, 6)]
    assert not ctrl.margin_kept and not isinstance(ctrl.last, ObjectPDPlan)
    assert np.all(np.isfinite(tau))


@pytest.mark.skipif(config.DISABLE_JIT, reason="compiled functions need the JIT")
def test_the_python_path_plans_with_the_contact_loops_object_pd_step(statuses):
    """After a contact-loop run (grasp_failure separates from 0.15 s), ``ObjectPD``'s Python
    path on separated rows (what a step handed back runs) calls ``object_pd_step`` through
    the loop's own compile of it: no second compile of the plan."""
    sc = load_scenario(SCENARIOS / "grasp_failure.yaml")
    built = build_scenario(sc, load_visuals=False)
    ctrl = scenario_controller(built)
    simulate_built(built, ctrl, 0.2, sc.simulation.dt, sc.simulation.solver)
    step = controller_kernels.object_pd_step.py_func

    def made():
        return {key for key in function_pointers._by_signature if key[0] is step}

    before = made()
    assert before, "the contact loop did not compile object_pd_step"
    system, state = built.system, built.initial_state
    evaluation = system.blocks(state).with_active(touching(system, [(0, 0)]))
    ctrl.closed_loop(0.2, state, evaluation, False)
    assert statuses  # touching_torques ran, with object_pd_step's pointer made
    assert made() == before
