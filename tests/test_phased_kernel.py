"""The compiled ``phased_pd`` (``_compiled.phased.phased_torques``) against ``PhasedPD.reference``.

The shipped ``tilt_pick`` system (four arms, a finite table) with phases of every kind and
every contact-set setting (press subsets and none, a released arm, offsets, a phase margin,
loose rows), at states around the initial one (random joint and object velocities) and
times in each phase, with two active sets: the initial one (two arms touching) and every arm
row touching. The torques agree to 1e-9 relative; so do the planned multipliers and support
forces, and whether the margins were kept.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np

import multiarm_pin.dynamics.force_distribution as fd
from multiarm_pin.app.scenario import build_scenario, load_scenario
from multiarm_pin.sim.controllers import make_controller

PATH = Path(__file__).resolve().parent.parent / "scenarios" / "tilt_pick.yaml"
_LSQ_LINEAR = __import__("scipy.optimize", fromlist=["lsq_linear"]).lsq_linear


@cache
def _built():
    return build_scenario(load_scenario(PATH), load_visuals=False)


def _phases(built):
    arms = [a.name for a in built.system.arms]
    labels = [lab for b, _, lab in built.system.contact_labels if b < len(arms)]
    return [
        {"name": "rest", "kind": "hold", "t": 0.0, "duration": 0.1,
         "offsets": {arms[0]: [0.0005, 0, 0]}},
        {"name": "tilt", "kind": "tilt", "t": 0.1, "duration": 1.0, "pivot": [0.4, 0.0, 0.7],
         "axis": [0, 1, 0], "angle": 0.12, "press": [0, 1]},
        {"name": "loose", "kind": "hold", "t": 1.1, "duration": 0.5, "press": [0, 1],
         "margin": 1.5, "loose": labels[:2], "offsets": {arms[-1]: [-0.01, 0.0, 0.002]}},
        {"name": "let_go", "kind": "hold", "t": 1.6, "duration": 0.4, "release": [arms[0]]},
        {"name": "lift", "kind": "move", "t": 2.0, "duration": 0.5, "press": [],
         "displacement": [0.01, 0, 0.05]},
        {"name": "hard", "kind": "hold", "t": 2.5, "duration": 0.3, "press": [0, 1],
         "margin": 60.0},
    ]


def _compare(ctrl, built, t, state, active):
    s = built.system
    ev = s.blocks(state).with_active(active)
    tau = ctrl.compiled_torques(t, state, ev)
    plan, lam, kept = ctrl.last, ctrl.last_support_mu.copy(), ctrl.margin_kept
    ref = ctrl.reference(t, state, s.blocks(state).with_active(active))
    if tau is None:
        return None, False
    assert kept == ctrl.margin_kept
    scale = max(1.0, np.abs(ref).max())
    np.testing.assert_allclose(tau, ref, rtol=0, atol=1e-9 * scale)
    np.testing.assert_allclose(plan.mu, ctrl.last.mu, rtol=0,
                               atol=1e-9 * max(1.0, np.abs(ctrl.last.mu).max()))
    np.testing.assert_allclose(lam, ctrl.last_support_mu, rtol=0,
                               atol=1e-9 * max(1.0, np.abs(lam).max()))
    np.testing.assert_allclose(plan.a_o, ctrl.last.a_o, rtol=0, atol=1e-9)
    return float(np.abs(tau - ref).max() / scale), kept


def _states(built, rng):
    """States around the initial one: random joint and object velocities."""
    x0 = built.initial_state
    v = 0.05 * rng.standard_normal(built.system.nv)
    obj = type(x0.obj)(x0.obj.position, x0.obj.quaternion, 0.02 * rng.standard_normal(6))
    return type(x0)(x0.q, v, obj)


def test_the_kernel_equals_the_reference_in_every_phase(monkeypatch):
    """Every case served, and equal to the reference, its fallbacks included.

    Where no forces keep the margins both plan with zero margins (the phase ``hard`` asks
    60 N of two arms squeezing a box on its pivot); where no pushing forces make the wrench
    (the pusher released, the stop alone) the reference's bounded least squares
    (``lsq_linear``) and the kernel's (NNLS on the shifted forces) give the same forces.
    """
    from multiarm_pin.sim.stepper import Stepper

    bounded = []
    monkeypatch.setattr(fd, "lsq_linear", lambda *a, **k: bounded.append(t) or
                        _LSQ_LINEAR(*a, **k))

    built = _built()
    s, x0 = built.system, built.initial_state
    ctrl = make_controller("phased_pd", s, phases=_phases(built), margin=2.0,
                           support_margin=2.0)
    stepper = Stepper(s, None, "object_first", None)
    stepper.init_active(stepper.blocks_at(0.0, x0)[1], 1e-6)
    first = np.array(stepper.active[:s.n_arms, :s.N_max])
    every = np.array(s.contact_mask[:s.n_arms, :s.N_max])
    ctrl.compiled_torques(0.0, x0, s.blocks(x0).with_active(first))  # fixes the starts
    rng = np.random.default_rng(7)
    cases, least_squares = [], []
    for t in (0.0, 0.05, 0.4, 0.9, 1.3, 1.8, 2.2, 2.6, 2.7):
        for active in (first, every):
            bounded.clear()
            cases.append(_compare(ctrl, built, t, _states(built, rng), active))
            least_squares.append(bool(bounded))
    assert all(e is not None for e, _ in cases)
    assert any(least_squares)  # the released pusher: the reference's bounded least squares
    assert all(not kept for (_, kept), b in zip(cases, least_squares, strict=True) if b)
    assert sum(not kept for _, kept in cases) > sum(least_squares)  # "hard": zero margins
    assert max(e for e, _ in cases) < 1e-9


def test_the_kernel_reads_the_references_constants():
    """The kernel's copies of the reference's thresholds (the compiled layer imports nothing
    above it) are the reference's values."""
    from multiarm_pin._compiled import phased as kernel
    from multiarm_pin.dynamics.inverse_dynamics import RANK_TOL
    from multiarm_pin.sim.controllers import phased

    assert kernel.PRESSING_GAP == phased.PRESSING_GAP
    assert kernel.RANK_TOL == RANK_TOL
    assert kernel.BEST_EFFORT_SLACK == fd.BEST_EFFORT_SLACK


def test_best_effort_forces_are_the_least_norm_ones_at_the_cones_boundary():
    """A wrench that pushing forces make only with some of them at exactly 0 (the best-effort
    case): the smallest forces are found, not an arbitrary split, in the reference and the
    kernel alike. A box on four coplanar table corners under its weight: only the resultant
    (m g up through the centre) is decided; the smallest forces are m g / 4 each, and the
    lone side contact, asked for nothing, carries 0."""
    from multiarm_pin._compiled import phased as kernel

    mg = 4.0 * 9.81
    corners = np.array([[0.2, 0.15], [-0.2, 0.15], [-0.2, -0.15], [0.2, -0.15]])
    G = np.zeros((4, 6))  # unit normal forces up at the corners, about the COM (z = -0.1)
    for j, (x, y) in enumerate(corners):
        n, r = np.array([0.0, 0.0, 1.0]), np.array([x, y, -0.1])
        G[j] = np.concatenate([n, np.cross(r, n)])
    side = np.array([[1.0], [0.0], [0.0], [0.0], [0.1], [0.0]])  # a contact pushing +x
    W = np.hstack([side, G.T])
    unilateral = np.ones(5, dtype=bool)
    margins = np.zeros(5)
    y = np.array([0.0, 0.5 * mg, 0.0, 0.5 * mg, 0.0])  # diagonal corners: others at 0
    w = W @ y
    expected = np.array([0.0] + [mg / 4] * 4)
    slack = fd.BEST_EFFORT_SLACK * np.abs(w).max()
    ref = fd._min_norm_forces(W, w, unilateral, np.where(unilateral, margins - slack, 0.0),
                              1e-9, fd.internal_force_basis(W, "svd"))
    ref = np.maximum(ref, margins)
    out = np.empty(5)
    assert kernel.min_norm_forces(W, w, unilateral, margins - slack, out)
    out = np.maximum(out, margins)
    np.testing.assert_allclose(ref, expected, rtol=0, atol=1e-9 * mg)
    np.testing.assert_allclose(out, expected, rtol=0, atol=1e-9 * mg)
