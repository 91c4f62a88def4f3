"""Whole runs of systems whose rows all touch, on the compiled loop (``sim.contact_loop``),
against the Python stepper, sample by sample; an interrupted run; ``compiled: false``."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from closed_loop_cases import RUN_FIELDS, rel_err, run_scenario, run_tolerance

from multiarm_pin._compiled import controller_kernels
from multiarm_pin.sim import contact_loop
from multiarm_pin.sim.simulation import partial_result


@pytest.mark.parametrize("name", ["two_ur5_box", "three_ur5_box", "revolute_handle",
                                  "ur5_panda_box", "mp6_pair_box", "fingertips_form_closure",
                                  "two_gripper_form_closure"])
def test_runs_equal_the_python_loop(name, monkeypatch):
    fast, calls = run_scenario(name, 0.1, True, monkeypatch)
    ref, _ = run_scenario(name, 0.1, False, monkeypatch)
    assert calls, "the compiled loop did not run"
    for field in RUN_FIELDS:
        assert rel_err(getattr(fast, field), getattr(ref, field)) <= run_tolerance(field), field
    np.testing.assert_array_equal(fast.t, ref.t)
    np.testing.assert_array_equal(fast.active, ref.active)
    assert list(fast.solver) == list(ref.solver)
    assert fast.warnings == ref.warnings
    assert np.abs(ref.object_twist).max() > 1e-3  # it moved


@pytest.mark.parametrize("name", ["two_ur5_box", "ur5_panda_box", "fingertips_form_closure"])
def test_semi_implicit_runs_equal_the_python_loop(name, monkeypatch):
    """Semi-implicit Euler in the compiled loop (one evaluation a step) against the stepper's."""
    fast, calls = run_scenario(name, 0.1, True, monkeypatch, integrator="semi_implicit")
    ref, _ = run_scenario(name, 0.1, False, monkeypatch, integrator="semi_implicit")
    rk4, _ = run_scenario(name, 0.1, True, monkeypatch)
    assert calls, "the compiled loop did not run"
    assert fast.integrator == "semi_implicit"
    for field in RUN_FIELDS:
        assert rel_err(getattr(fast, field), getattr(ref, field)) <= run_tolerance(field), field
    np.testing.assert_array_equal(fast.active, ref.active)
    assert fast.warnings == ref.warnings
    # a different integrator: first order, so it differs from RK4 by far more than round-off
    assert rel_err(fast.q, rk4.q) > 1e-7


def test_touching_contacts_kernel_leaves_the_run_unchanged(monkeypatch):
    """grasp_failure to 0.4 s: planning on the touching contacts (from 0.15 s) and holding
    the arms still (rank 5 from 0.243 s) by the compiled kernels gives the run of the numpy
    reference (the kernel made to report a doubtful case at every call, as before it served
    partial active sets): same states, events, warnings."""
    statuses = []
    kernel = controller_kernels.touching_torques

    def recording(*args):
        out = kernel(*args)
        statuses.append(int(out[0]))
        return out

    def refusing(*args):
        return controller_kernels.PD_NOT_FINITE, 0

    with monkeypatch.context() as mp:  # (the compiled loop off: ObjectPD's Python path)
        mp.setattr(controller_kernels, "touching_torques", recording)
        fast, _ = run_scenario("grasp_failure", 0.4, False, monkeypatch)
    with monkeypatch.context() as mp:
        mp.setattr(controller_kernels, "touching_torques", refusing)
        ref, _ = run_scenario("grasp_failure", 0.4, False, monkeypatch)
    assert controller_kernels.PD_OK in statuses and controller_kernels.PD_HOLD in statuses
    assert statuses.count(controller_kernels.PD_OK) + statuses.count(
        controller_kernels.PD_HOLD) == len(statuses)  # no evaluation went to the reference
    assert len(ref.events) >= 2 and sum("object_pd:" in w for w in ref.warnings) == 1
    assert [(e.kind, e.block, e.row) for e in fast.events] == \
        [(e.kind, e.block, e.row) for e in ref.events]
    for a, b in zip(fast.events, ref.events, strict=True):
        assert abs(a.t - b.t) <= 1e-9
    assert fast.warnings == ref.warnings
    np.testing.assert_array_equal(fast.t, ref.t)
    np.testing.assert_array_equal(fast.active, ref.active)
    for field in RUN_FIELDS:
        assert rel_err(getattr(fast, field), getattr(ref, field)) <= 1e-9, field


def test_an_interrupt_keeps_the_samples_so_far(monkeypatch):
    def progress(frac):
        if frac > 0.5:
            raise KeyboardInterrupt

    full, _ = run_scenario("two_ur5_box", 0.2, True, monkeypatch)
    with pytest.raises(KeyboardInterrupt) as info:
        run_scenario("two_ur5_box", 0.2, True, monkeypatch, progress=progress)
    part = partial_result(info.value)
    n = len(part.t)
    assert 0 < n < len(full.t)
    for field in RUN_FIELDS:
        np.testing.assert_array_equal(getattr(part, field), getattr(full, field)[:n])
    assert (part.solver == contact_loop.RECORDED_SOLVERS[False][0]).all()


def test_compiled_false_takes_every_step_on_the_reference(monkeypatch):
    """``simulation: {compiled: false}``: the compiled loop is not asked for a stretch, and
    the run is the reference run (the compiled loop switched off), sample for sample."""
    from closed_loop_cases import SCENARIOS

    from multiarm_pin.app.runner import scenario_controller, simulate_built
    from multiarm_pin.app.scenario import build_scenario, load_scenario
    from multiarm_pin.sim.contact_loop import ContactLoop

    ref, _ = run_scenario("box_on_table", 0.05, False, monkeypatch)
    sc = load_scenario(SCENARIOS / "box_on_table.yaml")
    sc = dataclasses.replace(sc, simulation=dataclasses.replace(sc.simulation, compiled=False))
    built = build_scenario(sc, load_visuals=False)

    def refused(*args, **kwargs):
        raise AssertionError("the compiled loop was asked for a run")

    monkeypatch.setattr(ContactLoop, "for_run", refused)
    result = simulate_built(built, scenario_controller(built), 0.05, sc.simulation.dt,
                            sc.simulation.solver)
    for field in RUN_FIELDS:
        np.testing.assert_array_equal(getattr(result, field), getattr(ref, field), field)
    assert [(e.kind, e.t) for e in result.events] == [(e.kind, e.t) for e in ref.events]


@pytest.mark.parametrize("seed,n_arms", [(seed, 1 + seed % 6) for seed in range(6)])
def test_zero_torque_runs_of_random_systems_equal_the_stepper(seed, n_arms):
    """Random systems of 1-6 UR5s and Pandas, every joint kind (bilateral rows, and the
    fingertips' unilateral ones), falling from rest without torques: the loop takes the
    runs that had no compiled loop before it served bilateral rows, and gives the stepper's
    samples, events and warnings."""
    from closed_loop_cases import random_case

    from multiarm_pin.sim.contact_loop import ContactLoop
    from multiarm_pin.sim.simulation import simulate
    from multiarm_pin.sim.stepper import Stepper

    system, state, _, _ = random_case(seed, n_arms)
    assert ContactLoop.declines(Stepper(system, None, "auto", None), "rk4") is None
    fast = simulate(system, state, None, 0.06, 0.005)
    ref = simulate(system, state, None, 0.06, 0.005, compiled=False)
    for field in RUN_FIELDS:
        assert rel_err(getattr(fast, field), getattr(ref, field)) <= 1e-9, field
    np.testing.assert_array_equal(fast.active, ref.active)
    assert list(fast.solver) == list(ref.solver)
    assert [(e.kind, e.block, e.row) for e in fast.events] == \
        [(e.kind, e.block, e.row) for e in ref.events]
    assert fast.warnings == ref.warnings
    assert np.abs(ref.object_twist[-1]).max() > 0.1  # it fell


@pytest.mark.parametrize("kinds", [("spherical", "spherical"), ("cylindrical", "prismatic")])
def test_arms_of_every_supported_joint_type_run_on_the_loop_as_on_the_stepper(kinds,
                                                                             monkeypatch):
    """Two arms of ``every_joint_model`` (revolute, continuous and prismatic joints, aligned
    and unaligned axes, two trees and a branch) holding a box, falling without torques: the
    loop takes every stretch and gives the stepper's run."""
    import pinocchio as pin
    from rigid_body_models import every_joint_model, random_state
    from system_builders import BOX_SIZE, joint_spec

    from multiarm_pin.model.arm import Arm
    from multiarm_pin.model.rigid_object import RigidObject
    from multiarm_pin.sim.contact_loop import ContactLoop
    from multiarm_pin.sim.simulation import simulate
    from multiarm_pin.system import MultiArmSystem

    rng = np.random.default_rng(3)
    model, _ = every_joint_model(rng)
    arms = [Arm.from_model(model, tool, name=name,
                           base_placement=pin.SE3(np.eye(3), np.array([x, 0.0, 0.0])))
            for name, tool, x in (("a", "l_a5", -0.6), ("b", "l_b5", 0.6))]
    q0 = [random_state(model, rng)[0] for _ in arms]
    system, state = MultiArmSystem.from_initial_state(
        arms, RigidObject.box(BOX_SIZE, 2.0), [joint_spec(k) for k in kinds], q0,
        pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.5])))
    statuses, run = [], ContactLoop.run

    def counted(self, *args):
        out = run(self, *args)
        statuses.append(self.last_status)
        return out

    monkeypatch.setattr(ContactLoop, "run", counted)
    fast = simulate(system, state, None, 0.1, 0.005)
    ref = simulate(system, state, None, 0.1, 0.005, compiled=False)
    assert statuses and set(statuses) == {contact_loop.kernels.STAGE_OK}
    for field in RUN_FIELDS:
        assert rel_err(getattr(fast, field), getattr(ref, field)) <= 1e-9, field
    assert list(fast.solver) == list(ref.solver) and fast.warnings == ref.warnings
    assert np.abs(ref.v).max() > 0.1  # the arms moved
