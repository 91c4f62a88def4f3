"""Location of contact events inside an integration step: separations, off-edge, touchdowns.

All are roots of a scalar function of the step fraction ``θ ∈ [0, 1]`` (the integration
re-run from the step's start with step ``θ h`` and the active set unchanged), found by one
Illinois (modified regula falsi) iteration, :func:`illinois`: the separation search on the
release function of the rows that let go (:func:`release`), the off-edge search on the
smallest edge margin of the active rows of finite supports, the touchdown search on the
smallest watched gap. They differ in their stopping test, their bisection safeguard and what
they carry along; the rules (tolerances, bands) are those of
:mod:`multiarm_pin.sim.contact_events`. The stepper
(:class:`~multiarm_pin.sim.stepper.Stepper`) calls :func:`locate_separation`,
:func:`locate_off_edge` and :func:`locate_touchdown` and applies the events.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

from multiarm_pin.sim import contact_events as ce
from multiarm_pin.system import ContactRows, MultiArmSystem, SystemState


class Stepping(Protocol):
    """What the searches use of the stepper that calls them.

    :class:`~multiarm_pin.sim.stepper.Stepper` (which imports this module): its system, its
    active set (``(B, R)`` bool), its finite-support rows, and these methods.
    """

    system: MultiArmSystem
    unilateral: bool
    active: np.ndarray
    finite_rows: np.ndarray

    def evaluate(self, t: float, state: SystemState) -> tuple:
        """``(solution, evaluation, tau, rows)`` at ``(t, state)``, the current active set."""

    def step(self, integrator: str, t: float, state: SystemState, sol: Any,
             h: float) -> SystemState:
        """One step of size ``h`` [s] from ``(t, state)`` whose solution is ``sol``."""

    def edge_margins(self, state: SystemState) -> np.ndarray:
        """(B, R) edge margins [m] at a state."""

    def gaps(self, state: SystemState) -> np.ndarray:
        """(B, R) gaps [m] of every row at a state."""

    def rows_at(self, t: float, state: SystemState) -> ContactRows:
        """The contact rows at a state."""


RESTING_RELEASE = 1e-300
"""Value of :func:`release` for a group whose rows carry no force and none lifts: positive
(not released), the smallest there is, so that it guides the secant as a zero force would."""

MAX_ITERATIONS = 200
"""Iterations of :func:`illinois` at the most (a safety cap; the bracket halves far sooner)."""


def illinois(
    f: Callable[[float], tuple[float, Any]],
    lo: float,
    f_lo: float,
    hi: float,
    f_hi: float,
    narrow: Callable[[float, float], bool],
    *,
    hi_payload: Any = None,
    band: float | None = None,
    bisect_every: int = 0,
) -> tuple[float, Any]:
    """Root of ``f`` on the bracket ``[lo, hi]`` (``f_lo > 0 >= f_hi``) by the Illinois method.

    Each iterate is the secant point of the bracket, or its midpoint when the secant point
    leaves the open bracket or (``bisect_every = m > 0``) on every ``m``-th iterate; ``f`` is
    evaluated there and the iterate replaces the end of the same sign. When the same end is
    kept twice in a row, the other end's value is halved (Illinois), so the bracket shrinks
    from both sides.

    Args:
        f: ``θ -> (value, payload)``: the function and what goes with its value (a state, a
            solution...), carried along to the answer.
        lo: lower end of the bracket.
        f_lo: value at ``lo`` (> 0).
        hi: upper end of the bracket.
        f_hi: value at ``hi`` (<= 0).
        narrow: ``(lo, hi) -> bool``, True when the bracket is short enough.
        hi_payload: the payload at ``hi`` (returned if ``hi`` is the answer and never moved).
        band: None: the answer is the upper end ``hi`` (the first ``θ`` known past the root),
            returned with its payload as soon as the bracket is narrow. A number: the answer
            is the last iterate, returned as soon as ``|value| <= band`` or when it was
            computed from a narrow bracket.
        bisect_every: every ``bisect_every``-th iterate is a bisection (0: only when the
            secant point leaves the bracket).

    Returns:
        ``(θ, payload)`` of the answer (after :data:`MAX_ITERATIONS` iterations, the current
        one).
    """
    side = 0
    theta, payload = hi, hi_payload
    for it in range(MAX_ITERATIONS):
        short = narrow(lo, hi)
        if short and band is None:
            break
        theta = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
        if (bisect_every and it % bisect_every == bisect_every - 1) or not (lo < theta < hi):
            theta = 0.5 * (lo + hi)
        value, payload = f(theta)
        if band is not None and (abs(value) <= band or short):
            return theta, payload
        if value > 0.0:
            lo, f_lo = theta, value
            if side == 1:
                f_hi *= 0.5
            side = 1
        else:
            hi, f_hi, hi_payload = theta, value, payload
            if side == -1:
                f_lo *= 0.5
            side = -1
    if band is None:
        return hi, hi_payload
    return theta, payload


def release(sol, rows: np.ndarray) -> float:
    """Signed release function of the ``rows`` group: > 0 while none lifts, < 0 after.

    ``-max φ̈_k`` [m/s²] over the rows that carry no force (``μ_k = 0``) and lift
    (``φ̈_k > LIFT_ACCELERATION``) if any; otherwise the group's total force ``Σ μ_k``
    [N] (> 0). For an active unilateral row the LCP gives either ``μ > 0, φ̈ = 0`` or
    ``μ = 0, φ̈ >= 0``, so the sign changes exactly when the first row of the group lets
    go; the total force (unique even when the rows are redundant, e.g. one edge of a box
    on two vertices, where a single row's ``μ`` is not) only guides the secant. A group that
    carries no force and does not lift (a contact resting with zero force) is not released:
    the value is then :data:`RESTING_RELEASE` > 0.
    """
    lift = rows & (sol.mu <= 0.0) & (sol.phi_dd > ce.LIFT_ACCELERATION)
    if lift.any():
        return -float(sol.phi_dd[lift].max())
    # > 0 even when the group's forces vanish (a row with no planned force, resting): only
    # a lift releases; a zero here would read as "released" and stop the search early
    return max(float(sol.mu[rows].sum()), RESTING_RELEASE)


def locate_separation(stepper: Stepping, integrator: str, t: float, state: SystemState, sol,
                      h: float, new: SystemState, t_end: float):
    """The first separation inside a step, or None.

    Rows that separate inside the step: active unilateral rows that, at the step's end,
    have ``μ = 0`` and lift (``φ̈ > SEPARATION_ACCELERATION``, the same test as at a
    step's start), at least one of which pushed at its start (``μ > 0``; otherwise the
    test at the next step's start takes them). The time is the root of :func:`release` on
    ``θ ∈ [0, 1]``, located by :func:`illinois` (every third iterate a bisection) to a
    bracket shorter than ``SEPARATION_TIME_TOLERANCE``.

    Args:
        stepper: the stepper (its active set and evaluations).
        integrator: the integrator's name.
        t: the step's start [s].
        state: the state at ``t``.
        sol: its solution.
        h: the step [s].
        new: the state at ``t_end``.
        t_end: the step's end time [s].

    Returns:
        ``(θ, state at t + θ h, (B, R) mask of those rows with μ = 0 there)`` (θ the
        bracket's upper end, where the first rows have let go), or None.
    """
    if not stepper.unilateral:
        return None
    s = stepper.system
    pushing = stepper.active & s.contact_unilateral & (sol.mu > 0.0)
    if not pushing.any():
        return None
    end = stepper.evaluate(t_end, new)[0]  # the step's end time exactly (cached)
    rows = (stepper.active & s.contact_unilateral & (end.mu <= 0.0)
            & (end.phi_dd > ce.SEPARATION_ACCELERATION))
    if not (rows & pushing).any():
        return None
    f_lo, f_hi = release(sol, rows), release(end, rows)
    if not (f_lo > 0.0 > f_hi):
        return None

    def f(theta: float):
        s_e = stepper.step(integrator, t, state, sol, theta * h)
        sol_e = stepper.evaluate(t + theta * h, s_e)[0]
        return release(sol_e, rows), (s_e, sol_e)

    theta, (s_hi, sol_hi) = illinois(
        f, 0.0, f_lo, 1.0, f_hi, lambda lo, hi: (hi - lo) * h < ce.SEPARATION_TIME_TOLERANCE,
        hi_payload=(new, end), bisect_every=3)
    return theta, s_hi, rows & (sol_hi.mu <= 0.0)


def locate_off_edge(stepper: Stepping, integrator: str, t: float, state: SystemState, sol,
                    h: float, new: SystemState):
    """The first active row of a finite support leaving its rectangle inside a step, or None.

    The rows watched: active rows of supports with an ``extent``
    (:attr:`Stepper.finite_rows`), all inside at the step's start (edge margin > 0; a row
    already outside is dropped by the check at a step's start). When the smallest of their
    edge margins (:meth:`Stepper.edge_margins`) is <= 0 at the step's end, its root on
    ``θ ∈ [0, 1]`` is located by :func:`illinois` to a bracket shorter than
    ``EDGE_TIME_TOLERANCE``.

    Args:
        stepper: the stepper (its active set, steps and edge margins).
        integrator: the integrator's name.
        t: the step's start [s].
        state: the state at ``t``.
        sol: its solution.
        h: the step [s].
        new: the state at ``t + h``.

    Returns:
        ``(θ, state at t + θ h, (B, R) mask of those rows outside there)`` (θ the bracket's
        upper end, just past the edge), or None.
    """
    rows = stepper.active & stepper.finite_rows
    if not rows.any():
        return None
    f_hi = float(stepper.edge_margins(new)[rows].min())
    if f_hi > 0.0:
        return None
    f_lo = float(stepper.edge_margins(state)[rows].min())
    if not f_lo > 0.0:
        return None

    def f(theta: float):
        s_e = stepper.step(integrator, t, state, sol, theta * h)
        return float(stepper.edge_margins(s_e)[rows].min()), s_e

    theta, s_hi = illinois(
        f, 0.0, f_lo, 1.0, f_hi, lambda lo, hi: (hi - lo) * h < ce.EDGE_TIME_TOLERANCE,
        hi_payload=new)
    return theta, s_hi, rows & (stepper.edge_margins(s_hi) <= 0.0)


def locate_touchdown(stepper: Stepping, integrator: str, t: float, state: SystemState, sol,
                     h: float, watch: np.ndarray, g_hi: float) -> tuple[float, SystemState]:
    """``θ`` of the step where the smallest watched gap first reaches ``[-tol, 0]``.

    A bracket ``[lo, hi]`` with the gap above the band at ``lo`` and below it at ``hi``
    is refined by :func:`illinois` (to the band, or a bracket shorter than
    ``TIME_TOLERANCE``). When the step starts inside the band (a row that just rebounded, or
    one touching), ``θ = 0`` if some such row approaches; otherwise ``lo`` is searched by
    halving ``θ`` (the row rises, then comes back).

    Args:
        stepper: the stepper.
        integrator: the integrator's name.
        t: the step's start [s].
        state: the state at ``t``.
        sol: its solution.
        h: the step [s].
        watch: (B, R) bool, the rows watched for a touchdown.
        g_hi: the smallest watched gap at the step's end [m] (below ``-tol``).

    Returns:
        ``(θ, state at t + θ h)``.
    """
    tol = ce.GAP_TOLERANCE
    target = -0.5 * tol
    lo, hi = 0.0, 1.0
    rows0 = stepper.rows_at(t, state)
    f_lo, f_hi = float(rows0.phi[watch].min()) - target, g_hi - target
    if f_lo <= 0.5 * tol:  # a watched row starts within (or below) the band
        if np.any(watch & (rows0.phi <= 0.0) & (rows0.phi_dot < -ce.REBOUND_SPEED)):
            return 0.0, state
        theta = 1.0
        while True:
            theta *= 0.5
            if theta * h < ce.TIME_TOLERANCE:
                return 0.0, state
            f = float(stepper.gaps(stepper.step(integrator, t, state, sol, theta * h))[watch]
                      .min()) - target
            if f > 0.5 * tol:
                lo, f_lo = theta, f
                break
            hi, f_hi = theta, f

    def gap(theta: float):
        s_e = stepper.step(integrator, t, state, sol, theta * h)
        return float(stepper.gaps(s_e)[watch].min()) - target, s_e

    return illinois(gap, lo, f_lo, hi, f_hi,
                    lambda lo, hi: (hi - lo) * h < ce.TIME_TOLERANCE, band=0.5 * tol)
