"""The stepper of :func:`~multiarm_pin.sim.simulation.simulate`: evaluations, steps, events.

:class:`Stepper` evaluates the closed-loop dynamics at a state (the controller called with the
blocks at zero torque, its torque added, the forward dynamics solved on the active set of
rows: :func:`multiarm_pin.dynamics.solve` or, with unilateral rows,
:func:`multiarm_pin.dynamics.unilateral.solve_unilateral`), takes fixed steps (``"rk4"``,
``"semi_implicit"``) and, with unilateral rows, handles separations and touchdowns (with
impacts) inside a step, event-driven, as :mod:`multiarm_pin.sim.contact_events` describes
(with supports of finite extent, the points leaving their rectangle too: ``off_edge``); the
events are located by :mod:`multiarm_pin.sim.event_location`.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from multiarm_pin.dynamics import Solution
from multiarm_pin.dynamics import solve as solve_dynamics
from multiarm_pin.dynamics.evaluation import baumgarte_gains
from multiarm_pin.exceptions import DynamicsError, MultiArmError
from multiarm_pin.model.rigid_object import ObjectState
from multiarm_pin.sim import contact_events as ce
from multiarm_pin.sim.closed_loop import closed_loop_evaluation, controller_torques
from multiarm_pin.sim.contact_events import ContactEvent
from multiarm_pin.sim.disturbances import WrenchSchedule
from multiarm_pin.sim.event_location import locate_off_edge, locate_separation, locate_touchdown
from multiarm_pin.spatial import integrate_quaternion
from multiarm_pin.system import ContactRows, MultiArmSystem, SystemState

ROWS_KEPT = 8
"""States whose contact rows :class:`Stepper` keeps for :meth:`Stepper.gaps` (a step's start,
its three stages, its end and a few event iterates)."""


class Stepper:
    """Evaluates the closed-loop dynamics on the active set and handles contact events.

    Attributes:
        active: (B, R) bool, the active set (rows of :meth:`MultiArmSystem.contact_blocks`).
        events: the contact events so far (:class:`ContactEvent`).
        finite_rows: (B, R) bool, the rows of supports with an ``extent`` (a rectangle).
        fallen: (B, R) bool, rows of finite supports that went below their plane while
            outside its rectangle and have not come back above it (never watched for a
            touchdown, nor counted as penetrating; :mod:`multiarm_pin.sim.contact_events`).
        beside_start: (B, R) bool, unilateral rows that started below their plane without
            touching (a fingertip of a joint that starts apart, beside its face: its gap is
            a distance to the face's extended plane) and have not come above it since: not
            counted as penetrating (the builder checked that no tip starts in the object).
        notes: notes of the run (the result's warnings), e.g. why it is not on a compiled loop.
    """

    def __init__(self, system: MultiArmSystem, controller, solver: str, baumgarte,
                 wrench: WrenchSchedule | None = None, torque_limit: np.ndarray | None = None):
        self.system = system
        self.controller = controller
        self.solver = solver
        # (nv,) |τ| bound [N m or N] of every joint, +inf where none; None: no saturation.
        # The applied torque is clip(τ_commanded, -limit, limit); the commanded torque of the
        # last evaluation is kept in `commanded` (the record's tau_commanded)
        self.torque_limit = torque_limit
        self.commanded = np.zeros(system.nv)
        # parsed once per run: the same tuple of floats at every evaluation (whose compiled
        # parameter vector CompiledSystem keeps)
        self.baumgarte = None if baumgarte is None else baumgarte_gains(baumgarte)
        self.wrench = wrench if wrench else None
        self.model = None if system.arm_set is None else system.arm_set.model
        self.unilateral = bool(system.contact_unilateral.any())
        self.active = system.contact_mask.copy()
        self.events: list[ContactEvent] = []
        self.notes: list[str] = []
        sup = system.supports
        self.edges = sup.finite  # some support is a rectangle: off-edge events
        self.finite_rows = np.zeros(system.contact_mask.shape, dtype=bool)
        if self.edges:
            self.finite_rows[system.n_arms, :sup.n_rows] = sup.finite_rows
        self.fallen = np.zeros_like(self.finite_rows)
        self.beside_start = np.zeros_like(self.finite_rows)
        self._cache = None  # (t, state, active, result) of the last evaluation
        # id(state) -> (state, rows) of the last ROWS_KEPT states whose rows were evaluated
        # (the state is kept so that its id is not reused while the entry lives)
        self._rows: dict[int, tuple[SystemState, ContactRows]] = {}
        # _evaluate's fused branch, decided once: arms' bilateral rows only, no wrench and no
        # saturation (the fused kernels add the controller's torque as it is)
        self._fused = bool(system.n_arms and not self.unilateral and self.wrench is None
                           and not system.supports.n_rows and torque_limit is None)

    def evaluate(self, t: float, state: SystemState):
        """``(solution, evaluation, tau, rows)`` at ``(t, state)`` with the current active set.

        Errors carry the time (same type, message prefixed with ``t = ... s``).
        """
        c = self._cache
        if c is not None and c[0] == t and c[1] is state and np.array_equal(c[2], self.active):
            self.commanded = c[4]
            return c[3]
        try:
            out = self._evaluate(t, state)
            self._cache = (t, state, self.active.copy(), out, self.commanded)
            self._remember(state, out[3])
            return out
        except MultiArmError as exc:
            _with_time(exc, t)
            raise

    def stage(self, t: float, state: SystemState) -> Solution:
        """The solution at an integrator stage: :meth:`evaluate`'s, without what it is not read for.

        On the fused path (arms' bilateral rows only, no wrench) a stage state is new and
        evaluated once: no cache entry and no :class:`ContactRows` views are made for it.
        """
        if not self._fused:
            return self.evaluate(t, state)[0]
        try:
            return closed_loop_evaluation(self.system, self.controller, t, state, self.solver,
                                          self.baumgarte)[0]
        except MultiArmError as exc:
            _with_time(exc, t)
            raise

    def _evaluate(self, t: float, state: SystemState):
        s = self.system
        w = None if self.wrench is None else self.wrench(t)
        if not s.n_arms:
            full, rows = s.contact_blocks(state, None, None, self.baumgarte, w)
            return self._solve(t, full), None, np.zeros(0), rows
        if self._fused:
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
            if self.torque_limit is not None:  # the actuators saturate: τ applied = clip(τ)
                self.commanded = tau
                tau = np.clip(tau, -self.torque_limit, self.torque_limit)
            # with_torques's sum without its input checks: tau is checked (shape, finite)
            # and pad puts zeros on the padded dofs
            blocks = ev.blocks.replaced(h=ev.blocks.h + s.pad(tau))
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
        """Tangent ``[q̇ (nv); v̇ (nv); ṗ (3); q̇uat (4); ȧ (6)]``.

        Filled in place of one new array (the same values as concatenating
        ``quaternion_derivative`` and the rest: the quaternion rate in Python floats, the same
        IEEE operations in the same order).
        """
        nv = self.system.nv
        o = state.obj
        d = np.empty(2 * nv + 13)
        d[:nv] = state.v
        d[nv:2 * nv] = self.system.unpad(sol.qdd)
        tw = o.twist
        d[2 * nv:2 * nv + 3] = tw[:3]
        x, y, z, w = o.quaternion.tolist()
        wx, wy, wz = tw[3:].tolist()
        d[2 * nv + 3:2 * nv + 7] = (0.5 * (w * wx + wy * z - wz * y),
                                    0.5 * (w * wy + wz * x - wx * z),
                                    0.5 * (w * wz + wx * y - wy * x),
                                    0.5 * -(wx * x + wy * y + wz * z))
        d[2 * nv + 7:] = sol.a_o
        return d

    def advance(self, state: SystemState, d: np.ndarray, h: float) -> SystemState:
        """The state ``h`` [s] along the tangent ``d`` (:meth:`derivative`'s layout)."""
        nv = self.system.nv
        hd = h * d  # the same products as scaling each slice
        q = state.q if self.model is None else pin.integrate(self.model, state.q, hd[:nv])
        v = state.v + hd[nv:2 * nv]
        o = state.obj
        p = o.position + hd[2 * nv:2 * nv + 3]
        quat = o.quaternion + hd[2 * nv + 3:2 * nv + 7]
        quat = quat / math.sqrt(quat.dot(quat))  # np.linalg.norm's own formula, without its
        tw = o.twist + hd[2 * nv + 7:]           # generic checks
        return SystemState(q, v, ObjectState(p, quat, tw))

    def step(self, integrator: str, t: float, state: SystemState, sol: Solution,
             h: float) -> SystemState:
        """One step of size ``h`` [s] from ``(t, state)`` whose solution is ``sol``."""
        if integrator == "rk4":
            d1 = self.derivative(state, sol)
            s2 = self.advance(state, d1, 0.5 * h)
            d2 = self.derivative(s2, self.stage(t + 0.5 * h, s2))
            s3 = self.advance(state, d2, 0.5 * h)
            d3 = self.derivative(s3, self.stage(t + 0.5 * h, s3))
            s4 = self.advance(state, d3, h)
            d4 = self.derivative(s4, self.stage(t + h, s4))
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
        """Active at t = 0: bilateral rows, and unilateral rows whose gap is within ``±tol``.

        A row of a finite support is active only if its point is inside the rectangle. A
        fingertip that starts apart (``Joint.starts_apart``) beside its face has a negative
        gap to the face's extended plane: it touches nothing and is not active.
        """
        s = self.system
        touching = np.abs(rows.phi) <= tol
        if self.edges:
            touching &= self.rows_margins(rows) > 0.0
        self.active = s.contact_mask & (~s.contact_unilateral | touching)
        self.beside_start = np.zeros_like(self.active)
        self.beside_start[:s.n_arms] = (s.contact_mask & s.contact_unilateral & ~self.active
                                        & (rows.phi < -tol))[:s.n_arms]

    def update_beside_start(self, rows: ContactRows) -> None:
        """Clear :attr:`beside_start` on the rows above their plane or touching."""
        if self.beside_start.any():
            self.beside_start &= (rows.phi < -ce.GAP_TOLERANCE) & ~self.active

    # ------------------------------------------------------------------ finite supports
    def _margins(self, support_points: np.ndarray) -> np.ndarray:
        """(B, R) edge margins [m] from the support rows' (K, 3) world points (inf elsewhere)."""
        s = self.system
        out = np.full(s.contact_mask.shape, np.inf)
        if self.edges:
            out[s.n_arms, :s.supports.n_rows] = s.supports.edge_margins(support_points)
        return out

    def rows_margins(self, rows: ContactRows) -> np.ndarray:
        """(B, R) edge margins [m] of the rows' points: > 0 inside their support's rectangle.

        :meth:`~multiarm_pin.constraints.SupportSet.edge_margins` on the support block;
        ``+inf`` on the rows of infinite supports, the arms' rows and padding.
        """
        s = self.system
        return self._margins(rows.contact_points[s.n_arms, :s.supports.n_rows]
                             if self.edges else None)

    def edge_margins(self, state: SystemState) -> np.ndarray:
        """(B, R) edge margins [m] at a state (:meth:`rows_margins`; geometry only)."""
        if not self.edges:
            return self._margins(None)
        known = self._known_rows(state)
        if known is not None:
            return self.rows_margins(known)
        return self._margins(self.system.support_terms(state).contact_points)

    def beside(self, rows: ContactRows) -> np.ndarray | None:
        """(B, R) rows not on their support: outside its rectangle, or fallen; None: none can be.

        Their negative gaps are distances to the plane beside (or under) the support, not
        penetrations.
        """
        if not self.edges:
            return None
        return self.fallen | (self.rows_margins(rows) <= 0.0)

    def _update_fallen(self, state: SystemState) -> None:
        """Mark the rows below their plane while outside its rectangle; clear those back above."""
        g = self.gaps(state)
        outside = self.finite_rows & ~self.active & (self.edge_margins(state) <= 0.0)
        self.fallen = ((self.fallen | (outside & (g < -ce.GAP_TOLERANCE)))
                       & (g <= ce.GAP_TOLERANCE))

    def separations(self, t: float, sol, rows: ContactRows, keep=None) -> bool:
        """Drop active unilateral rows that the solution lets go; True if any was dropped.

        Rows of finite supports whose point is outside the rectangle leave first (event
        ``off_edge``); when there are any, only they leave now (the solution had them in the
        active set), the others are checked at the next call.

        ``keep``: (B, R) bool rows not to drop now (those that just touched down: they stay
        active until the next sample, where the check runs again).
        """
        if not self.unilateral:
            return False
        s = self.system
        if self.edges:  # rows whose point is outside its support's rectangle: off the edge
            off = self.active & self.finite_rows & (self.rows_margins(rows) <= 0.0)
            if off.any():  # ``sol`` had them: the others are checked on the new solution
                self._leave(t, off, "off_edge", rows)
                return True
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

    def _remember(self, state: SystemState, rows: ContactRows) -> None:
        """Keep the rows evaluated at ``state`` (the last :data:`ROWS_KEPT` states)."""
        memo = self._rows
        memo[id(state)] = (state, rows)
        if len(memo) > ROWS_KEPT:
            del memo[next(iter(memo))]  # the oldest (dicts keep insertion order)

    def _known_rows(self, state: SystemState) -> ContactRows | None:
        """The rows of ``state`` (this very object) if they were evaluated, else None.

        Rows depend on the state only (positions and velocities: not on the time, the
        torques, the active set, the wrench or Baumgarte), so any evaluation of the same
        state object gives them. States are never modified in place by the stepper.
        """
        hit = self._rows.get(id(state))
        return hit[1] if hit is not None and hit[0] is state else None

    def gaps(self, state: SystemState) -> np.ndarray:
        """(B, R) gaps [m] of every row at a state (not to be modified: may be shared).

        Those of a state the stepper evaluated already are reused.
        """
        known = self._known_rows(state)
        if known is not None:
            return known.phi
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
            ending = None  # (event kind, rows leaving) at the step's (new) end
            sep = locate_separation(self, integrator, t, state, sol, h, new, t_end)
            if sep is not None:
                theta_s, new, leaving = sep
                h = theta_s * h
                ending = ("separation", leaving)
            if self.edges:  # a point leaving its rectangle before that: the step ends there
                off = locate_off_edge(self, integrator, t, state, sol, h, new)
                if off is not None:
                    theta_e, new, leaving = off
                    h = theta_e * h
                    ending = ("off_edge", leaving)
            watch = self._watch()
            # a row far below the band at the step's start is not watched: its tip went
            # round an edge, behind the (infinite) plane of its face, and touches nothing
            watch &= self.gaps(state) >= -ce.LOST_GAP
            if self.edges:  # a point outside its rectangle all along touches nothing
                self._update_fallen(state)
                watch &= ~self.fallen & ((self.edge_margins(state) > 0.0)
                                         | (self.edge_margins(new) > 0.0))
            g_hi = float(self.gaps(new)[watch].min()) if watch.any() else 0.0
            if g_hi >= -tol:
                if ending is None:
                    return new
                t, state = t + h, new
                self._leave(t, ending[1], ending[0], state=state)
                sol = self._settled(t, state)
                if t_end - t <= ce.TIME_TOLERANCE:
                    return state
                continue
            theta, s_e = locate_touchdown(self, integrator, t, state, sol, h, watch, g_hi)
            t = t + theta * h
            if self.edges and not self._lands(t, s_e, watch):
                # the row reaching the plane is beside the rectangle: no touchdown, the step
                # is split there (that row is fallen now)
                state = s_e
                sol = self._settled(t, state)
                if t_end - t <= ce.TIME_TOLERANCE:
                    return state
                continue
            state, joined = self._impact(t, s_e, watch)
            sol = self._settled(t, state, keep=joined)
            if t_end - t <= ce.TIME_TOLERANCE:
                return state
        raise DynamicsError(f"t = {t:.6g} s: more than {ce.MAX_EVENTS_PER_STEP} contact events "
                            "in one step")

    def _settled(self, t: float, state: SystemState, keep=None) -> Solution:
        """The solution at ``(t, state)`` once the rows it lets go have left the active set.

        ``keep``: rows that may not leave (as :meth:`separations` takes it).
        """
        sol, _, _, rows = self.evaluate(t, state)
        if self.separations(t, sol, rows, keep=keep):
            sol = self.evaluate(t, state)[0]
        return sol

    def _leave(self, t: float, leaving: np.ndarray, kind: str, rows: ContactRows | None = None,
               state: SystemState | None = None) -> None:
        """Drop ``leaving`` rows from the active set, with their events (``kind``) at ``t``.

        ``rows``: the rows at ``t``, or None to get them at ``state`` (only if a row leaves).
        """
        leaving = leaving & self.active
        if not leaving.any():
            return
        if rows is None:
            rows = self.rows_at(t, state)
        for b, r in zip(*np.nonzero(leaving), strict=True):
            self._event(t, kind, b, r, phi_dot=float(rows.phi_dot[b, r]),
                        phi_dot_after=float(rows.phi_dot[b, r]))
        self.active = self.active & ~leaving

    def _lands(self, t: float, state: SystemState, watch: np.ndarray) -> bool:
        """True if a watched row reaching its plane at a located touchdown is inside its rectangle.

        The watched rows at the plane but outside their rectangle become fallen.
        """
        rows = self.rows_at(t, state)
        at_plane = watch & (rows.phi <= ce.GAP_TOLERANCE)
        inside = self.rows_margins(rows) > 0.0
        self.fallen |= at_plane & ~inside
        return bool((at_plane & inside).any())

    def _impact(self, t: float, state: SystemState, watch: np.ndarray
                ) -> tuple[SystemState, np.ndarray]:
        """Apply the impact law at a touchdown, update the active set.

        Returns:
            The state after the impact and the (B, R) mask of rows that joined the active set.
        """
        from multiarm_pin.dynamics.unilateral import solve_impact

        s = self.system
        full, rows = self.blocks_at(t, state)
        touching = watch & (rows.phi <= ce.GAP_TOLERANCE)
        if self.edges:  # only inside its support's rectangle
            touching &= self.rows_margins(rows) > 0.0
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

    def blocks_at(self, t: float, state: SystemState, reference: bool = False):
        """``(blocks, rows)`` of every contact row at a state, without torques.

        The impact law uses only ``M``, ``W``, ``W_o`` and ``M_o``: no controller call.
        ``reference``: the arms' blocks by the numpy reference (``MultiArmSystem.blocks``),
        equal to the compiled ones to round-off, without compiling the Python path's
        evaluation kernel (``evaluate_state``) for one call; their rows are not kept for
        reuse (the stepper's steps reuse only rows of its own path).
        """
        s = self.system
        w = None if self.wrench is None else self.wrench(t)
        if not s.n_arms:
            out = s.contact_blocks(state, None, None, self.baumgarte, w)
        else:
            ev = s.blocks(state, None, self.baumgarte, reference=reference)
            out = s.contact_blocks(state, ev.blocks, ev.constraints, self.baumgarte, w)
        if not reference:
            self._remember(state, out[1])
        return out

    def rows_at(self, t: float, state: SystemState) -> ContactRows:
        """The :class:`ContactRows` at a state: :meth:`blocks_at`'s, reused if known."""
        known = self._known_rows(state)
        return known if known is not None else self.blocks_at(t, state)[1]


def _with_time(exc: MultiArmError, t: float) -> None:
    """Prefix the error's message with ``t = ... s`` (once)."""
    if exc.args and isinstance(exc.args[0], str) and not exc.args[0].startswith("t = "):
        exc.args = (f"t = {t:.6g} s: {exc.args[0]}", *exc.args[1:])
