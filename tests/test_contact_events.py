"""Unilateral contacts in simulation: closed forms through the whole event-driven path.

Systems without arms (an object on supports) isolate the contact layer; the grasp tests use
the two-gripper scenario. Every expected value is derived in the test's docstring.
"""

from __future__ import annotations

import numpy as np
import pytest

from multiarm_pin.constraints import Support
from multiarm_pin.exceptions import InputError
from multiarm_pin.model.rigid_object import RigidObject
from multiarm_pin.sim.disturbances import WrenchSchedule
from multiarm_pin.sim.simulation import simulate
from multiarm_pin.system import MultiArmSystem

G = 9.81


def _box_on_table(size, mass, points, e=0.0, height=0.0, quaternion=(0, 0, 0, 1)):
    """A box on the plane z = 0 through the given object-frame points, COM raised by height."""
    box = RigidObject.box(size, mass)
    system = MultiArmSystem([], box, [], gravity=(0, 0, -G),
                            supports=[Support("table", [0, 0, 0], [0, 0, 1], points, e)])
    z = -min(float((np.asarray(box.shape.vertices) @ np.eye(3)[2]).min()), 0.0) + height
    return system, box, system.state(np.zeros(0), None, [0.0, 0.0, z], quaternion)


@pytest.mark.parametrize("ratio", [0.8, 1.25])
def test_box_on_two_supports_under_a_torque(ratio):
    """Both sides press iff τ <= W a / 2; beyond, one lifts and the other's force is rigid-body.

    Box of width ``a`` (x), depth ``b`` (y), height ``c``; its bottom rests on two
    frictionless line supports at ``x = ±a/2`` (two vertices each, the plane z = 0); weight
    ``W = m g``; a torque ``τ`` about +y (it presses the +x side down). Statics, with side
    totals ``F_L`` (x = -a/2) and ``F_R`` (x = +a/2): ``F_L + F_R = W`` and the moment about
    the COM ``τ + (a/2)(F_L - F_R) = 0``, so ``F_L = W/2 - τ/a`` and ``F_R = W/2 + τ/a``:
    both push iff ``τ <= W a / 2``. Beyond, the left side lifts (``μ = 0``, ``φ̈ > 0``) and
    the box pivots on the right edge at rest: with ``z̈ = (F_R - W)/m``,
    ``I α = τ - (a/2) F_R`` (``I = m (a² + c²)/12``) and the edge's normal acceleration
    ``z̈ - (a/2) α = 0``: ``F_R = (W/m + a τ / (2 I)) / (1/m + a² / (4 I))``.
    Cases at 0.8 and 1.25 times the threshold, so the verdict has a 20 % margin.
    """
    a, b, c, m = 0.6, 0.4, 0.2, 3.0
    V = np.array([[sx * a / 2, sy * b / 2, -c / 2] for sx in (-1, 1) for sy in (-1, 1)])
    system, box, state = _box_on_table([a, b, c], m, V)
    W = m * G
    tau = ratio * W * a / 2
    r = simulate(system, state, None, 0.002, 0.002, "rk4",
                 external_wrench=WrenchSchedule([(0.0, 1.0, [0, 0, 0, 0, tau, 0])]))
    mu = r.mu[0, 0, :4]  # the support block (block 0: no arms), rows in the order of V
    left, right = mu[:2].sum(), mu[2:].sum()
    if ratio < 1:
        assert not r.events
        np.testing.assert_allclose([left, right], [W / 2 - tau / a, W / 2 + tau / a],
                                   rtol=1e-10)
    else:
        assert {(e.kind, e.row) for e in r.events if e.t == 0.0} == {("separation", 0),
                                                                    ("separation", 1)}
        I_yy = m * (a * a + c * c) / 12
        F_R = (W / m + a * tau / (2 * I_yy)) / (1 / m + a * a / (4 * I_yy))
        assert left == 0.0
        np.testing.assert_allclose(right, F_R, rtol=1e-10)
        assert not r.active[0, 0, :2].any() and r.active[0, 0, 2:4].all()


@pytest.mark.parametrize("e", [0.0, 0.5, 1.0])
def test_body_dropped_flat_rebounds_with_e_v_to_e2_h(e):
    """Dropped flat from height h: touchdown at √(2h/g), speed v = √(2gh), rebound e v, e² h.

    A free fall (no rotation) reaches the table at ``t = √(2h/g)`` with ``v = √(2 g h)``; the
    four bottom vertices touch at once (four redundant rows: the forces are not unique, the
    motion is). Newton's law ``φ̇⁺ = -e φ̇⁻`` for the flat body gives an upward speed ``e v``
    and, by energy in the following free flight, an apex ``e² h`` above the rest height
    (computed from any sample of that flight as ``z + ż² / (2 g)``, exact for a ballistic
    arc). With e = 0 the box stays on the table with the weight shared by the rows.
    Tolerances: the touchdown is located to a gap within ``GAP_TOLERANCE`` = 1e-9 m, i.e.
    a time within 1e-9 m / v and a speed within ``g 1e-9 / v`` (relative ``g 1e-9 / v² ≈
    1e-8``); the apex, quadratic in the speed, within 2e-8 relative.
    """
    h = 0.05
    size = [0.4, 0.3, 0.2]
    V = RigidObject.box(size, 2.0).shape.vertices
    system, box, state = _box_on_table(size, 2.0, V[V[:, 2] < 0], e, height=h)
    rest = 0.1
    r = simulate(system, state, None, 0.16, 0.004, "rk4")
    t_hit, v = np.sqrt(2 * h / G), np.sqrt(2 * G * h)
    hits = [ev for ev in r.events if ev.kind == "touchdown"]
    first = [ev for ev in hits if abs(ev.t - hits[0].t) < 1e-12]
    assert sorted(ev.row for ev in first) == [0, 1, 2, 3]
    for ev in first:
        assert abs(ev.t - t_hit) < 1e-9
        np.testing.assert_allclose(ev.phi_dot, -v, rtol=2e-8)
        np.testing.assert_allclose(ev.phi_dot_after, e * v, rtol=2e-8, atol=1e-12)
        assert ev.rebound == (e > 0)
    k = np.searchsorted(r.t, t_hit) + 2  # a sample after the impact, before any other event
    z, zd = r.object_position[k, 2], r.object_twist[k, 2]
    if e == 0:
        assert abs(z - rest) < 1e-9 and abs(zd) < 1e-9
        np.testing.assert_allclose(r.mu[-1, 0, :4].sum(), 2.0 * G, rtol=1e-9)
    else:
        np.testing.assert_allclose(z + zd * zd / (2 * G) - rest, e * e * h, rtol=5e-8)
    np.testing.assert_allclose(r.object_twist[k, [0, 1, 3, 4, 5]], 0.0, atol=1e-12)


def test_tilted_rod_hitting_the_floor():
    """Lower end of a tilted falling rod hits a frictionless floor: v⁺ and ω⁺ in closed form.

    Rod (a thin box) of length L, thickness t, mass m, its axis tilted by θ about +y; it
    falls without rotation from rest; the contact point is the lower end
    ``r = (L/2)(cos θ, 0, -sin θ)`` from the COM, normal +z, so ``G = [n; r × n]`` with
    ``r × n = (0, -d, 0)``, ``d = (L/2) cos θ``, and ``φ̇ = ż - d ω_y``. At touchdown
    ``φ̇⁻ = -v``, ``v = √(2 g h)``. An impulse P along +z gives ``Δż = P/m`` and
    ``Δω_y = -d P / I`` (``I = m (L² + t²)/12``), so ``φ̇⁺ = -v + P (1/m + d²/I) = e v``:
    ``P = (1 + e) v / (1/m + d²/I)``, ``ż⁺ = -v + P/m``, ``ω_y⁺ = -d P / I``, the horizontal
    velocity and the other rates stay 0. After the impact the row leaves (e > 0) and the rod
    flies freely: ``ω`` constant and ``ż`` decreasing by ``g`` per second. Tolerance 2e-8
    relative: the touchdown is located to within 1e-9 m of gap (``v`` within ``g 1e-9 / v``).
    """
    L, th, m, theta, e, h = 1.0, 0.04, 1.5, 0.5, 0.5, 0.03
    end = np.array([L / 2, 0.0, 0.0])
    quat = np.array([0.0, np.sin(theta / 2), 0.0, np.cos(theta / 2)])
    rod = RigidObject.box([L, th, th], m)
    system = MultiArmSystem([], rod, [], gravity=(0, 0, -G),
                            supports=[Support("floor", [0, 0, 0], [0, 0, 1], [end], e)])
    z0 = (L / 2) * np.sin(theta) + h
    state = system.state(np.zeros(0), None, [0.0, 0.0, z0], quat)
    dt = 0.004
    r = simulate(system, state, None, 0.1, dt, "rk4")
    (ev,) = [x for x in r.events if x.kind == "touchdown"][:1]
    v = np.sqrt(2 * G * h)
    d = (L / 2) * np.cos(theta)
    I_yy = m * (L * L + th * th) / 12
    P = (1 + e) * v / (1 / m + d * d / I_yy)
    assert abs(ev.t - np.sqrt(2 * h / G)) < 1e-9
    np.testing.assert_allclose(ev.impulse, P, rtol=2e-8)
    np.testing.assert_allclose(ev.phi_dot_after, e * v, rtol=2e-8)
    k = np.searchsorted(r.t, ev.t) + 1
    tw = r.object_twist[k]
    np.testing.assert_allclose(tw[4], -d * P / I_yy, rtol=2e-8)
    np.testing.assert_allclose(tw[2], -v + P / m - G * (r.t[k] - ev.t), rtol=2e-8)
    np.testing.assert_allclose(tw[[0, 1, 3, 5]], 0.0, atol=1e-12)


def test_resting_box_with_redundant_vertices_stays_and_carries_its_weight():
    """Eight vertices of which four touch: no event, zero motion, vertical forces sum to m g."""
    size = [0.4, 0.3, 0.2]
    V = RigidObject.box(size, 2.0).shape.vertices
    system, box, state = _box_on_table(size, 2.0, V)
    r = simulate(system, state, None, 0.05, 0.005, "rk4")
    assert not r.events
    assert np.abs(r.object_position - r.object_position[0]).max() < 1e-12
    np.testing.assert_allclose(r.mu[:, 0, :8].sum(axis=1), 2.0 * G, rtol=1e-10)
    assert r.active[0, 0].sum() == 4  # only the bottom four touch at t = 0


def test_rk45_with_unilateral_contacts_is_refused():
    size = [0.4, 0.3, 0.2]
    V = RigidObject.box(size, 2.0).shape.vertices
    system, box, state = _box_on_table(size, 2.0, V)
    with pytest.raises(InputError, match="not event-aware"):
        simulate(system, state, None, 0.01, 0.005, "rk45")


class _RampWrench(WrenchSchedule):
    """External wrench ``w(t) = w0 + t w1`` at the COM, world axes [N, N m] (a ramp)."""

    def __init__(self, w0, w1):
        super().__init__([(0.0, 1e9, np.zeros(6))])
        self.w0, self.w1 = np.asarray(w0, float), np.asarray(w1, float)

    def __call__(self, t: float) -> np.ndarray:
        return self.w0 + t * self.w1


def test_separation_time_of_a_box_under_a_torque_ramp_is_located():
    """Under ``τ(t) = c t`` about +y the left side lifts exactly at ``t* = W a / (2 c)``.

    Same box and supports as :func:`test_box_on_two_supports_under_a_torque`: both sides
    press iff ``τ <= W a / 2`` (``F_L = W/2 - τ/a``), and before that the box does not move,
    so ``F_L(t) = W/2 - c t / a`` vanishes at ``t* = W a / (2 c)``. ``t*`` is put between
    grid points (0.0123 s with dt = 5 ms); the separation must be recorded within
    ``SEPARATION_TIME_TOLERANCE`` (1e-10 s, so 1e-9 s here with the integrator's round-off)
    of ``t*``, far below dt, for both left rows, and no other event.
    """
    a, b, c, m = 0.6, 0.4, 0.2, 3.0
    V = np.array([[sx * a / 2, sy * b / 2, -c / 2] for sx in (-1, 1) for sy in (-1, 1)])
    system, box, state = _box_on_table([a, b, c], m, V)
    W = m * G
    t_star = 0.0123
    rate = W * a / (2 * t_star)
    dt = 0.005
    r = simulate(system, state, None, 0.03, dt, "rk4",
                 external_wrench=_RampWrench(np.zeros(6), [0, 0, 0, 0, rate, 0]))
    assert sorted((e.kind, e.row) for e in r.events) == [("separation", 0), ("separation", 1)]
    for e in r.events:
        assert abs(e.t - t_star) < 1e-9, (e.t, t_star)
    k = int(np.ceil(t_star / dt))  # first sample after t*
    assert not r.active[k, 0, :2].any() and r.active[k, 0, 2:4].all()
    assert r.active[k - 1, 0, :4].all()
    # before t*, the left side's force is the closed form
    np.testing.assert_allclose(r.mu[k - 1, 0, :2].sum(), W / 2 - rate * r.t[k - 1] / a,
                               rtol=1e-9)


def test_body_pressed_by_a_decaying_force_separates_when_the_force_vanishes():
    """Pressed by ``f_z(t) = -P + c t`` (plus its weight), the box lifts at ``(W + P) / c``.

    A box flat on a table (four bottom vertices), pushed down by ``P - c t``. At rest the
    table's total force is ``W + P - c t`` (vertical balance), zero at ``t* = (W + P)/c``;
    afterwards the net force ``c (t - t*)`` is upward and all four rows lift together.
    With ``t*`` between grid points, every row's separation time equals ``t*`` to 1e-9 s,
    and afterwards the box rises as ``z - z0 = c (t - t*)³ / (6 m)``.
    """
    a, b, c, m = 0.6, 0.4, 0.2, 2.0
    V = np.array([[sx * a / 2, sy * b / 2, -c / 2] for sx in (-1, 1) for sy in (-1, 1)])
    system, box, state = _box_on_table([a, b, c], m, V)
    W, P = m * G, 5.0
    t_star = 0.0217
    rate = (W + P) / t_star
    r = simulate(system, state, None, 0.04, 0.005, "rk4",
                 external_wrench=_RampWrench([0, 0, -P, 0, 0, 0], [0, 0, rate, 0, 0, 0]))
    assert sorted(e.row for e in r.events if e.kind == "separation") == [0, 1, 2, 3]
    assert all(e.kind == "separation" for e in r.events)
    for e in r.events:
        assert abs(e.t - t_star) < 1e-9, (e.t, t_star)
    z0 = state.obj.position[2]
    after = r.t > t_star
    np.testing.assert_allclose(r.object_position[after, 2] - z0,
                               rate * (r.t[after] - t_star) ** 3 / (6 * m), rtol=1e-6,
                               atol=1e-12)
