"""Physics of whole simulations, each against a law or an independent computation.

What is checked and why (the arm bases are fixed to the world, so the total momentum of
arms + object is NOT conserved: the bases push on the arms):
- energy: with τ = 0, no gravity, no Baumgarte, the constraints are ideal (workless), so
  the total kinetic energy is conserved; the rk4 error shrinks ~16x when dt halves;
- the object's momentum changes by exactly the integral of gravity plus the contact wrenches
  the solver reports (Newton-Euler of the object alone, integrated by Simpson's rule);
- Baumgarte keeps the gaps below 1e-6 m over 10 s of two UR5s welded to a box;
- object-level control holds a box still and the contact wrenches add up to its weight;
- force distribution keeps every fingertip force >= margin on a 7-contact form-closure grasp.
"""

import numpy as np
import pytest
from system_builders import build_system, moving_state

from multiarm_pin.dynamics.force_distribution import distribute_forces
from multiarm_pin.grasp.form_closure import form_closure
from multiarm_pin.sim.controllers import make_controller
from multiarm_pin.sim.simulation import simulate

ZERO_G = (0.0, 0.0, 0.0)


def energy_error(result):
    E = result.kinetic_energy
    return np.abs(E - E[0]).max() / E[0]


def test_kinetic_energy_conserved_without_gravity_and_torque():
    rng = np.random.default_rng(7)
    system, state = build_system(["ur5", "panda"], ["weld", "revolute"], rng, gravity=ZERO_G)
    state = moving_state(system, state, rng, speed=2.0)
    coarse = simulate(system, state, None, 0.4, 0.02, "rk4")
    fine = simulate(system, state, None, 0.4, 0.01, "rk4")
    e1, e2 = energy_error(coarse), energy_error(fine)
    assert np.abs(coarse.v).max() > 1.0  # a real motion
    assert e1 / e2 > 10.0  # fourth order: ~16
    assert e2 < 1e-5
    r45 = simulate(system, state, None, 0.4, 0.02, "rk45")
    assert energy_error(r45) < 1e-7
    eu1 = energy_error(simulate(system, state, None, 0.4, 0.004, "semi_implicit"))
    eu2 = energy_error(simulate(system, state, None, 0.4, 0.002, "semi_implicit"))
    assert 1.5 < eu1 / eu2 < 3.0  # first order
    # the constraints did no work: the violation stays tiny without Baumgarte
    assert fine.constraint_violation.max() < 1e-6


def simpson(y, dt):
    """Integral over the whole grid of samples y (T, ...) with T odd."""
    assert len(y) % 2 == 1
    w = np.ones(len(y))
    w[1:-1:2], w[2:-1:2] = 4.0, 2.0
    return dt / 3.0 * np.tensordot(w, y, axes=1)


def test_object_momentum_changes_by_the_integral_of_the_wrenches():
    rng = np.random.default_rng(8)
    system, state = build_system(["ur5", "ur5"], ["weld", "spherical"], rng)
    state = moving_state(system, state, rng, speed=1.0)
    dt = 0.002
    r = simulate(system, state, make_controller("joint_pd", system, kp=50.0, kd=5.0), 0.3, dt,
                 "rk4", baumgarte=(5.0, 5.0))
    m, g = system.obj.mass, system.gravity
    # contact wrench on the object about its COM (world) = Σ G_objectᵀ μ = Σ [n; r × n] μ
    f = np.einsum("tnk,tnki->ti", r.mu, r.normals)
    arm = r.contact_points - r.object_position[:, None, None, :]
    moment = np.einsum("tnk,tnki->ti", r.mu, np.cross(arm, r.normals))
    assert np.abs(f).max() > 10.0
    # linear: m Δẋ = ∫ (m g + f) dt
    lin = m * (r.object_twist[-1, :3] - r.object_twist[0, :3])
    np.testing.assert_allclose(lin, simpson(m * g + f, dt), rtol=1e-6, atol=1e-6 * m)
    # angular about the world origin: L = I_w ω + x × m ẋ, dL/dt = x × (m g + f) + moment
    rot = [system.obj.inertia_world(r.state(k).obj.rotation) for k in range(len(r.t))]
    L = np.einsum("tij,tj->ti", np.array(rot), r.object_twist[:, 3:]) + np.cross(
        r.object_position, m * r.object_twist[:, :3])
    torque = np.cross(r.object_position, m * g + f) + moment
    np.testing.assert_allclose(L[-1] - L[0], simpson(torque, dt), rtol=1e-6, atol=1e-6)


def two_ur5_box(gravity=(0.0, 0.0, -9.81)):
    return build_system(["ur5", "ur5"], ["weld", "weld"], None, gravity=gravity, mass=5.0)


def test_baumgarte_keeps_gaps_below_a_micrometre_for_ten_seconds():
    system, state = two_ur5_box()
    r = simulate(system, state, make_controller("joint_pd", system, kp=200.0, kd=20.0), 10.0,
                 0.005, "rk4", baumgarte=(5.0, 5.0))
    assert r.t[-1] == pytest.approx(10.0)
    assert np.abs(r.object_position - r.object_position[0]).max() > 1e-3  # it moved (sagged)
    assert r.constraint_violation.max() < 1e-6


def test_object_level_control_holds_the_box_and_contacts_carry_its_weight():
    system, state = two_ur5_box()
    r = simulate(system, state, make_controller("object_pd", system), 1.0, 0.005, "rk4",
                 baumgarte=(5.0, 5.0))
    assert np.abs(r.object_position - r.object_position[0]).max() < 1e-6
    assert np.abs(r.object_twist).max() < 1e-6
    m = system.obj.mass
    for k in range(0, len(r.t), 20):
        ev = system.blocks(r.state(k))
        wrench = np.einsum("nik,nk->i", ev.blocks.W_o, r.mu[k])
        np.testing.assert_allclose(wrench, [0, 0, m * 9.81, 0, 0, 0], atol=1e-6 * m * 9.81)
    # without the object weight in the control, gravity compensation alone lets it fall
    g = simulate(system, state, make_controller("gravity_compensation", system), 0.2, 0.005)
    assert g.object_position[-1, 2] < g.object_position[0, 2] - 1e-3


SEVEN_CONTACTS = [  # a form-closure grasp of the 0.4 x 0.3 x 0.2 box, split over 3 arms
    [("+y", [-0.09, 0.15, -0.02]), ("+x", [0.2, 0.04, -0.06]), ("-y", [-0.02, -0.15, -0.05])],
    [("-x", [-0.2, 0.11, -0.06]), ("-z", [0.06, 0.0, -0.1])],
    [("+z", [0.02, -0.01, 0.1]), ("-z", [-0.04, -0.06, -0.1])],
]


def test_force_distribution_keeps_seven_fingertip_contacts_pushing():
    specs = [{"type": "fingertips", "contacts": c, "radius": 0.01} for c in SEVEN_CONTACTS]
    system, state = build_system(["ur5", "ur5", "ur5"], specs, None)
    ev = system.blocks(state)
    W = ev.blocks.stacked_W_o()
    assert W.shape == (6, 7) and form_closure(W).form_closure
    weight = -ev.blocks.h_o
    # the least-norm forces alone would pull on some contact: the margin is what matters
    assert np.linalg.lstsq(W, weight, rcond=None)[0].min() < 0
    margin = 2.0
    fd = distribute_forces(ev.blocks, weight, system.unilateral, margin)
    assert fd.min_unilateral >= margin - 1e-9
    np.testing.assert_allclose(W @ fd.mu_flat, weight, atol=1e-9)
    ctrl = make_controller("object_pd", system, margin=margin)
    r = simulate(system, state, ctrl, 0.5, 0.005, "rk4", baumgarte=(5.0, 5.0))
    mu = r.mu[:, r.unilateral]
    assert mu.shape == (len(r.t), 7)
    assert mu.min() >= margin - 1e-6
    assert not r.warnings
    assert np.abs(r.object_position - r.object_position[0]).max() < 1e-6
