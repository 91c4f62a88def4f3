"""The compiled contact loop (``sim.contact_loop``): whole runs with separations, touchdowns
and impacts against the Python stepper, sample by sample and event by event."""

from __future__ import annotations

import numpy as np
import pytest
from closed_loop_cases import (
    RUN_FIELDS,
    SCENARIOS,
    assert_same_contact_run,
    rel_err,
    run_scenario,
)

from multiarm_pin.app.runner import scenario_controller, simulate_built
from multiarm_pin.app.scenario import build_scenario, load_scenario
from multiarm_pin.sim import contact_events as ce
from multiarm_pin.sim import contact_loop
from multiarm_pin.sim import event_location as el
from multiarm_pin.sim.contact_loop import ContactLoop
from multiarm_pin.sim.controllers import make_controller
from multiarm_pin.sim.disturbances import WrenchSchedule
from multiarm_pin.sim.stepper import Stepper


def _same_events(fast, ref, tol):
    assert [(e.kind, e.block, e.row, e.rebound) for e in fast.events] == \
        [(e.kind, e.block, e.row, e.rebound) for e in ref.events]
    for a, b in zip(fast.events, ref.events, strict=True):
        assert abs(a.t - b.t) <= tol
        for f in ("phi_dot", "phi_dot_after", "impulse"):
            assert abs(getattr(a, f) - getattr(b, f)) <= 1e-7 * (1.0 + abs(getattr(b, f))), f


@pytest.mark.parametrize(("name", "duration", "tol", "support_block"), [
    ("box_on_table", 0.6, 1e-9, 0),     # no arms: a bouncing box, 40 touchdowns
    ("grasp_failure", 0.6, 1e-7, None),  # fingertips let go, object_pd holds the arms still
    ("pick_from_table", 0.4, 1e-7, 2),  # arms and a support: the stand's rows let go
])
def test_runs_equal_the_python_stepper(name, duration, tol, support_block, monkeypatch):
    """Event by event and sample by sample. The support's rows (four coplanar vertices)
    are redundant: which of them takes a force or an impulse is decided by round-off, so
    they are compared by their resultant, which is unique (the row by row split agrees only
    while both paths compute the same numbers to the bit); the fingertips on 6-joint arms
    are independent rows, compared one by one."""
    fast, calls = run_scenario(name, duration, True, monkeypatch)
    ref, _ = run_scenario(name, duration, False, monkeypatch)
    assert calls, "the contact loop did not run"
    assert ref.events, "the scenario should have contact events"
    assert_same_contact_run(fast, ref, tol, support_block=support_block)
    assert fast.warnings == ref.warnings


def test_the_whole_grasp_failure_on_the_compiled_loop(monkeypatch):
    """Every contact touching until the first release, then separations and the hold-still
    fallback, all in the loop: the Python run's events, hold-still warning and fall."""
    fast, calls = run_scenario("grasp_failure", 1.0, True, monkeypatch)
    ref, _ = run_scenario("grasp_failure", 1.0, False, monkeypatch)
    assert len(ref.events) > 5
    _same_events(fast, ref, 1e-7)
    assert fast.warnings == ref.warnings
    assert any("holding the arms still" in w for w in fast.warnings)
    for field in RUN_FIELDS:
        assert rel_err(getattr(fast, field), getattr(ref, field)) <= 1e-6, field


def test_rules_are_the_event_modules():
    rules = contact_loop.rules_vector()
    k = contact_loop.kernels
    assert rules[k.R_GAP] == ce.GAP_TOLERANCE
    assert rules[k.R_SEP_TIME] == ce.SEPARATION_TIME_TOLERANCE
    assert rules[k.R_MAX_EVENTS] == ce.MAX_EVENTS_PER_STEP
    assert rules[k.R_RESTING_RELEASE] == el.RESTING_RELEASE
    assert len(rules) == len(k.EVENT_CONSTANTS)


def test_recorded_solver_names_are_the_unilateral_solves():
    """The kernel's solver codes name what ``solve_unilateral`` records on the same path, and
    what ``solve`` records for a run without unilateral rows (its object-first solve)."""
    k = contact_loop.kernels
    assert contact_loop.RECORDED_SOLVERS[True][k.SOLVER_BILATERAL] == "bilateral"
    assert contact_loop.RECORDED_SOLVERS[True][k.SOLVER_ACTIVE_SET] == "active_set"
    assert contact_loop.RECORDED_SOLVERS[False][k.SOLVER_BILATERAL] == "object_first"


def test_a_wrench_schedule_of_another_kind_stays_on_the_stepper():
    """The loops read a schedule's intervals as a table: a subclass with its own ``__call__``
    (here a ramp) would be read wrongly, so the loop takes no such run, with bilateral rows
    or unilateral ones."""
    class Ramp(WrenchSchedule):
        def __call__(self, t):
            return np.array([0.0, 0.0, -10.0 * t, 0.0, 0.0, 0.0])

    for name in ("two_ur5_box", "grasp_failure"):
        built = build_scenario(load_scenario(SCENARIOS / f"{name}.yaml"), load_visuals=False)
        plain = WrenchSchedule([(0.0, 1.0, np.ones(6))])
        ramp = Ramp([(0.0, 1.0, np.ones(6))])
        for wrench, takes in ((plain, True), (ramp, False)):
            stepper = Stepper(built.system, scenario_controller(built), "object_first", None,
                              wrench)
            assert (ContactLoop.for_run(stepper, "rk4") is not None) == takes, (name, takes)


def test_zero_torque_with_arms_runs_on_the_contact_loop_as_on_the_stepper(monkeypatch):
    """The registry's ``none`` (zero torque) is served by the contact loop's zero-torque mode:
    the fingertips of grasp_failure let the box fall, the same run as the stepper's."""
    built = build_scenario(load_scenario(SCENARIOS / "grasp_failure.yaml"), load_visuals=False)
    sim = built.scenario.simulation
    runs, calls, run = [], [], ContactLoop.run
    monkeypatch.setattr(ContactLoop, "run", lambda self, *a: calls.append(a[3]) or run(self, *a))
    for compiled in (True, False):
        calls.clear()
        with monkeypatch.context() as mp:
            if not compiled:
                mp.setattr(ContactLoop, "for_run", classmethod(lambda cls, *a: None))
            ctrl = make_controller("none", built.system)
            runs.append(simulate_built(built, ctrl, 0.1, sim.dt, sim.solver))
        assert bool(calls) == compiled
    fast, ref = runs
    assert fast.events and not [w for w in fast.warnings if "reference" in w]
    assert_same_contact_run(fast, ref, 1e-9)


@pytest.mark.parametrize(("name", "duration", "tol", "support_block"), [
    ("box_on_table", 0.4, 1e-9, 0),
    # to 0.2 s: the first separation (0.15 s); later, first-order steps make its tips chatter
    # past MAX_EVENTS_PER_STEP at 0.254 s, on the stepper as in the kernel
    ("grasp_failure", 0.2, 1e-7, None),
])
def test_semi_implicit_runs_with_events_equal_the_python_stepper(name, duration, tol,
                                                                 support_block, monkeypatch):
    """Semi-implicit Euler in the contact loop (``Stepper.step``'s other branch, its events
    located with the same steps): the stepper's events and samples; and a first-order run,
    far from RK4's."""
    fast, calls = run_scenario(name, duration, True, monkeypatch,
                               integrator="semi_implicit")
    ref, _ = run_scenario(name, duration, False, monkeypatch, integrator="semi_implicit")
    rk4, _ = run_scenario(name, duration, True, monkeypatch)
    assert calls, "the contact loop did not run"
    assert fast.integrator == "semi_implicit" and ref.events, "the run should have events"
    assert_same_contact_run(fast, ref, tol, support_block=support_block)
    assert fast.warnings == ref.warnings
    assert not [w for w in fast.warnings if "reference (numpy) stepper" in w]
    assert rel_err(fast.object_position, rk4.object_position) > 1e-7


def test_the_event_machinery_is_compiled_at_the_first_step_that_needs_it(monkeypatch):
    """The loop starts without its events where every row is active (arms, no supports) and
    is made with them at the first step that needs them: never for a grasp that holds
    (fingertips_form_closure), at the first release of grasp_failure. Without them it takes
    the same steps with the same operations: the same run, bit for bit, as the loop made
    with its events from the start."""
    made = []
    original = contact_loop.kernels.loop_functions

    def recorded(head, events=True):
        made.append(events)
        return original(head, events)

    monkeypatch.setattr(contact_loop.kernels, "loop_functions", recorded)
    lazy, _ = run_scenario("fingertips_form_closure", 0.1, True, monkeypatch)
    assert made and not any(made)
    made.clear()
    run_scenario("grasp_failure", 0.3, True, monkeypatch)
    assert made[0] is False and made[-1] is True
    made.clear()
    init = ContactLoop.__init__

    def eager(self, *args, **kwargs):
        init(self, *args, **kwargs)
        self.with_events = True

    monkeypatch.setattr(ContactLoop, "__init__", eager)
    full, _ = run_scenario("fingertips_form_closure", 0.1, True, monkeypatch)
    assert made and all(made)
    for field in RUN_FIELDS:
        np.testing.assert_array_equal(getattr(lazy, field), getattr(full, field), field)
    assert list(lazy.solver) == list(full.solver)
