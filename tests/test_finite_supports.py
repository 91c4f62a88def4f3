"""Supports of finite extent in simulation: off-edge events and landings against closed forms.

A support with ``extent: [lx, ly]`` is a rectangle of its plane: a point leaving it while it
touches loses its support (event ``off_edge``), a point outside never touches down. Systems
without arms (a box on a table) isolate the contact layer; every expected value is derived in
the test's docstring.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from closed_loop_cases import RUN_FIELDS, SCENARIOS

from multiarm_pin.app.scenario import build_scenario, load_scenario
from multiarm_pin.constraints import Support
from multiarm_pin.model.rigid_object import RigidObject
from multiarm_pin.sim import contact_events as ce
from multiarm_pin.sim.contact_loop import FINITE_SUPPORTS_NOTE, ContactLoop
from multiarm_pin.sim.disturbances import WrenchSchedule
from multiarm_pin.sim.simulation import simulate
from multiarm_pin.sim.stepper import Stepper
from multiarm_pin.system import MultiArmSystem

G = 9.81
A, B, C, M = 0.4, 0.3, 0.2, 2.0
"""The box: sides a (x), b (y), c (z) [m], mass [kg]."""


def _box_system(table: Support, position, twist=(0.0,) * 6):
    """The box (its 8 vertices the table's points) on ``table``, flat, at ``position``."""
    box = RigidObject.box([A, B, C], M)
    system = MultiArmSystem([], box, [], gravity=(0, 0, -G), supports=[table])
    return system, system.state(np.zeros(0), None, position, (0, 0, 0, 1), twist)


def _table(x_min: float, x_max: float, e: float = 0.0) -> Support:
    """The table z = 0 on ``x_min <= x <= x_max`` (3 m deep in y), the box's vertices on it."""
    V = RigidObject.box([A, B, C], M).shape.vertices
    return Support("table", [0.5 * (x_min + x_max), 0.0, 0.0], [0, 0, 1], V, e,
                   extent=[x_max - x_min, 3.0])


def _pitch(quaternion) -> float:
    """Rotation [rad] about +y of a rotation about y only (``[x, y, z, w]``)."""
    R = pin.Quaternion(np.asarray(quaternion)[[3, 0, 1, 2]]).toRotationMatrix()
    return float(np.arctan2(R[0, 2], R[0, 0]))


def _bottom(system) -> tuple[np.ndarray, np.ndarray]:
    """Rows of the bottom vertices (z = -c/2) at x = +a/2 (leading) and x = -a/2 (trailing)."""
    p = system.supports.supports[0].points
    bottom = p[:, 2] < 0
    return np.flatnonzero(bottom & (p[:, 0] > 0)), np.flatnonzero(bottom & (p[:, 0] < 0))


def test_a_box_pushed_over_the_edge_loses_support_at_sqrt_2md_over_f_and_tips():
    """Pushed by ``F`` along +x, the leading vertices pass the edge at ``t* = √(2 m d / F)``.

    The box rests flat on a frictionless table whose edge is ``d`` ahead of its leading
    (x = +a/2) vertices; ``F`` through the COM. Until ``t*`` it slides without turning:
    ``x(t) = F t² / (2 m)`` (all four bottom vertices press), so the leading vertices reach
    the edge when ``x = d``. They lose support then (event ``off_edge``, to 1e-9 s, far
    below the 1e-6 s asked, the location's tolerance being 1e-10 s).

    Right after, the box is at rest in rotation, held at its trailing edge (r = (-a/2, 0,
    -c/2) from the COM) by a vertical force ``N``: ``m z̈ = N - m g``, ``I α = (a/2) N``
    about +y (``I = m (a² + c²) / 12``) and the edge's normal acceleration ``z̈ + (a/2) α =
    0`` give ``N = g / (1/m + a² / (4 I))``, ``α = a N / (2 I)`` (> 0: it tips nose down,
    over the edge). ``t*`` is put 0.5 ms before a sample, where the pitch is ~4e-6 rad and
    ``ω`` ~0.02 rad/s: the recorded ``ω̇`` and trailing force equal the closed form to
    1e-4 (the terms neglected, of the pitch's and ``ω² r / g``'s order, are ~1e-5).
    Afterwards the pitch grows at every sample,
    the leading vertices never touch down and nothing penetrates the table.
    """
    F, dt, t_star = 4.0, 0.01, 0.2195
    d = F * t_star**2 / (2 * M)
    system, state = _box_system(_table(-1.0, A / 2 + d), [0.0, 0.0, C / 2])
    r = simulate(system, state, None, 0.32, dt, "rk4",
                 external_wrench=WrenchSchedule([(0.0, 10.0, [F, 0, 0, 0, 0, 0])]))
    lead, trail = _bottom(system)
    off = [e for e in r.events if e.kind == "off_edge" and e.row in lead]
    assert sorted(e.row for e in off) == sorted(lead)
    assert all(e.label == f"table[{e.row}]" and e.body == "table" for e in off)
    for e in off:
        assert abs(e.t - np.sqrt(2 * M * d / F)) < 1e-9, (e.t, t_star)
    assert not [e for e in r.events if e.kind == "touchdown"]
    assert all(e.t > t_star + 0.05 for e in r.events if e.row in trail)
    before = r.t < t_star
    np.testing.assert_allclose(r.object_position[before, 0], F * r.t[before] ** 2 / (2 * M),
                               rtol=1e-12, atol=1e-15)
    assert max(abs(_pitch(q)) for q in r.object_quaternion[before]) < 1e-12

    k = int(np.ceil(t_star / dt))  # the first sample after t*
    I_yy = M * (A * A + C * C) / 12
    N = G / (1 / M + A * A / (4 * I_yy))
    alpha = A * N / (2 * I_yy)
    np.testing.assert_allclose(r.object_acceleration[k, 4], alpha, rtol=1e-4)
    np.testing.assert_allclose(r.mu[k, 0, trail].sum(), N, rtol=1e-4)
    assert not r.active[k, 0, lead].any() and r.active[k, 0, trail].all()
    pitch = np.array([_pitch(q) for q in r.object_quaternion[k:]])
    assert pitch[0] > 0 and np.all(np.diff(pitch) > 0) and pitch[-1] > 0.1
    assert r.constraint_violation.max() < 1e-6
    assert r.warnings == [FINITE_SUPPORTS_NOTE]


def test_the_finite_supports_note_comes_once_and_only_after_a_step_off_the_rectangle(
        monkeypatch):
    """A box on a table 2 cm longer than it (1 cm each side of its bottom vertices).

    At rest it stays: no step has a point off the rectangle, the contact loop hands back
    none and the warnings are empty. Pushed along +x by ``F = 8 N`` (``ẍ = F / m = 4 m/s²``)
    its leading vertices pass the edge, 1 cm ahead, at ``t* = √(2 · 0.01 / 4)`` = 0.071 s;
    from then on every step is the stepper's (handed back with ``STAGE_OFF_RECTANGLE``, more
    than once, or left to it while a row is fallen past the edge), and the note comes
    exactly once.
    """
    from multiarm_pin._compiled.contact_loop import STAGE_OFF_RECTANGLE

    statuses = []
    run = ContactLoop.run

    def counted(self, *args):
        out = run(self, *args)
        statuses.append(self.last_status)
        return out

    monkeypatch.setattr(ContactLoop, "run", counted)
    F, gap = 8.0, 0.01
    system, state = _box_system(_table(-A / 2 - gap, A / 2 + gap), [0.0, 0.0, C / 2])
    rest = simulate(system, state, None, 0.15, 0.01, "rk4")
    assert statuses and STAGE_OFF_RECTANGLE not in statuses
    assert not rest.events and rest.warnings == []
    statuses.clear()
    pushed = simulate(system, state, None, 0.15, 0.01, "rk4",
                      external_wrench=WrenchSchedule([(0.0, 1.0, [F, 0, 0, 0, 0, 0])]))
    lead, _ = _bottom(system)
    off = [e for e in pushed.events if e.kind == "off_edge"]
    assert sorted(e.row for e in off) == sorted(lead)
    assert all(abs(e.t - np.sqrt(2 * M * gap / F)) < 1e-9 for e in off)
    assert statuses.count(STAGE_OFF_RECTANGLE) >= 2
    assert pushed.warnings == [FINITE_SUPPORTS_NOTE]


GRAZING = 5.0 * np.sqrt(2 * 0.05 / G) + 2.5e-4
"""[m] The thrown box's start whose leading vertices reach the plane's level 0.25 mm before
the table's edge: they enter the rectangle 50 µs later, 50 µm below its plane."""


@pytest.mark.parametrize(("gap", "lands"), [
    (0.05, "all"),       # over the table before the plane: all four bottom vertices land
    (0.30, "leading"),   # the trailing ones are still beside the table: they fall past it
    (0.70, "none"),      # below the table's top before its edge: nothing touches
    (GRAZING, "none"),   # just below it, in the same step: they do not land from below
])
def test_a_box_thrown_at_a_table_lands_only_where_it_is_over_it(gap, lands):
    """Thrown flat at ``v`` along +x from beside a table, its vertices land at ``√(2h/g)``.

    The box's bottom starts ``h`` above the plane z = 0, its leading vertices ``gap`` before
    the table's edge (x = 0), no rotation: every bottom vertex reaches the plane's level at
    ``t_h = √(2h/g)`` (0.101 s for h = 5 cm), when the leading ones have moved ``v t_h`` =
    0.505 m and the trailing ones are ``a`` behind. A vertex lands (event ``touchdown`` at
    ``t_h``, to the location's tolerance) iff it is over the table then; one beside it falls
    past the edge: no event, and its negative gap is no penetration (the recorded
    constraint violation stays at the active rows' drift). Gaps 0.05 m (trailing ones over
    the table by 0.055 m), 0.30 m (leading ones in by 0.205 m, trailing ones out by
    0.195 m), 0.70 m (leading ones 0.195 m short) and :data:`GRAZING` (leading ones at the
    plane's level 0.25 mm short of the edge, inside 50 µs later within the same step, 50 µm
    under the plane: fallen, not landing from below). By the end (0.2 s, 1 m further) some
    bottom vertex that did not land is over the table but below its plane (it came in under
    it): still no touchdown. Without a landing the box falls freely,
    ``z = z0 - g t² / 2``. (Only the bottom vertices are counted: after a one-sided landing
    the box tips back and a top vertex may land later, which is right.)
    """
    h, v = 0.05, 5.0
    t_h = np.sqrt(2 * h / G)
    system, state = _box_system(_table(0.0, 2.0), [-gap - A / 2, 0.0, h + C / 2],
                                [v, 0, 0, 0, 0, 0])
    r = simulate(system, state, None, 0.2, 0.01, "rk4")
    lead, trail = _bottom(system)
    bottom = [*lead, *trail]
    expected = {"all": bottom, "leading": list(lead), "none": []}[lands]
    down = [e for e in r.events if e.kind == "touchdown" and e.row in bottom]
    assert sorted(e.row for e in down) == sorted(expected)
    for e in down:
        assert abs(e.t - t_h) < 1e-6, (e.t, t_h)
        assert e.phi_dot == pytest.approx(-G * t_h, rel=1e-6)
    missed = sorted(set(bottom) - set(expected))
    end = r.contact_points[-1, 0, missed]
    assert not missed or np.any((end[:, 0] > 0.0) & (end[:, 2] < 0.0))  # one under the table
    assert r.constraint_violation.max() < 1e-6
    if lands == "none":
        assert not r.events and not r.active.any()
        np.testing.assert_allclose(r.object_position[:, 2], h + C / 2 - G * r.t**2 / 2,
                                   rtol=0, atol=1e-12)


def test_an_active_row_outside_its_rectangle_at_the_start_leaves_at_once():
    """A box half over the edge at t = 0: its outside vertices are not supported from t = 0."""
    system, state = _box_system(_table(-1.0, 0.0), [0.0, 0.0, C / 2])
    r = simulate(system, state, None, 0.02, 0.01, "rk4")
    lead, trail = _bottom(system)
    assert not r.active[0, 0, lead].any() and r.active[0, 0, trail].all()
    assert not [e for e in r.events if e.row in lead]
    assert _pitch(r.object_quaternion[-1]) > 0  # it tips over the edge at x = 0


def test_a_large_finite_support_changes_nothing_on_either_path():
    """A finite support whose points stay inside their rectangle changes nothing.

    The shipped ``box_on_table`` (a box bouncing on an infinite table, no extent) and the
    same box on a 100 m table, far from its edges: both are the compiled contact loop's
    (neither has the finite supports' note: no step has a point off the rectangle), and the
    finite table's run equals the infinite table's bit for bit (every recorded field, every
    event, the warnings), on the contact loop and on the Python stepper alike: the edge
    checks change nothing while every point is inside.
    """
    built = build_scenario(load_scenario(SCENARIOS / "box_on_table.yaml"), load_visuals=False)
    sim = built.scenario.simulation
    assert ContactLoop.for_run(Stepper(built.system, None, "auto", sim.baumgarte),
                               "rk4") is not None
    plane = built.system.supports.supports[0]
    big = Support(plane.name, plane.point, plane.normal, plane.points, plane.restitution,
                  extent=[100.0, 100.0])
    system = MultiArmSystem([], built.obj, [], gravity=built.system.gravity, supports=[big])
    assert ContactLoop.for_run(Stepper(system, None, "auto", sim.baumgarte), "rk4") is not None

    def run(s, loop):
        original = ContactLoop.for_run
        try:
            if not loop:
                ContactLoop.for_run = classmethod(lambda cls, *a: None)
            return simulate(s, built.initial_state, None, 0.3, sim.dt, "rk4",
                            baumgarte=sim.baumgarte)
        finally:
            ContactLoop.for_run = original

    shipped = run(built.system, True)
    finite_loop = run(system, True)
    assert FINITE_SUPPORTS_NOTE not in finite_loop.warnings
    assert finite_loop.warnings == shipped.warnings
    assert [e.as_dict() for e in finite_loop.events] == [e.as_dict() for e in shipped.events]
    for field in (*RUN_FIELDS, "active"):
        np.testing.assert_array_equal(getattr(finite_loop, field), getattr(shipped, field),
                                      err_msg=field)
    infinite = run(built.system, False)
    finite = run(system, False)
    assert len(infinite.events) > 5
    assert [e.as_dict() for e in finite.events] == [e.as_dict() for e in infinite.events]
    for field in (*RUN_FIELDS, "active"):
        np.testing.assert_array_equal(getattr(finite, field), getattr(infinite, field),
                                      err_msg=field)
    assert ce.EDGE_TIME_TOLERANCE < 1e-6  # the off-edge times asked for (issue 23)


def test_a_point_below_the_plane_beside_the_table_is_no_initial_penetration():
    """The initial-state check counts only the points over the rectangle.

    The box's bottom 5 cm below the table's plane: beside the table (x from 1 to 2 m) that is
    no penetration; half over it (x from -1 to 0), its two bottom vertices over the table are.
    """
    from multiarm_pin.exceptions import InitialGapError

    beside, state = _box_system(_table(1.0, 2.0), [0.0, 0.0, C / 2 - 0.05])
    beside.check_supports(state)
    over, state = _box_system(_table(-1.0, 0.0), [0.0, 0.0, C / 2 - 0.05])
    with pytest.raises(InitialGapError, match=r"2 point\(s\) below the plane"):
        over.check_supports(state)


def test_a_box_sliding_down_a_finite_ramp_leaves_its_lower_edge_at_the_closed_form_time():
    """On a frictionless ramp of slope θ the box slides at ``g sin θ``, off at ``√(2d/(g sin θ))``.

    The ramp's normal is ``n = (sin θ, 0, cos θ)``, its downhill direction ``e = (cos θ, 0,
    -sin θ)``, the rectangle's x axis given as ``[2, 0, 0.3]`` (any direction of the x-z
    plane projects onto ``±e``); the box lies on it (rotated by θ about y), its downhill
    vertices ``d`` before the lower edge. Gravity's component along the ramp is ``g sin θ``,
    the normal forces balance the rest and the box slides without turning, so the downhill
    vertices reach the edge at ``t* = √(2d / (g sin θ))``; the uphill ones stay on.
    """
    theta, d = np.radians(20.0), 0.05
    n = np.array([np.sin(theta), 0.0, np.cos(theta)])
    e = np.array([np.cos(theta), 0.0, -np.sin(theta)])
    s0 = 0.0  # the box's centre along e from the ramp's centre line
    edge = s0 + A / 2 + d
    V = RigidObject.box([A, B, C], M).shape.vertices
    length = 1.0 + edge
    ramp = Support("ramp", (edge - 0.5 * length) * e, n, V, extent=[length, 2.0],
                   x_axis=[2.0, 0.0, 0.3])
    np.testing.assert_allclose(ramp.x_axis, e, atol=1e-15)
    box = RigidObject.box([A, B, C], M)
    system = MultiArmSystem([], box, [], gravity=(0, 0, -G), supports=[ramp])
    state = system.state(np.zeros(0), None, s0 * e + (C / 2) * n,
                         (0.0, np.sin(theta / 2), 0.0, np.cos(theta / 2)))
    r = simulate(system, state, None, 0.2, 0.01, "rk4")
    p = ramp.points
    down = np.flatnonzero((p[:, 2] < 0) & (p[:, 0] > 0))
    t_star = np.sqrt(2 * d / (G * np.sin(theta)))
    assert sorted(ev.row for ev in r.events) == sorted(down)
    for ev in r.events:
        assert ev.kind == "off_edge" and abs(ev.t - t_star) < 1e-9, (ev.t, t_star)
    before = r.t < t_star
    np.testing.assert_allclose(r.object_position[before] @ e,
                               0.5 * G * np.sin(theta) * r.t[before] ** 2, atol=1e-12)


def test_a_run_off_the_edge_has_a_replay_page(tmp_path):
    """The replay takes every kind of contact event: ``off_edge`` markers on its timeline
    (the page's events are its trajectory's, kind by kind)."""
    from multiarm_pin.app.replay import write_replay_html
    from multiarm_pin.app.run_results import replay_parts, system_trajectory_arrays

    F, t_star = 4.0, 0.2195
    d = F * t_star**2 / (2 * M)
    system, state = _box_system(_table(-1.0, A / 2 + d), [0.0, 0.0, C / 2])
    r = simulate(system, state, None, 0.3, 0.01, "rk4",
                 external_wrench=WrenchSchedule([(0.0, 10.0, [F, 0, 0, 0, 0, 0])]))
    assert any(e.kind == "off_edge" for e in r.events)
    traj = system_trajectory_arrays(system, r)
    arms, obj, contacts = replay_parts([], system.obj, traj)
    assert [e.kind for e in contacts.events] == [e.kind for e in r.events]
    page = write_replay_html(tmp_path / "replay.html", arms, obj, traj["t"], contacts)
    assert page.stat().st_size > 0
