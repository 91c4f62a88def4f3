"""Whole runs with the compiled closed loop (``sim.compiled_loop``) against the Python loop,
sample by sample, including the steps the kernel hands back and an interrupted run."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from closed_loop_cases import RUN_FIELDS, rel_err, run_scenario, run_tolerance

from multiarm_pin._compiled import controller_kernels
from multiarm_pin.sim import compiled_loop
from multiarm_pin.sim.simulation import partial_result


@pytest.mark.parametrize("name", ["two_ur5_box", "three_ur5_box", "revolute_handle",
                                  "ur5_panda_box", "mp6_pair_box", "fingertips_form_closure"])
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


def test_steps_handed_back_keep_the_events(monkeypatch):
    """Fingertips that let go (grasp_failure): the kernel hands those steps back, the
    stepper locates the same separations."""
    fast, calls = run_scenario("grasp_failure", 0.6, "closed", monkeypatch)
    ref, _ = run_scenario("grasp_failure", 0.6, False, monkeypatch)
    assert calls, "the compiled loop did not run"
    assert ref.events, "the scenario should separate"
    assert [(e.kind, e.block, e.row) for e in fast.events] == \
        [(e.kind, e.block, e.row) for e in ref.events]
    for a, b in zip(fast.events, ref.events, strict=True):
        assert abs(a.t - b.t) <= 1e-9
    for field in RUN_FIELDS:
        assert rel_err(getattr(fast, field), getattr(ref, field)) <= 1e-7, field


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

    with monkeypatch.context() as mp:
        mp.setattr(controller_kernels, "touching_torques", recording)
        fast, _ = run_scenario("grasp_failure", 0.4, "closed", monkeypatch)
    with monkeypatch.context() as mp:  # (the contact loop off: ObjectPD's Python path)
        mp.setattr(controller_kernels, "touching_torques", refusing)
        ref, _ = run_scenario("grasp_failure", 0.4, "closed", monkeypatch)
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
    assert (part.solver == compiled_loop.RECORDED_SOLVER[False]).all()


def test_compiled_false_takes_every_step_on_the_reference(monkeypatch):
    """``simulation: {compiled: false}``: neither compiled loop is asked for a stretch, and
    the run is the reference run (the compiled loops switched off), sample for sample."""
    from closed_loop_cases import SCENARIOS

    from multiarm_pin.app.runner import scenario_controller, simulate_built
    from multiarm_pin.app.scenario import build_scenario, load_scenario
    from multiarm_pin.sim.compiled_loop import CompiledLoop
    from multiarm_pin.sim.contact_loop import ContactLoop

    ref, _ = run_scenario("box_on_table", 0.05, False, monkeypatch)
    sc = load_scenario(SCENARIOS / "box_on_table.yaml")
    sc = dataclasses.replace(sc, simulation=dataclasses.replace(sc.simulation, compiled=False))
    built = build_scenario(sc, load_visuals=False)

    def refused(*args, **kwargs):
        raise AssertionError("a compiled loop was asked for a run")

    monkeypatch.setattr(CompiledLoop, "for_run", refused)
    monkeypatch.setattr(ContactLoop, "for_run", refused)
    result = simulate_built(built, scenario_controller(built), 0.05, sc.simulation.dt,
                            sc.simulation.solver)
    for field in RUN_FIELDS:
        np.testing.assert_array_equal(getattr(result, field), getattr(ref, field), field)
    assert [(e.kind, e.t) for e in result.events] == [(e.kind, e.t) for e in ref.events]
