"""The shipped ``tilt_pick`` scenario (issue 27): its start, its grasp and its tilt's onset.

The whole run (5.6 s, the compiled contact loop) is checked once here, against the issue's
"done when" (``test_scenarios_run`` leaves its whole run to this module).
"""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np
from scipy.optimize import linprog

from multiarm_pin.app.runner import scenario_controller, simulate_built
from multiarm_pin.app.scenario import build_scenario, load_scenario
from tests.run_helpers import tilt_pick_event_times

PATH = Path(__file__).resolve().parent.parent / "scenarios" / "tilt_pick.yaml"


@cache
def _built():
    return build_scenario(load_scenario(PATH), load_visuals=False)


def test_the_grippers_start_apart_and_the_couple_touches():
    """Gaps at t = 0: the pusher's and the stop's tips touch; four_finger's are its
    approach offset along each face's normal (4 cm); three_finger's -x and -y tips 8 and
    4 cm off, its -z tip 10 cm above the bottom face's plane but beside the face (x beyond
    -0.4 m): not touching, not active."""
    from multiarm_pin.sim.stepper import Stepper

    built = _built()
    s, state = built.system, built.initial_state
    phi = s.blocks(state).constraints.phi
    assert np.abs(phi[:2, :3]).max() < 1e-9
    np.testing.assert_allclose(phi[2, :4], 0.04, atol=1e-9)
    np.testing.assert_allclose(phi[3, :3], [0.08, 0.04, -0.1], atol=1e-9)
    stepper = Stepper(s, None, "object_first", None)
    stepper.init_active(stepper.blocks_at(0.0, state)[1], 1e-6)
    assert stepper.active[:2, :3].all() and not stepper.active[2:4, :4].any()
    assert stepper.beside_start[3, 2] and stepper.beside_start.sum() == 1


def test_the_final_grasp_is_form_closure_and_needs_every_gripper_tip():
    """The 13 contacts of the lift (Eq 2.1 by LP: rank 6 and a strictly positive
    combination of the wrenches is zero); without four_finger's tip[3] or three_finger's
    bottom tip it is not, so the pivot edge cannot leave the table before they touch."""
    built = _built()
    tips = []
    for j in built.joints:
        for c in j.contacts:
            n = -c.surface.normal  # the force on the object pushes against the outward normal
            p = j.tool_in_object.act(c.point) + c.radius * c.surface.normal
            tips.append(np.r_[n, np.cross(p, n)])
    W = np.array(tips).T

    def closure(cols):
        Wc = W[:, cols]
        res = linprog(np.zeros(Wc.shape[1]), A_eq=Wc, b_eq=np.zeros(6),
                      bounds=[(1, None)] * Wc.shape[1], method="highs")
        return np.linalg.matrix_rank(Wc) == 6 and res.status == 0

    every = list(range(W.shape[1]))
    assert W.shape[1] == 13 and closure(every)
    assert not closure([k for k in every if k != 9])  # four_finger:tip[3]
    assert not closure([k for k in every if k != 12])  # three_finger:tip[2]


@cache
def _onset():
    """The first 0.2 s of the run (the tilt's onset)."""
    built = _built()
    sc = built.scenario
    return simulate_built(built, scenario_controller(built), 0.2, sc.simulation.dt,
                          sc.simulation.solver)


def test_the_tilt_starts_on_the_pivot_edge():
    """The first 0.2 s: the -x edge's vertices (rows 2, 3) separate first, at the tilt's
    start; the pivot (rows 0, 1) presses with at least the support margin; no contact
    force is negative; the compiled contact loop takes it (no note that the reference
    stepper does)."""
    res = _onset()
    assert [(e.kind, e.label) for e in res.events] == [("separation", "table[2]"),
                                                       ("separation", "table[3]")]
    assert 0.1 <= res.events[0].t < 0.11
    after = res.t > 0.11
    assert res.mu[after, 4, :2].min() >= 2.0 - 1e-6  # the support block comes after 4 arms
    assert res.mu.min() >= 0.0
    assert res.constraint_violation.max() < 1e-6
    assert not any("numpy) stepper" in w for w in res.warnings)


def test_the_onset_stays_on_the_table_and_has_no_finite_support_note():
    """The table is a 1.6 x 1.2 m rectangle about the origin, the box's support points at
    x = ±0.4, y = ±0.3 m: in the first 0.2 s they stay over 0.25 m inside it at every
    sample, so no step is handed to the Python stepper for a point off its rectangle and
    the run's warnings have no ``FINITE_SUPPORTS_NOTE``."""
    from multiarm_pin.sim.contact_loop import FINITE_SUPPORTS_NOTE

    built, res = _built(), _onset()
    table = built.system.supports.supports[0]
    assert table.extent is not None
    half = np.asarray(table.extent) / 2
    n_arms = len(built.system.arms)
    points = res.contact_points[:, n_arms, :len(table.points), :2]  # world x, y
    assert (half - np.abs(points)).min() > 0.25
    assert FINITE_SUPPORTS_NOTE not in res.warnings


def test_the_compiled_run_equals_the_reference_stepper():
    """The tilt's onset (0.2 s: the far edge's vertices separate) on the compiled contact
    loop and on the Python stepper with the controller's numpy reference: the same events
    (times to 1e-9 s), joint and object trajectories to 1e-9, contact forces to 1e-9 of the
    largest; only the reference run says that the reference stepper takes it."""
    built = _built()
    sim = built.scenario.simulation
    reference = scenario_controller(built)
    reference.compiled = False
    runs = [simulate_built(built, ctrl, 0.2, sim.dt, sim.solver)
            for ctrl in (scenario_controller(built), reference)]
    a, b = runs
    assert [(e.kind, e.label) for e in a.events] == [(e.kind, e.label) for e in b.events]
    assert len(a.events) == 2
    np.testing.assert_allclose([e.t for e in a.events], [e.t for e in b.events], atol=1e-9)
    for name in ("q", "v", "object_position", "object_quaternion", "object_twist"):
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=0, atol=1e-9,
                                   err_msg=name)
    tol = 1e-9 * np.abs(b.mu).max()
    n_arms = len(built.system.arms)  # mu's blocks: the arms', then the table's
    np.testing.assert_allclose(a.mu[:, :n_arms], b.mu[:, :n_arms], rtol=0, atol=tol)
    # The table's four points are the corners of a face: their rows have a null direction
    # (λ_k ∝ sign(x_k) sign(y_k)), so the split among them while all four press depends on
    # rounding (the CPU's and the solver's pivots); what the dynamics sees is their
    # resultant: Σλ_k and Σλ_k p_k (object frame; the object's pose is the same in both
    # runs, checked above).
    points = np.asarray(built.system.supports.supports[0].points)
    table = [r.mu[:, n_arms, :len(points)] for r in runs]
    resultants = [np.concatenate([lam.sum(axis=1, keepdims=True), lam @ points], axis=1)
                  for lam in table]
    np.testing.assert_allclose(resultants[0], resultants[1], rtol=0, atol=4 * tol)
    assert np.all(a.mu[:, n_arms, len(points):] == 0.0)
    assert not any("numpy) stepper" in w for w in a.warnings)
    assert [w for w in b.warnings if "numpy) stepper" in w] == [
        "the run is taken by the reference (numpy) stepper, not a compiled loop: controller "
        "'phased_pd' was built with compiled=False"]


def test_the_whole_run_tilts_inserts_lifts_and_ends_on_target():
    """The issue's "done when": in the events, the far edge's vertices separate first (the
    tilt), then fingertips touch down on the bottom face, then the pivot's vertices
    separate (the lift); no contact force below zero at any sample; no collision and every
    joint within its limits (the feasibility report); the box's final pose on its target
    to 1e-3 m (the closed form: the start turned 0.12 rad about the pivot edge, then moved
    by (0.05, 0, 0.05) m)."""
    from multiarm_pin.app.run_feasibility import check_initial_state
    from multiarm_pin.feasibility import feasibility_report

    built = _built()
    scene = check_initial_state(built)
    sim = built.scenario.simulation
    res = simulate_built(built, scenario_controller(built), sim.duration, sim.dt, sim.solver)
    report = feasibility_report(built.system, res, ground=built.scenario.ground, scene=scene)
    assert report.feasible, [v.describe() for v in report.violations]
    assert all(v is None or v > 0 for v in report.clearance.values()), report.clearance
    assert report.clearance["arm_support"] > 0.01  # the whole table top, not only under the box
    far, bottom, pivot = tilt_pick_event_times(res.events)
    assert far < bottom < pivot
    assert not any(e.kind == "touchdown" and e.label.startswith("table")
                   for e in res.events)  # the box never falls back
    assert res.mu.min() >= 0.0
    assert not res.active[-1, 4].any()  # carried: no support row touches at the end
    th = 0.12
    R = np.array([[np.cos(th), 0, np.sin(th)], [0, 1, 0], [-np.sin(th), 0, np.cos(th)]])
    c = np.array([0.4, 0.0, 0.7])
    goal = c + R @ (np.array([0.0, 0.0, 0.9]) - c) + [0.05, 0.0, 0.05]
    assert np.linalg.norm(res.object_position[-1] - goal) < 1e-3
    x, y, z, w = res.object_quaternion[-1]
    q_goal = np.array([0.0, np.sin(th / 2), 0.0, np.cos(th / 2)])
    assert abs(abs(np.dot([x, y, z, w], q_goal)) - 1.0) < 1e-6
