"""Time integration of a multi-arm system and the record of a run.

State: the arms' ``q, v`` and the object's position, quaternion ``[x, y, z, w]`` and twist
``[ẋ; ω]`` (world axes at the COM). At every evaluation the controller is called with the
blocks at zero torque, its torque is added (``h ← h + τ``) and the forward dynamics solved
(:func:`multiarm_pin.dynamics.solve`).

Integrators (``integrator=``):

- ``"rk4"``: classical fixed-step Runge-Kutta. Arm configurations are advanced with
  ``pin.integrate`` on the combined model (exact for Pinocchio's one-DOF joints, whose
  configuration spaces commute), the quaternion as a vector of R⁴ with
  ``q̇ = ½ [ω; 0] ⊗ q`` and renormalised at every stage and step (so the scheme keeps its
  fourth order).
- ``"rk45"``: ``scipy.integrate.solve_ivp(method="RK45")`` (Dormand-Prince, the thesis's
  ``ode45``) with output on the ``dt`` grid; the quaternion is normalised whenever it is read.
  Needs ``nq == nv`` (``q̇ = v``).
- ``"semi_implicit"``: symplectic Euler: velocities first (``v ← v + dt q̈``), then positions
  with the new velocities (``pin.integrate``, :func:`~multiarm_pin.spatial.integrate_quaternion`).

Everything is sampled every ``dt`` into a :class:`SimulationResult`.

Unilateral contacts (fingertips, supports): when the system has any, every evaluation solves
the mixed complementarity problem on the *active set* of rows
(:func:`multiarm_pin.dynamics.unilateral.solve_unilateral`, the rows of
:meth:`MultiArmSystem.contact_blocks`), and separations and touchdowns (with impacts) are
handled between steps, event-driven, as :mod:`multiarm_pin.sim.contact_events` describes; every
event is in :attr:`SimulationResult.events`. ``rk45`` (adaptive, not event-aware) is only for
systems without unilateral rows. Systems without unilateral rows use the bilateral solvers as
before.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from multiarm_pin.constraints.joint import INITIAL_GAP_TOLERANCE
from multiarm_pin.dynamics import SOLVERS, Solution
from multiarm_pin.dynamics import solve as solve_dynamics
from multiarm_pin.exceptions import DynamicsError, InputError, MultiArmError
from multiarm_pin.model.rigid_object import ObjectState
from multiarm_pin.sim import contact_events as ce
from multiarm_pin.sim.closed_loop import closed_loop_evaluation, controller_torques
from multiarm_pin.sim.contact_events import ContactEvent
from multiarm_pin.sim.disturbances import WrenchSchedule
from multiarm_pin.spatial import integrate_quaternion, quaternion_derivative
from multiarm_pin.system import ContactRows, Evaluation, MultiArmSystem, SystemState

INTEGRATORS = ("rk4", "rk45", "semi_implicit")
"""Names accepted by :func:`simulate`."""

MAX_WARNINGS = 200
"""Contact-separation warnings kept in a result (the rest are counted)."""

Controller = Callable[[float, SystemState, Evaluation], np.ndarray]
"""``controller(t, state, evaluation) -> tau (nv,)``; ``evaluation`` holds the blocks at τ = 0."""


@dataclass
class SimulationResult:
    """Record of a run, sampled every ``dt`` (T samples, B contact blocks, R rows per block).

    ``B = n_blocks`` and ``R = rows_max`` of :class:`MultiArmSystem`: the n arms' rows, then
    (when the system has supports) one block of every support row; without supports
    ``B, R = n, N_max``.

    Attributes:
        t: (T,) times [s].
        q: (T, nq) arms' configurations; v: (T, nv) velocities.
        object_position: (T, 3) [m]; object_quaternion: (T, 4) ``[x, y, z, w]``;
        object_twist: (T, 6) ``[ẋ; ω]`` world axes.
        tau: (T, nv) joint torques applied [N m].
        mu: (T, B, R) contact multipliers [N] (positive = pushing; 0 on padding and on
            separated rows).
        phi: (T, B, R) gaps [m]; phi_dot: (T, B, R) gap rates [m/s].
        contact_points: (T, B, R, 3) world contact points [m];
        normals: (T, B, R, 3) world push directions.
        object_acceleration: (T, 6) ``[ẍ; ω̇]``; qdd: (T, nv) joint accelerations.
        kinetic_energy: (T,) [J]; potential_energy: (T,) [J] (gravity, zero at z = 0).
        momentum: (T, 6) total ``[linear; angular]`` momentum of arms and object about the
            world origin [kg m/s, kg m²/s].
        constraint_violation: (T,) ``max |φ|`` over bilateral and active rows, and the
            largest penetration ``-φ`` of separated rows [m].
        solver: (T,) name of the solver used at each sample.
        warnings: contact separations (unilateral contact with ``μ < 0``) with time and
            arm/contact index, at each onset.
        solver_switches: times [s] at which the ``auto`` solver switched to the singular-arm
            variant (onsets).
        wall_time: seconds spent in :func:`simulate`.
        integrator, dt, baumgarte: the settings used.
        unilateral: (B, R) bool mask of unilateral rows.
        active: (T, B, R) bool, rows in the active set (touching) at each sample.
        external_wrench: (T, 6) ``[f; m]`` applied at the COM, world axes [N, N m].
        events: every separation and touchdown (:class:`ContactEvent`), in time order.
        contact_labels: ``(block, row, label)`` of every real row.
    """

    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    object_position: np.ndarray
    object_quaternion: np.ndarray
    object_twist: np.ndarray
    tau: np.ndarray
    mu: np.ndarray
    phi: np.ndarray
    phi_dot: np.ndarray
    contact_points: np.ndarray
    normals: np.ndarray
    object_acceleration: np.ndarray
    qdd: np.ndarray
    kinetic_energy: np.ndarray
    potential_energy: np.ndarray
    momentum: np.ndarray
    constraint_violation: np.ndarray
    solver: np.ndarray
    unilateral: np.ndarray
    integrator: str
    dt: float
    baumgarte: tuple[float, float] | None
    warnings: list[str] = field(default_factory=list)
    solver_switches: list[float] = field(default_factory=list)
    wall_time: float = 0.0
    active: np.ndarray | None = None
    external_wrench: np.ndarray | None = None
    events: list[ContactEvent] = field(default_factory=list)
    contact_labels: list = field(default_factory=list)

    @property
    def total_energy(self) -> np.ndarray:
        """(T,) kinetic + potential energy [J]."""
        return self.kinetic_energy + self.potential_energy

    def state(self, k: int) -> SystemState:
        """The :class:`SystemState` of sample ``k``."""
        return SystemState(self.q[k].copy(), self.v[k].copy(),
                           ObjectState(self.object_position[k].copy(),
                                       self.object_quaternion[k].copy(),
                                       self.object_twist[k].copy()))


class _Stepper:
    """Evaluates the closed-loop dynamics on the active set and handles contact events."""

    def __init__(self, system: MultiArmSystem, controller, solver: str, baumgarte,
                 wrench: WrenchSchedule | None = None):
        self.system = system
        self.controller = controller
        self.solver = solver
        self.baumgarte = baumgarte
        self.wrench = wrench if wrench else None
        self.model = None if system.arm_set is None else system.arm_set.model
        self.unilateral = bool(system.contact_unilateral.any())
        self.active = system.contact_mask.copy()
        self.events: list[ContactEvent] = []
        self._cache = None  # (t, state, active, result) of the last evaluation

    def evaluate(self, t: float, state: SystemState):
        """``(solution, evaluation, tau, rows)`` at ``(t, state)`` with the current active set.

        Errors carry the time (same type, message prefixed with ``t = ... s``).
        """
        c = self._cache
        if c is not None and c[0] == t and c[1] is state and np.array_equal(c[2], self.active):
            return c[3]
        try:
            out = self._evaluate(t, state)
            self._cache = (t, state, self.active.copy(), out)
            return out
        except MultiArmError as exc:
            if exc.args and isinstance(exc.args[0], str) and not exc.args[0].startswith("t = "):
                exc.args = (f"t = {t:.6g} s: {exc.args[0]}", *exc.args[1:])
            raise

    def _evaluate(self, t: float, state: SystemState):
        s = self.system
        w = None if self.wrench is None else self.wrench(t)
        if not s.n_arms:
            full, rows = s.contact_blocks(state, None, None, self.baumgarte, w)
            return self._solve(t, full), None, np.zeros(0), rows
        if not self.unilateral and w is None and not s.supports.n_rows:
            # arms' bilateral rows only: one shared, fused evaluation (blocks, controller and
            # forward dynamics on one buffer, multiarm_pin.sim.closed_loop)
            sol, ev, tau = closed_loop_evaluation(s, self.controller, t, state, self.solver,
                                                  self.baumgarte)
            ct = ev.constraints
            return sol, ev, tau, ContactRows(ct.phi, ct.phi_dot, ct.contact_points, ct.normals)
        ev = s.blocks(state, None, self.baumgarte)
        if self.unilateral:  # the controller sees which contacts touch
            ev = ev.with_active(self.active[:s.n_arms, :s.N_max].copy())
        if self.controller is None:
            tau = np.zeros(s.nv)
            blocks = ev.blocks
        else:
            tau = controller_torques(self.controller, t, state, ev, s.nv)
            blocks = ev.blocks.with_torques(s.pad(tau))
        full, rows = s.contact_blocks(state, blocks, ev.constraints, self.baumgarte, w)
        return self._solve(t, full), ev, tau, rows

    def _solve(self, t: float, blocks):
        try:
            if self.unilateral:
                from multiarm_pin.dynamics.unilateral import solve_unilateral

                return solve_unilateral(blocks, self.system.contact_unilateral, self.active)
            return solve_dynamics(blocks, self.solver)
        except DynamicsError as exc:
            raise DynamicsError(f"t = {t:.6g} s: {exc}") from exc

    def derivative(self, state: SystemState, sol: Solution) -> np.ndarray:
        """Tangent ``[q̇ (nv); v̇ (nv); ṗ (3); q̇uat (4); ȧ (6)]``."""
        o = state.obj
        return np.concatenate([state.v, self.system.unpad(sol.qdd), o.twist[:3],
                               quaternion_derivative(o.quaternion, o.twist[3:]), sol.a_o])

    def advance(self, state: SystemState, d: np.ndarray, h: float) -> SystemState:
        nv = self.system.nv
        q = state.q if self.model is None else pin.integrate(self.model, state.q, h * d[:nv])
        v = state.v + h * d[nv:2 * nv]
        o = state.obj
        p = o.position + h * d[2 * nv:2 * nv + 3]
        quat = o.quaternion + h * d[2 * nv + 3:2 * nv + 7]
        quat = quat / np.linalg.norm(quat)
        tw = o.twist + h * d[2 * nv + 7:]
        return SystemState(q, v, ObjectState(p, quat, tw))

    def step(self, integrator: str, t: float, state: SystemState, sol: Solution,
             h: float) -> SystemState:
        """One step of size ``h`` [s] from ``(t, state)`` whose solution is ``sol``."""
        if integrator == "rk4":
            d1 = self.derivative(state, sol)
            s2 = self.advance(state, d1, 0.5 * h)
            d2 = self.derivative(s2, self.evaluate(t + 0.5 * h, s2)[0])
            s3 = self.advance(state, d2, 0.5 * h)
            d3 = self.derivative(s3, self.evaluate(t + 0.5 * h, s3)[0])
            s4 = self.advance(state, d3, h)
            d4 = self.derivative(s4, self.evaluate(t + h, s4)[0])
            return self.advance(state, (d1 + 2.0 * d2 + 2.0 * d3 + d4) / 6.0, h)
        system = self.system  # semi-implicit Euler
        v = state.v + h * system.unpad(sol.qdd)
        tw = state.obj.twist + h * sol.a_o
        o = state.obj
        q = state.q if self.model is None else pin.integrate(self.model, state.q, h * v)
        return SystemState(q, v, ObjectState(o.position + h * tw[:3],
                                             integrate_quaternion(o.quaternion, tw[3:], h), tw))

    # ------------------------------------------------------------------ events
    def _event(self, t: float, kind: str, b: int, r: int, **kw) -> None:
        s = self.system
        label = next(lab for bb, rr, lab in s.contact_labels if bb == b and rr == r)
        body = s.arms[b].name if b < s.n_arms else s.supports.supports[
            int(s.supports.support_index[r])].name
        self.events.append(ContactEvent(float(t), kind, int(b), int(r), label, body, **kw))

    def init_active(self, rows: ContactRows, tol: float) -> None:
        """Active at t = 0: bilateral rows, and unilateral rows whose gap is within ``tol``."""
        s = self.system
        self.active = s.contact_mask & (~s.contact_unilateral | (rows.phi <= tol))

    def separations(self, t: float, sol, rows: ContactRows, keep=None) -> bool:
        """Drop active unilateral rows that the solution lets go; True if any was dropped.

        ``keep``: (B, R) bool rows not to drop now (those that just touched down: they stay
        active until the next sample, where the check runs again).
        """
        if not self.unilateral:
            return False
        s = self.system
        leave = self.active & s.contact_unilateral & (
            ((sol.mu <= 0.0) & (sol.phi_dd > ce.SEPARATION_ACCELERATION))
            | (rows.phi > ce.SEPARATION_GAP) | (rows.phi_dot > ce.SEPARATION_SPEED))
        if keep is not None:
            leave &= ~keep
        for b, r in zip(*np.nonzero(leave), strict=True):
            self._event(t, "separation", b, r, phi_dot=float(rows.phi_dot[b, r]),
                        phi_dot_after=float(rows.phi_dot[b, r]))
        self.active = self.active & ~leave
        return bool(leave.any())

    def _watch(self) -> np.ndarray:
        s = self.system
        return s.contact_mask & s.contact_unilateral & ~self.active

    def gaps(self, state: SystemState) -> np.ndarray:
        """(B, R) gaps [m] of every row at a state."""
        s = self.system
        out = np.zeros((s.n_blocks, s.rows_max))
        if s.n_arms:
            out[:s.n_arms, :s.N_max] = s.blocks(state).constraints.phi
        if s.supports.n_rows:
            out[s.n_arms, :s.supports.n_rows] = s.support_terms(state).phi
        return out

    def advance_with_events(self, integrator: str, t: float, state: SystemState, sol,
                            h: float, t_end: float | None = None) -> SystemState:
        """The state at ``t + h``: steps, touchdowns located and impacts applied on the way.

        ``t_end``: the grid time ``t + h`` exactly (default ``t + h`` in floating point), so
        that the step's final evaluation, made to look for separations, is the one the next
        step starts from (cached) and a wrench switching at a grid time is read there.
        """
        if not self.unilateral:
            return self.step(integrator, t, state, sol, h)
        tol = ce.GAP_TOLERANCE
        t_end = t + h if t_end is None else float(t_end)
        for _ in range(ce.MAX_EVENTS_PER_STEP):
            h = t_end - t
            new = self.step(integrator, t, state, sol, h)
            # a separation inside the step: the step ends there (touchdowns before it first)
            sep = self._locate_separation(integrator, t, state, sol, h, new, t_end)
            if sep is not None:
                theta_s, new, leaving = sep
                h = theta_s * h
            watch = self._watch()
            # a row far below the band at the step's start is not watched: its tip went
            # round an edge, behind the (infinite) plane of its face, and touches nothing
            watch &= self.gaps(state) >= -ce.LOST_GAP
            g_hi = float(self.gaps(new)[watch].min()) if watch.any() else 0.0
            if g_hi >= -tol:
                if sep is None:
                    return new
                t, state = t + h, new
                self._separate(t, state, leaving)
                sol, _, _, rows = self.evaluate(t, state)
                if self.separations(t, sol, rows):
                    sol = self.evaluate(t, state)[0]
                if t_end - t <= ce.TIME_TOLERANCE:
                    return state
                continue
            theta, s_e = self._locate(integrator, t, state, sol, h, watch, g_hi)
            t = t + theta * h
            state, joined = self._impact(t, s_e, watch)
            sol, _, _, rows = self.evaluate(t, state)
            if self.separations(t, sol, rows, keep=joined):
                sol = self.evaluate(t, state)[0]
            if t_end - t <= ce.TIME_TOLERANCE:
                return state
        raise DynamicsError(f"t = {t:.6g} s: more than {ce.MAX_EVENTS_PER_STEP} contact events "
                            "in one step")

    @staticmethod
    def _release(sol, rows: np.ndarray) -> float:
        """Signed release function of the ``rows`` group: > 0 while none lifts, < 0 after.

        ``-max φ̈_k`` [m/s²] over the rows that carry no force (``μ_k = 0``) and lift
        (``φ̈_k > LIFT_ACCELERATION``) if any; otherwise the group's total force ``Σ μ_k``
        [N] (> 0). For an active unilateral row the LCP gives either ``μ > 0, φ̈ = 0`` or
        ``μ = 0, φ̈ >= 0``, so the sign changes exactly when the first row of the group lets
        go; the total force (unique even when the rows are redundant, e.g. one edge of a box
        on two vertices, where a single row's ``μ`` is not) only guides the secant.
        """
        lift = rows & (sol.mu <= 0.0) & (sol.phi_dd > ce.LIFT_ACCELERATION)
        if lift.any():
            return -float(sol.phi_dd[lift].max())
        return float(sol.mu[rows].sum())

    def _locate_separation(self, integrator, t, state, sol, h, new, t_end):
        """The first separation inside a step, or None.

        Rows that separate inside the step: active unilateral rows that, at the step's end,
        have ``μ = 0`` and lift (``φ̈ > SEPARATION_ACCELERATION``, the same test as at a
        step's start), at least one of which pushed at its start (``μ > 0``; otherwise the
        test at the next step's start takes them). The time is the root of
        :meth:`_release` on ``θ ∈ [0, 1]`` (the integration re-run from the step's start
        with step ``θ h`` and the active set unchanged), located by the Illinois method
        (every third iterate a bisection) to a bracket shorter than
        ``SEPARATION_TIME_TOLERANCE``.

        Returns:
            ``(θ, state at t + θ h, (B, R) mask of those rows with μ = 0 there)`` (θ the
            bracket's upper end, where the first rows have let go), or None.
        """
        if not self.unilateral:
            return None
        s = self.system
        pushing = self.active & s.contact_unilateral & (sol.mu > 0.0)
        if not pushing.any():
            return None
        end = self.evaluate(t_end, new)[0]  # the step's end time exactly (cached)
        rows = (self.active & s.contact_unilateral & (end.mu <= 0.0)
                & (end.phi_dd > ce.SEPARATION_ACCELERATION))
        if not (rows & pushing).any():
            return None
        lo, hi = 0.0, 1.0
        f_lo, f_hi = self._release(sol, rows), self._release(end, rows)
        if not (f_lo > 0.0 > f_hi):
            return None
        s_hi, sol_hi, side = new, end, 0
        for it in range(200):
            if (hi - lo) * h < ce.SEPARATION_TIME_TOLERANCE:
                break
            theta = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
            if it % 3 == 2 or not (lo < theta < hi):
                theta = 0.5 * (lo + hi)
            s_e = self.step(integrator, t, state, sol, theta * h)
            sol_e = self.evaluate(t + theta * h, s_e)[0]
            f = self._release(sol_e, rows)
            if f > 0.0:
                lo, f_lo = theta, f
                if side == 1:
                    f_hi *= 0.5
                side = 1
            else:
                hi, f_hi, s_hi, sol_hi = theta, f, s_e, sol_e
                if side == -1:
                    f_lo *= 0.5
                side = -1
        return hi, s_hi, rows & (sol_hi.mu <= 0.0)

    def _separate(self, t: float, state: SystemState, leaving: np.ndarray) -> None:
        """Drop ``leaving`` rows from the active set, with their events at ``t``."""
        leaving = leaving & self.active
        if not leaving.any():
            return
        rows = self._blocks_at(t, state)[1]
        for b, r in zip(*np.nonzero(leaving), strict=True):
            self._event(t, "separation", b, r, phi_dot=float(rows.phi_dot[b, r]),
                        phi_dot_after=float(rows.phi_dot[b, r]))
        self.active = self.active & ~leaving

    def _locate(self, integrator, t, state, sol, h, watch, g_hi):
        """``θ`` of the step where the smallest watched gap first reaches ``[-tol, 0]``.

        A bracket ``[lo, hi]`` with the gap above the band at ``lo`` and below it at ``hi``
        is refined by the Illinois method. When the step starts inside the band (a row
        that just rebounded, or one touching), ``θ = 0`` if some such row approaches;
        otherwise ``lo`` is searched by halving ``θ`` (the row rises, then comes back).
        """
        tol = ce.GAP_TOLERANCE
        target = -0.5 * tol
        lo, hi = 0.0, 1.0
        _, rows0 = self._blocks_at(t, state)
        f_lo, f_hi = float(rows0.phi[watch].min()) - target, g_hi - target
        if f_lo <= 0.5 * tol:  # a watched row starts within (or below) the band
            if np.any(watch & (rows0.phi <= 0.0) & (rows0.phi_dot < -ce.REBOUND_SPEED)):
                return 0.0, state
            theta = 1.0
            while True:
                theta *= 0.5
                if theta * h < ce.TIME_TOLERANCE:
                    return 0.0, state
                f = float(self.gaps(self.step(integrator, t, state, sol, theta * h))[watch]
                          .min()) - target
                if f > 0.5 * tol:
                    lo, f_lo = theta, f
                    break
                hi, f_hi = theta, f
        side = 0
        theta, s_e = hi, None
        for _ in range(200):
            theta = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
            if not (lo < theta < hi):
                theta = 0.5 * (lo + hi)
            s_e = self.step(integrator, t, state, sol, theta * h)
            f = float(self.gaps(s_e)[watch].min()) - target
            if abs(f) <= 0.5 * tol or (hi - lo) * h < ce.TIME_TOLERANCE:
                return theta, s_e
            if f > 0:
                lo, f_lo = theta, f
                if side == 1:
                    f_hi *= 0.5
                side = 1
            else:
                hi, f_hi = theta, f
                if side == -1:
                    f_lo *= 0.5
                side = -1
        return theta, s_e

    def _impact(self, t: float, state: SystemState, watch: np.ndarray
                ) -> tuple[SystemState, np.ndarray]:
        """Apply the impact law at a touchdown, update the active set.

        Returns:
            The state after the impact and the (B, R) mask of rows that joined the active set.
        """
        from multiarm_pin.dynamics.unilateral import solve_impact

        s = self.system
        full, rows = self._blocks_at(t, state)
        touching = watch & (rows.phi <= ce.GAP_TOLERANCE)
        candidates = self.active | touching
        e = np.where(np.abs(rows.phi_dot) < ce.RESTING_SPEED, 0.0, s.contact_restitution)
        uni = s.contact_unilateral
        try:
            imp = solve_impact(full, uni, candidates, rows.phi_dot, e)
            for _ in range(3):  # capture rows that would leave slower than RESTING_SPEED
                slow = (candidates & uni & (imp.phi_dot_plus > ce.REBOUND_SPEED)
                        & (imp.phi_dot_plus <= ce.RESTING_SPEED))
                if not slow.any():
                    break
                uni = uni & ~slow  # held at φ̇⁺ = 0 by this impact (as bilateral rows)
                imp = solve_impact(full, uni, candidates, rows.phi_dot, e)
        except DynamicsError as exc:
            raise DynamicsError(f"t = {t:.6g} s: impact: {exc}") from exc
        o = state.obj
        new = SystemState(state.q, state.v + s.unpad(imp.dqd),
                          ObjectState(o.position, o.quaternion, o.twist + imp.dv_o))
        leave = candidates & s.contact_unilateral & (imp.phi_dot_plus > ce.REBOUND_SPEED)
        for b, r in zip(*np.nonzero(touching), strict=True):
            self._event(t, "touchdown", b, r, phi_dot=float(rows.phi_dot[b, r]),
                        phi_dot_after=float(imp.phi_dot_plus[b, r]),
                        impulse=float(imp.P[b, r]), rebound=bool(leave[b, r]))
        for b, r in zip(*np.nonzero(self.active & leave), strict=True):
            self._event(t, "separation", b, r, phi_dot=float(rows.phi_dot[b, r]),
                        phi_dot_after=float(imp.phi_dot_plus[b, r]),
                        impulse=float(imp.P[b, r]))
        joined = touching & ~leave
        self.active = candidates & ~leave
        return new, joined

    def _blocks_at(self, t: float, state: SystemState):
        """``(blocks, rows)`` of every contact row at a state, without torques.

        The impact law uses only ``M``, ``W``, ``W_o`` and ``M_o``: no controller call.
        """
        s = self.system
        w = None if self.wrench is None else self.wrench(t)
        if not s.n_arms:
            return s.contact_blocks(state, None, None, self.baumgarte, w)
        ev = s.blocks(state, None, self.baumgarte)
        return s.contact_blocks(state, ev.blocks, ev.constraints, self.baumgarte, w)


def simulate(
    system: MultiArmSystem,
    initial_state: SystemState,
    controller: Controller | None,
    duration: float,
    dt: float,
    integrator: str = "rk4",
    solver: str = "auto",
    baumgarte: tuple[float, float] | None = None,
    progress: Callable[[float], None] | None = None,
    *,
    check_initial: bool = True,
    initial_tol: float = INITIAL_GAP_TOLERANCE,
    velocity_tol: float = 1e-6,
    rtol: float = 1e-9,
    atol: float = 1e-11,
    max_record_bytes: int | None = None,
    external_wrench: WrenchSchedule | None = None,
) -> SimulationResult:
    """Simulate the closed-loop system from ``initial_state`` for ``duration`` seconds.

    Args:
        system: the system.
        initial_state: the state at t = 0; must satisfy the joints (``|φ| <= initial_tol``
            [m], ``|φ̇| <= velocity_tol`` [m/s]) unless ``check_initial`` is False.
        controller: ``controller(t, state, evaluation) -> tau (nv,)`` (see
            :mod:`multiarm_pin.sim.controllers`), or None for zero torque.
        duration: simulated time [s] (> 0).
        dt: sampling period [s] (and step of the fixed-step integrators).
        integrator: ``"rk4"``, ``"rk45"`` or ``"semi_implicit"``.
        solver: forward-dynamics solver name (:data:`multiarm_pin.dynamics.SOLVERS`).
        baumgarte: ``(α, β)`` [1/s] constraint stabilisation (thesis Sec 4.3), or None.
        progress: optional ``callable(fraction)`` called as the run advances (0..1).
        check_initial: validate the initial state first.
        initial_tol: gap tolerance [m] of that check.
        velocity_tol: gap-rate tolerance [m/s] of that check.
        rtol: relative tolerance of ``rk45``.
        atol: absolute tolerance of ``rk45``.
        max_record_bytes: largest memory [bytes] the record may take
            (:func:`record_bytes`); default :func:`default_record_limit`.
        external_wrench: wrench on the object's COM over time intervals
            (:class:`~multiarm_pin.sim.disturbances.WrenchSchedule`), or None.

    Returns:
        :class:`SimulationResult`.

    Any exception raised once the integration has started (a :class:`DynamicsError`, a
    ``KeyboardInterrupt``...) carries the samples completed so far: read them with
    :func:`partial_result`.

    Raises:
        InputError: unknown integrator or solver (lists the known ones), bad ``dt``/duration,
            or a run whose record would not fit in memory (before allocating it).
        ConstraintError: an initial state that violates the joints.
        DynamicsError: NaN in the state, or no solution of the dynamics (with the time).
    """
    t_start = time.perf_counter()
    if max_record_bytes is None:
        max_record_bytes = default_record_limit()
    if integrator not in INTEGRATORS:
        raise InputError(
            f"unknown integrator {integrator!r}; known integrators: {', '.join(INTEGRATORS)}"
        )
    if solver not in SOLVERS:
        raise InputError(f"unknown solver {solver!r}; known solvers: {', '.join(SOLVERS)}")
    duration, dt = float(duration), float(dt)
    if not (np.isfinite(dt) and dt > 0):
        raise InputError(f"dt: expected a positive time step [s], got {dt}")
    if not (np.isfinite(duration) and duration >= dt):
        raise InputError(f"duration: expected a finite time >= dt = {dt} [s], got {duration}")
    if controller is not None and not callable(controller):
        raise InputError(
            f"controller: expected callable(t, state, evaluation) or None, got "
            f"{type(controller).__name__}"
        )
    system.check_state(initial_state)
    if check_initial:
        system.check_initial_state(initial_state, tol=initial_tol, velocity_tol=velocity_tol)
    if integrator == "rk45" and system.nq != system.nv:
        raise InputError(
            f"integrator 'rk45' needs nq == nv (q̇ = v), got nq = {system.nq}, nv = {system.nv} "
            "(an arm has continuous or multi-DOF joints); use 'rk4' or 'semi_implicit'"
        )
    if external_wrench is not None and not isinstance(external_wrench, WrenchSchedule):
        external_wrench = WrenchSchedule(external_wrench)
    stepper = _Stepper(system, controller, solver, baumgarte, external_wrench)
    if integrator == "rk45" and stepper.unilateral:
        raise InputError(
            "integrator 'rk45' is not event-aware and the system has unilateral contacts "
            "(fingertips or supports); use 'rk4' or 'semi_implicit'"
        )
    n_steps = int(np.floor(duration / dt + 1e-9))
    need = record_bytes(system, n_steps + 1)
    if need > max_record_bytes:
        raise InputError(
            f"duration: {duration:g} s at dt = {dt:g} s is {n_steps + 1} samples, whose record "
            f"needs ~{_human_bytes(need)} of memory (limit {_human_bytes(max_record_bytes)}); "
            "shorten the duration or lengthen dt"
        )
    times = np.arange(n_steps + 1) * dt
    rec = _Recorder(system, len(times), solver)

    def report(frac: float) -> None:
        if progress is not None:
            progress(min(max(frac, 0.0), 1.0))

    state = SystemState(np.array(initial_state.q, float), np.array(initial_state.v, float),
                        ObjectState(np.array(initial_state.obj.position, float),
                                    _normalised(initial_state.obj.quaternion),
                                    np.array(initial_state.obj.twist, float)))
    if stepper.unilateral:
        stepper.init_active(stepper._blocks_at(0.0, state)[1], initial_tol)
    try:
        _integrate(stepper, rec, state, times, integrator, rtol, atol, report)
    except BaseException as exc:  # keep what was simulated, for the caller to save
        exc.partial_result = rec.result(integrator, dt, baumgarte,
                                         time.perf_counter() - t_start, stepper, rec.count)
        raise
    report(1.0)
    return rec.result(integrator, dt, baumgarte, time.perf_counter() - t_start, stepper)


def partial_result(exc: BaseException) -> SimulationResult | None:
    """The record, up to the last completed step, that :func:`simulate` attached to ``exc``.

    Args:
        exc: an exception raised by :func:`simulate` (any, including ``KeyboardInterrupt``)
            once the integration had started.

    Returns:
        A :class:`SimulationResult` of the samples completed before the exception (possibly
        with 0 samples), or None if the exception came before the integration started.
    """
    return getattr(exc, "partial_result", None)


def record_bytes(system: MultiArmSystem, n_samples: int) -> int:
    """Memory [bytes] of the record of ``n_samples`` samples (all arrays of the result).

    Args:
        system: the system (its nq, nv, contact blocks and rows set the per-sample size).
        n_samples: T.
    """
    nm = system.n_blocks * system.rows_max  # arms and the supports' block
    per_sample = (1 + system.nq + 4 * system.nv + 3 + 4 + 6 + 6 + 3 * nm + 6 * nm + 2 + 6 + 1
                  + 6 + nm / 8)  # + external wrench (6 floats) and active set (1 byte a row)
    return int(8 * (per_sample + 2) * max(int(n_samples), 0))  # + time grid, solver names


def _human_bytes(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if n < 1024 or unit == "PiB":
            return f"{n:.3g} {unit}"
        n /= 1024
    return f"{n:.3g} EiB"


def default_record_limit() -> int:
    """Default largest record [bytes]: half of the machine's physical memory."""
    try:
        import os

        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") // 2)
    except (ValueError, OSError, AttributeError):
        return 4 * 1024**3


def _integrate(stepper: _Stepper, rec: _Recorder, state: SystemState, times: np.ndarray,
               integrator: str, rtol: float, atol: float, report) -> None:
    """Run the integrator over the time grid, recording every sample."""
    n_steps = len(times) - 1
    if integrator == "rk45":
        _run_rk45(stepper, rec, state, times, rtol, atol, report)
    else:
        every = max(1, n_steps // 100)
        for k in range(n_steps + 1):
            t = times[k]
            sol, ev, tau, rows = stepper.evaluate(t, state)
            if stepper.separations(t, sol, rows):
                sol, ev, tau, rows = stepper.evaluate(t, state)
            rec.record(k, t, state, sol, ev, tau, rows, stepper)
            if k == n_steps:
                break
            state = stepper.advance_with_events(integrator, t, state, sol, times[k + 1] - t,
                                                t_end=times[k + 1])
            if k % every == 0:
                report((k + 1) / n_steps)


def _normalised(q) -> np.ndarray:
    q = np.array(q, dtype=float)
    return q / np.linalg.norm(q)


def _run_rk45(stepper: _Stepper, rec: _Recorder, state: SystemState, times: np.ndarray,
              rtol: float, atol: float, report) -> None:
    from scipy.integrate import RK45

    system = stepper.system
    nq, nv = system.nq, system.nv
    duration = float(times[-1])

    def unpack(y: np.ndarray) -> SystemState:
        return SystemState(y[:nq], y[nq:nq + nv],
                           ObjectState(y[nq + nv:nq + nv + 3],
                                       _normalised(y[nq + nv + 3:nq + nv + 7]),
                                       y[nq + nv + 7:]))

    def fun(t: float, y: np.ndarray) -> np.ndarray:
        s = unpack(y)
        sol = stepper.evaluate(t, s)[0]
        report(t / duration)
        return stepper.derivative(s, sol)

    o = state.obj
    y0 = np.concatenate([state.q, state.v, o.position, o.quaternion, o.twist])
    # solve_ivp(method="RK45", t_eval=times) step by step, recording each grid time as soon
    # as a step passes it (same values; an error or interrupt keeps the samples so far)
    ode = RK45(fun, 0.0, y0, duration, rtol=rtol, atol=atol)
    k = 0
    while k < len(times):
        if times[k] <= ode.t:
            y = y0 if k == 0 else ode.dense_output()(times[k])
            s = unpack(y)
            sol, ev, tau, rows = stepper.evaluate(times[k], s)
            rec.record(k, times[k], s, sol, ev, tau, rows, stepper)
            k += 1
            continue
        message = ode.step()
        if ode.status == "failed":
            raise DynamicsError(f"rk45 integration failed at t = {ode.t:.6g} s: {message}")


class _Recorder:
    def __init__(self, system: MultiArmSystem, T: int, solver: str):
        n, m = system.n_blocks, system.rows_max
        self.system = system
        self.requested = solver
        self.t = np.zeros(T)
        self.q = np.zeros((T, system.nq))
        self.v = np.zeros((T, system.nv))
        self.p = np.zeros((T, 3))
        self.quat = np.zeros((T, 4))
        self.twist = np.zeros((T, 6))
        self.tau = np.zeros((T, system.nv))
        self.mu = np.zeros((T, n, m))
        self.phi = np.zeros((T, n, m))
        self.phi_dot = np.zeros((T, n, m))
        self.points = np.zeros((T, n, m, 3))
        self.normals = np.zeros((T, n, m, 3))
        self.a_o = np.zeros((T, 6))
        self.qdd = np.zeros((T, system.nv))
        self.ke = np.zeros(T)
        self.pe = np.zeros(T)
        self.momentum = np.zeros((T, 6))
        self.violation = np.zeros(T)
        self.active = np.zeros((T, n, m), dtype=bool)
        self.wrench = np.zeros((T, 6))
        self.solver = np.empty(T, dtype=object)
        self.warnings: list[str] = []
        self.n_warnings = 0
        self.switches: list[float] = []
        self._negative = np.zeros((n, m), dtype=bool)
        self._singular = False
        self.count = 0

    def record(self, k: int, t: float, state: SystemState, sol: Solution, ev: Evaluation,
               tau: np.ndarray, ct: ContactRows, stepper: _Stepper) -> None:
        s = self.system
        self.t[k] = t
        self.q[k] = state.q
        self.v[k] = state.v
        self.p[k] = state.obj.position
        self.quat[k] = state.obj.quaternion
        self.twist[k] = state.obj.twist
        self.tau[k] = tau
        self.mu[k] = sol.mu
        self.phi[k] = ct.phi
        self.phi_dot[k] = ct.phi_dot
        self.points[k] = ct.contact_points
        self.normals[k] = ct.normals
        self.a_o[k] = sol.a_o
        self.qdd[k] = s.unpad(sol.qdd)
        self.ke[k] = s.kinetic_energy(state)
        self.pe[k] = s.potential_energy(state)
        self.momentum[k] = s.momentum(state)
        held = stepper.active | (s.contact_mask & ~s.contact_unilateral)
        free = s.contact_mask & ~held
        viol = np.concatenate([np.abs(ct.phi[held]), np.maximum(-ct.phi[free], 0.0), [0.0]])
        self.violation[k] = float(viol.max())
        self.active[k] = stepper.active
        if stepper.wrench is not None:
            self.wrench[k] = stepper.wrench(t)
        self.solver[k] = sol.solver
        negative = s.contact_unilateral & (sol.mu < 0.0)
        for i, j in zip(*np.nonzero(negative & ~self._negative), strict=True):
            self.n_warnings += 1
            if len(self.warnings) < MAX_WARNINGS:
                self.warnings.append(
                    f"t = {t:.6g} s: arm {i} ({s.arms[i].name}) contact {j}: multiplier "
                    f"μ = {sol.mu[i, j]:.4g} N < 0, a frictionless contact would separate"
                )
        self._negative = negative
        singular = sol.solver == "singular" and self.requested == "auto"
        if singular and not self._singular:
            self.switches.append(float(t))
        self._singular = singular
        self.count = k + 1

    def result(self, integrator, dt, baumgarte, wall, stepper: _Stepper,
               n: int | None = None) -> SimulationResult:
        """The record as a :class:`SimulationResult`, its first ``n`` samples (all: None)."""
        n = len(self.t) if n is None else int(n)
        s = self.system
        warnings = [  # a grasp contact letting go is worth a warning (a support's is not)
            f"t = {e.t:.6g} s: arm {e.block} ({e.body}) contact {e.row}: separates (multiplier "
            f"μ = 0 N; holding it would need a pulling force)"
            for e in stepper.events if e.kind == "separation" and e.block < s.n_arms
        ][:MAX_WARNINGS] + list(self.warnings) + [  # a controller's own (ObjectPD holding)
            w for w in getattr(stepper.controller, "warnings", ()) if isinstance(w, str)]
        if self.n_warnings > len(warnings):
            warnings.append(f"... {self.n_warnings - len(warnings)} more separation warnings")
        return SimulationResult(
            t=self.t[:n], q=self.q[:n], v=self.v[:n], object_position=self.p[:n],
            object_quaternion=self.quat[:n], object_twist=self.twist[:n], tau=self.tau[:n],
            mu=self.mu[:n], phi=self.phi[:n], phi_dot=self.phi_dot[:n],
            contact_points=self.points[:n], normals=self.normals[:n],
            object_acceleration=self.a_o[:n], qdd=self.qdd[:n], kinetic_energy=self.ke[:n],
            potential_energy=self.pe[:n], momentum=self.momentum[:n],
            constraint_violation=self.violation[:n], solver=self.solver[:n],
            unilateral=np.array(self.system.contact_unilateral), integrator=integrator, dt=dt,
            baumgarte=None if baumgarte is None else tuple(float(x) for x in baumgarte),
            warnings=warnings, solver_switches=list(self.switches), wall_time=wall,
            active=self.active[:n], external_wrench=self.wrench[:n],
            events=[e for e in stepper.events if n == len(self.t) or e.t <= self.t[max(n - 1, 0)]],
            contact_labels=list(self.system.contact_labels),
        )


__all__ = [
    "INTEGRATORS",
    "ContactEvent",
    "Controller",
    "SimulationResult",
    "default_record_limit",
    "partial_result",
    "record_bytes",
    "simulate",
]
