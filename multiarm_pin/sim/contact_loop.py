"""The compiled loop of :func:`~multiarm_pin.sim.simulation.simulate`: steps and events in one call.

Every arm–object joint is made of point contacts (the thesis's ch. 3): a run's rows are
contact rows, bilateral or unilateral (fingertips, supports). When a run has RK4 or
semi-implicit Euler, a compiled solver (:data:`~multiarm_pin.sim.closed_loop.FUSED_SOLVERS`),
arms the compiled rigid-body pass supports (or no arms), and zero torque, an
:class:`~multiarm_pin.sim.controllers.ObjectPD` on its compiled path or a
:class:`~multiarm_pin.sim.controllers.PhasedPD`, :class:`ContactLoop` runs stretches of
samples, separations, touchdowns and impacts included, in one call of
:func:`multiarm_pin._compiled.contact_loop.run_contact_rk4`, which mirrors the
:class:`~multiarm_pin.sim.stepper.Stepper` and :mod:`multiarm_pin.sim.event_location` step for
step (the same evaluations in the same order, so the same event times to round-off). Its events
become the stepper's :class:`~multiarm_pin.sim.contact_events.ContactEvent` records, and the
controller's hold-still onsets its warnings.

What the kernel cannot decide as the Python path would (a doubtful controller or solver case,
NaN, too many events in one step, a step that starts or ends with a support point off its
rectangle, a row fallen past an edge) it hands back with the sample whose step the stepper then
takes in Python (which raises, falls back or decides exactly as before); the next stretch goes
to the kernel again. The results equal the stepper's to round-off (tests:
``tests/test_contact_loop.py``, ``tests/test_compiled_loop.py``,
``tests/test_compiled_loop_runs.py``).

Twins: ``multiarm_pin._compiled.contact_loop`` (this module's kernel, the compiled layer's side
of the same concept, the loop: :class:`ContactLoop` is its Python driver).
"""

from __future__ import annotations

import numpy as np

from multiarm_pin._compiled import contact_loop as kernels
from multiarm_pin._compiled import layout, mlcp
from multiarm_pin.dynamics.solve import SOLVERS
from multiarm_pin.dynamics.unilateral import UNILATERAL_SOLVERS
from multiarm_pin.model.rigid_object import ObjectState
from multiarm_pin.sim import contact_events as ce
from multiarm_pin.sim import event_location as el
from multiarm_pin.sim.closed_loop import FUSED_SOLVERS
from multiarm_pin.sim.disturbances import WrenchSchedule
from multiarm_pin.sim.result import Recorder
from multiarm_pin.system import SystemState

RECORDED_SOLVERS = {True: UNILATERAL_SOLVERS,
                    False: (SOLVERS["object_first"].name,) * len(UNILATERAL_SOLVERS)}
"""The solver recorded at the kernel's samples, by whether the run has unilateral rows, then by
the kernel's code (``SOLVER_BILATERAL``, ``SOLVER_ACTIVE_SET``): with unilateral rows the
names ``solve_unilateral`` records; without, the object-first solve's registry name, which
``solve`` records for ``auto`` and ``object_first`` (the kernel's code is then always
``SOLVER_BILATERAL``)."""

EVENT_KINDS = {kernels.EVENT_SEPARATION: "separation", kernels.EVENT_TOUCHDOWN: "touchdown"}
"""Event kind codes of the kernel's table."""

EVENT_ROWS = 4096
"""Rows of the event table of one call at the least (the kernel hands back before it can
overflow)."""

HOLD_REASON = ("the touching contacts cannot make every object wrench (rank {rank} < 6); "
               "holding the arms still (gravity compensation and joint PD)")
"""``ObjectPD``'s warning at a hold-still onset, after ``t = ... s: object_pd: ``."""

FINITE_SUPPORTS_NOTE = ("supports with an extent (finite rectangles): the steps that start or "
                        "end with a support point off its rectangle are taken by the Python "
                        "stepper, not the compiled contact loop (which locates no off-edge "
                        "event)")
"""The note, once in a run's warnings, of a run that had such a step: the kernel handed it
back (``STAGE_OFF_RECTANGLE``) or was not called while a row was fallen past its support's
edge. A run whose support points all stay on their rectangles has no such note."""


def rules_vector() -> np.ndarray:
    """The kernel's rules (:data:`~multiarm_pin._compiled.contact_loop.EVENT_CONSTANTS`)."""
    values = {name: getattr(ce, name) for name in kernels.EVENT_CONSTANTS[:11]}
    values.update(RESTING_RELEASE=el.RESTING_RELEASE, MAX_ITERATIONS=el.MAX_ITERATIONS,
                  DEPENDENCY_RTOL=mlcp.DEPENDENCY_RTOL, VIOLATION_RTOL=mlcp.VIOLATION_RTOL,
                  CONSISTENCY_RTOL=mlcp.CONSISTENCY_RTOL)
    return np.array([float(values[name]) for name in kernels.EVENT_CONSTANTS])


def _i64(a) -> np.ndarray:
    return np.array(a, dtype=np.int64, order="C")


def _f64(a) -> np.ndarray:
    return np.array(a, dtype=float, order="C")


def _same(a: np.ndarray, dtype) -> np.ndarray:
    """``a`` itself when it is C-contiguous of ``dtype`` (its flags kept), else such a copy."""
    return np.ascontiguousarray(a, dtype=dtype)


def _read_only(a: np.ndarray) -> np.ndarray:
    """A read-only view of ``a``.

    The kernel's argument types then do not depend on the caller's flags: one compiled
    specialisation for every run.
    """
    view = a.view()
    view.setflags(write=False)
    return view


class ContactLoop:
    """Stretches of steps with contact events in single compiled calls (see the module).

    Use :meth:`for_run`, which returns None when the run is not of the kind the kernel does.

    Args:
        stepper: the run's stepper (its system, controller, Baumgarte gains, wrench, active
            set and events).
        integrator: ``"rk4"`` or ``"semi_implicit"`` (``Stepper.step``'s two branches).
    """

    def __init__(self, stepper, integrator: str = "rk4"):
        from multiarm_pin.dynamics.object_first import DEFAULT_RCOND_TOL, OBJECT_RCOND_TOL
        from multiarm_pin.sim.controllers import controller_kernel

        s = stepper.system
        self.stepper = stepper
        self.system = s
        # the controller whose compiled inputs the kernel reads; None: zero torque
        self.kernel_name = controller_kernel(stepper.controller)[0]
        zero = self.kernel_name == "zero_torque"
        self.controller = None if zero else stepper.controller
        n, B, R = s.n_arms, s.n_blocks, s.rows_max
        nq, nv = s.nq, s.nv
        table = s._contact_rows
        if n:
            path = s.compiled
            model = s.arm_set.compiled_model
            params = path.params
            k, m = int(path.dims[layout.DIMS_K]), int(path.dims[layout.DIMS_M])
            # the compiled path's own tables (not copies): the kernels they share with it are
            # compiled for one set of argument types (their read-only flags included)
            arm = (_same(model.ints, np.int64), _same(model.floats, float),
                   _same(path.arm_table, np.int64), _same(path.v_starts, np.int64),
                   _same(path.contact_tables.ints, np.int64),
                   _same(path.contact_tables.floats, float))
            dims, N = _i64(path.dims), _same(path.N, np.int64)
            nv_arm = _i64(path.nv_arm)
            buf = np.zeros(path.layout.size)
        else:
            params = layout.parameter_vector(s.obj.mass, s.obj.inertia, s.gravity,
                                             DEFAULT_RCOND_TOL, OBJECT_RCOND_TOL)
            k, m = 1, 0
            arm = (np.zeros((0, layout.MODEL_INTS), np.int64),
                   np.zeros((0, layout.MODEL_FLOATS)), np.zeros((0, 1), np.int64),
                   np.zeros(0, np.int64), np.zeros((0, layout.CONTACT_INTS), np.int64),
                   np.zeros((0, layout.CONTACT_FLOATS)))
            dims = _i64(layout.dims_vector(1, 0, 0, 0))
            N, nv_arm = np.zeros(0, np.int64), np.zeros(0, np.int64)
            buf = np.zeros(0)
        params = params.copy()  # writable, as with_baumgarte's copy: one type for the kernels
        if stepper.baumgarte is not None:
            params = layout.with_baumgarte(params, *stepper.baumgarte)
        kc = k if n else table.nv_max_blocks
        sp_p, sp_n, sp_a = s.supports.tables()
        wrenches = (np.zeros((0, layout.WRENCH_WIDTH)) if stepper.wrench is None
                    else _f64(stepper.wrench.table()))
        # N_blocks read-only, as the compiled path's N: object_first, which takes either,
        # is compiled once
        self.S = (*arm, _f64(params), dims, N, nv_arm, sp_p, sp_n, sp_a,
                  np.array(s.contact_unilateral), np.array(s.contact_mask),
                  _i64(table.nv_blocks), _read_only(_i64(table.N_blocks)),
                  _f64(s.contact_restitution),
                  wrenches, rules_vector())
        nd = 2 * nv + layout.OBJECT_STATE_SIZE
        nx = layout.state_size(nq, nv)
        self._nx = nx
        self.W = (np.zeros((6, nv)), np.zeros((6, nv)), np.zeros((nv, nv)), np.zeros(nv),
                  np.zeros((n, 4, 4)), np.zeros(layout.ENERGY_SIZE), buf,
                  np.zeros((B, kc, kc)), np.zeros((B, kc)), np.zeros((B, kc, R)),
                  np.zeros((B, 6, R)), np.zeros((B, R)), np.zeros((6, 6)), np.zeros(6),
                  np.zeros((B, R)), np.zeros((B, R)), np.zeros((B, R, 3)),
                  np.zeros((B, R, 3)))
        # the semi-implicit step's rotation workspace, None for RK4: the integrator is then in
        # the loop's argument types, and a run compiles the step of its integrator only
        self.K = (np.zeros(nd), np.zeros(nd), np.zeros(nd), np.zeros(nd), np.zeros(nx),
                  np.zeros(nd), np.zeros((3, 3)) if integrator == "semi_implicit" else None)
        self.Z = (np.zeros(nd), np.zeros((B, R)), np.zeros((B, R)), np.zeros((B, R)),
                  np.zeros(2, np.int64))
        boolean = np.zeros((B, R), dtype=bool)
        self.L = (np.zeros(nx), np.zeros(nx), np.zeros(nx), np.zeros((B, R)), np.zeros((B, R)),
                  np.zeros((B, R)), boolean.copy(), boolean.copy(), boolean.copy(),
                  boolean.copy(), np.zeros(nd), np.zeros(nx), boolean.copy(), np.zeros(nq))
        self.I = (boolean.copy(), boolean.copy(), boolean.copy(), np.zeros((B, R)), np.zeros(6),
                  np.zeros((B, kc)), np.zeros((B, R)), np.zeros((B, R)), np.zeros((B, kc)),
                  np.zeros(6))
        self._k, self._m, self._kc = k, m, kc
        # a step adds at most 4 B R events per event it handles (separations, touchdowns, the
        # impact's separations, separations after it): the kernel hands back before a step
        # when fewer rows than that are free
        self.reserve = 4 * (int(ce.MAX_EVENTS_PER_STEP) + 2) * B * R + 8
        self.events = np.zeros((max(EVENT_ROWS, 2 * self.reserve), kernels.EVENT_WIDTH))
        self.n_events = np.zeros(1, np.int64)
        self.control = np.zeros(3, np.int64)
        # a hold-still onset follows a change of the active set: at most one per event
        self.onsets = np.zeros((len(self.events) + 1, kernels.HOLD_WIDTH))
        self.n_onsets = np.zeros(1, np.int64)
        self.q_hold = np.zeros(nq)
        self.last_status = kernels.STAGE_OK
        # (controller tuple, events, the kernel's entry point, fn and advance for its types)
        self._kernel = None
        # the loop with its event machinery (separations, touchdowns, the active-set solve):
        # from the start with supports or without arms (every evaluation may need the
        # active-set solve), else from the first step that needs it (kernels.loop_functions)
        self.with_events = bool(s.supports.n_rows) or not n
        self._kept_controller = None  # (controller inputs, the kernel's controller tuple)
        # (controller tuple, events, the arms' dofs in tau, evaluate_once's entry, held, fn)
        self._evaluator = None
        self._zero_x = np.zeros(nv)
        self.beside = np.zeros((B, R), dtype=bool)  # the stepper's beside_start, in and out

    CONTROLLER_KERNELS = ("zero_torque", "object_pd", "phased_pd")
    """The compiled controllers the kernel runs (names of
    :data:`~multiarm_pin.sim.controllers.CONTROLLER_KERNELS`)."""

    @classmethod
    def declines(cls, stepper, integrator: str) -> str | None:
        """Why a run is not of the kind the kernel does, or None when it is.

        It does: RK4 or semi-implicit Euler, a compiled solver
        (:data:`~multiarm_pin.sim.closed_loop.FUSED_SOLVERS`: ``auto`` and ``object_first``,
        the ones that also serve unilateral rows), rows bilateral or unilateral (fingertips,
        supports), arms whose every joint the compiled rigid-body pass supports (or none), a
        controller whose registry entry's kernel
        (:func:`~multiarm_pin.sim.controllers.controller_kernel`) is one of
        :data:`CONTROLLER_KERNELS`, and no external wrench or a
        :class:`~multiarm_pin.sim.disturbances.WrenchSchedule` itself (its intervals are the
        kernel's table; a subclass with its own ``__call__`` is not), and no torque
        saturation. Supports with an ``extent`` are served while every support point is
        inside its rectangle at a step's start and end (the kernel hands back the other
        steps, and the run then notes it: :data:`FINITE_SUPPORTS_NOTE`); fingertips that
        start beside their face are kept out of the recorded penetration as the stepper does
        (:attr:`Stepper.beside_start`). Without unilateral rows, every arm has at least as
        many joints as rows (the object-first solve's case; the kernel's mixed LCP would
        otherwise take the step that ``solve`` gives the singular-arm variant).
        """
        from multiarm_pin.sim.controllers import controller_kernel

        s = stepper.system
        if integrator not in ("rk4", "semi_implicit"):
            return (f"integrator {integrator!r} has no compiled loop (RK4 and semi-implicit "
                    "Euler only)")
        if stepper.solver not in FUSED_SOLVERS:
            return f"solver {stepper.solver!r} has no compiled path"
        if stepper.torque_limit is not None:
            return "torque saturation"  # the kernel adds the controller's torque as it is
        if stepper.wrench is not None and type(stepper.wrench) is not WrenchSchedule:
            return f"the external wrench is a {type(stepper.wrench).__name__}"
        if s.n_arms and (s.compiled is None or s.arm_set.compiled_model is None):
            return unsupported_joints_note(s)
        if not stepper.unilateral and s.n_arms and np.any(s.compiled.nv_arm < s.compiled.N):
            # solve_auto's singular-arm variant, or object_first's error, at every step
            return "an arm has fewer joints than rows (a singular arm at every step)"
        kernel, why = controller_kernel(stepper.controller)
        if kernel not in cls.CONTROLLER_KERNELS:
            return why or (f"the compiled loop runs the controllers "
                           f"{', '.join(cls.CONTROLLER_KERNELS)}, not {kernel}")
        if kernel != "zero_torque" and not s.n_arms:  # pragma: no cover - no arms, no control
            return "a controller without arms"
        return None

    @classmethod
    def for_run(cls, stepper, integrator: str) -> ContactLoop | None:
        """The contact loop of a run, or None when :meth:`declines` gives a reason."""
        return None if cls.declines(stepper, integrator) else cls(stepper, integrator)

    def ready(self, state: SystemState) -> bool:
        """True when the kernel can take the steps from ``state``.

        The first time, an ``object_pd`` controller fixes its state from a reference (numpy)
        evaluation of ``state`` (:meth:`ObjectPD.prepare`). Not while a row of a finite
        support is fallen past its edge (:attr:`Stepper.fallen`): the stepper's.
        """
        if self.stepper.fallen.any():
            return False
        ctrl = self.controller
        if ctrl is None:
            return True
        if ctrl.kernel_inputs() is None:
            s = self.system
            ctrl.prepare(state, s.blocks(state, None, self.stepper.baumgarte, reference=True))
        return ctrl.kernel_inputs() is not None

    def _controller(self) -> tuple:
        """The controller tuple of the kernel (``object_pd``'s inputs, or placeholders).

        Built again only when the controller's inputs are new arrays (kept otherwise: its
        arrays are the kernel's workspace and the controller's own); the controller's hold
        state is copied in at every call.
        """
        s = self.system
        n, m, k = s.n_arms, self._m, self._k
        ctrl = self.controller
        if ctrl is None:
            inputs = None
        else:
            inputs = ctrl.kernel_inputs()
            self.control[kernels.CTL_HOLDING] = int(bool(ctrl.holding))
            self.control[kernels.CTL_MARGIN_KEPT] = int(bool(ctrl.margin_kept))
            if ctrl.holding and ctrl._q_hold is not None:
                self.q_hold[:] = ctrl._q_hold
        kept = self._kept_controller
        if kept is not None and kept[0] is inputs:
            return kept[1]
        K = s.supports.n_rows
        if inputs is None:
            self.control[kernels.CTL_MODE] = kernels.CONTROL_NONE
            values = (np.zeros((1, layout.TRAJECTORY_WIDTH)), np.zeros(layout.PD_GAINS_SIZE),
                      np.zeros(2), np.zeros((n, 1, 3)), np.zeros((n, 1, 3)),
                      np.zeros(n, np.int64), np.zeros(layout.HOLD_GAINS_SIZE),
                      np.zeros((n, m), np.uint8), np.zeros((n, m), bool), np.zeros(s.nq))
        else:
            self.control[kernels.CTL_MODE] = kernels.CONTROL_OBJECT_PD
            values = inputs
        if self.kernel_name == "phased_pd":
            self.control[kernels.CTL_MODE] = kernels.CONTROL_PHASED
            arrays = (*ctrl.phase_arrays(), ctrl.offset_start)
        else:  # placeholders of the same types
            arrays = (np.zeros((1, layout.PHASE_SIZE)), np.zeros((1, K), bool),
                      np.zeros((1, n), bool), np.zeros((1, n), bool), np.zeros((1, n, 3)),
                      np.zeros((1, n, m)), np.zeros((n, 3)))
        # the phased controller's tables (read only: one type for every run), then its
        # planned support forces and object acceleration
        phased = (*(_read_only(a) for a in arrays), np.zeros(K), np.zeros(6))
        (traj, pd_gains, null_gains, hold_tool, hold_obj, hold_n, gains, qp_active,
         unilateral, q_ref) = values
        traj, unilateral = _read_only(traj), _read_only(unilateral)  # one type for every run
        self._O = (np.zeros(6), np.zeros((s.n_blocks, self._kc)),
                   np.zeros((s.n_blocks, s.rows_max)), np.zeros((s.n_blocks, s.rows_max)),
                   np.zeros((s.n_blocks, s.rows_max)), np.zeros((n, k)), np.zeros(s.nv),
                   np.zeros((n, k)), np.zeros(layout.REFERENCE_SIZE), np.zeros((3, 3)),
                   np.zeros((n, m)), np.zeros((n, k)), np.zeros(hold_tool.shape), np.zeros(6))
        C = (self.control, traj, pd_gains, null_gains, hold_tool, hold_obj, hold_n, gains,
             qp_active, unilateral, q_ref, self.q_hold, self.onsets, self.n_onsets,
             np.zeros((n, m), np.uint8), np.zeros((n, m), bool), np.zeros((n, m), bool),
             self._free_gains(gains), phased)
        self._kept_controller = (inputs, C)
        return C

    @staticmethod
    def _free_gains(gains: np.ndarray) -> np.ndarray:
        """The hold gains with no margin: ``object_pd``'s least-norm fallback."""
        out = np.array(gains, dtype=float)
        out[layout.GAIN_MARGIN] = 0.0
        return out

    def _arguments(self, rec: Recorder, x: np.ndarray, times: np.ndarray, k0: int, k1: int,
                   C: tuple, active: np.ndarray, codes: np.ndarray) -> tuple:
        """The arguments of the contact kernel (``run_contact_rk4``) before ``fn``."""
        self.n_events[0] = 0
        self.n_onsets[0] = 0
        self.Z[4][0] = 0  # no evaluation to reuse at the first sample
        Rec = (rec.q, rec.v, rec.p, rec.quat, rec.twist, rec.tau, rec.mu, rec.phi,
               rec.phi_dot, rec.points, rec.normals, rec.a_o, rec.qdd, rec.violation,
               rec.wrench, rec.ke, rec.pe, rec.momentum, rec.active, codes, self.beside)
        head = (k0, k1, times, x, active, self.S, C, self.W, self._O, self.K, self.Z, self.L,
                self.I, self.events, self.n_events, self.reserve, Rec)
        if self._kernel is None or self._kernel[0] is not C or self._kernel[1] != self.with_events:
            # the loop's entry point and its stages, for these types (the entry point without
            # numba's dispatch, which would type the function pointers again at every call)
            self._kernel = (C, self.with_events,
                            *kernels.loop_functions(head, self.with_events))
        return head

    def run(self, rec: Recorder, state: SystemState, times: np.ndarray, k0: int, k1: int
            ) -> tuple[int, SystemState]:
        """Samples ``k0 .. k1 - 1`` by the kernel, from ``state`` at sample ``k0``.

        Args:
            rec: the run's recorder (filled in place).
            state: the state at sample ``k0``.
            times: the run's time grid [s].
            k0: first sample.
            k1: one past the last sample.

        Returns:
            ``(k, state)``: the sample reached and its state. ``k == k1`` when every sample
            was done; otherwise (:attr:`last_status` says why) the stepper takes the step
            from sample ``k``, or, with ``STAGE_EVENTS_FULL``, the kernel is called again.
        """
        s = self.system
        stepper = self.stepper
        o = state.obj
        x = layout.state_vector(o.position, o.quaternion, o.twist, state.q, state.v,
                                self._zero_x)
        C = self._controller()
        active = np.array(stepper.active, dtype=bool)
        self.beside[:] = stepper.beside_start
        codes = np.zeros(len(times), np.int64)
        args = self._arguments(rec, x, times, k0, k1, C, active, codes)
        status, k = self._kernel[2](*args, *self._kernel[3:])
        self.last_status = int(status)
        k = int(k)
        # the samples recorded: up to k, and k itself when its step failed (it is recorded
        # again by the stepper, with the same values)
        done = slice(k0, k)
        rec.t[done] = times[done]
        names = RECORDED_SOLVERS[bool(stepper.unilateral)]
        for j in range(k0, k):
            rec.solver[j] = names[int(codes[j])]
        if k > k0:
            rec.mark_recorded(k)
        for row in self.events[:int(self.n_events[0])]:
            t, kind, b, r, before, after, impulse, rebound = row.tolist()
            stepper._event(t, EVENT_KINDS[int(kind)], int(b), int(r), phi_dot=before,
                           phi_dot_after=after, impulse=impulse, rebound=bool(rebound))
        stepper.active = active & s.contact_mask
        stepper.beside_start = self.beside.copy()
        ctrl = self.controller
        if ctrl is not None:
            for t, rank in self.onsets[:int(self.n_onsets[0])].tolist():
                ctrl.warnings.append(f"t = {t:.6g} s: object_pd: "
                                     + HOLD_REASON.format(rank=int(rank)))
            ctrl.holding = bool(self.control[kernels.CTL_HOLDING])
            ctrl.margin_kept = bool(self.control[kernels.CTL_MARGIN_KEPT])
            if ctrl.holding:
                ctrl._q_hold = self.q_hold.copy()
        state = state_from_vector(x, s.nq, s.nv)
        if self.last_status == kernels.STAGE_EVENTS_NOT_COMPILED:
            self.with_events = True  # from here on the loop with its events
            return self.run(rec, state, times, k, k1)
        return k, state

    def evaluate(self, t: float, state: SystemState) -> tuple[int, np.ndarray, np.ndarray]:
        """One evaluation at ``(t, state)`` on the stepper's active set, as the loop makes it.

        The compiled rigid-body pass, the rows and blocks, the controller's torques and the
        solve (:func:`~multiarm_pin._compiled.contact_loop.contact_stage`), no separation, no
        event, no record: what :func:`~multiarm_pin.sim.closed_loop.closed_loop_evaluation`
        computes with Pinocchio and numpy (the stepper's evaluation). The loop must be
        :meth:`ready` at ``state``. The loop's tuples are held once with its entry point
        (:func:`~multiarm_pin._compiled.held.hold`): a call unboxes one pointer for them. For
        tests and benchmarks.

        Returns:
            ``(status, tangent (2 nv + 13,), tau (nv,) [N m])``: ``STAGE_OK`` or why the
            stepper must decide; the tangent ``[q̇; v̇; ṗ; q̇uat; ȧ]`` as
            ``Stepper.derivative``.
        """
        s = self.system
        C = self._controller()
        o = state.obj
        x = layout.state_vector(o.position, o.quaternion, o.twist, state.q, state.v,
                                self._zero_x)
        active = np.array(self.stepper.active, dtype=bool)
        d = np.empty(2 * s.nv + layout.OBJECT_STATE_SIZE)
        kept = self._evaluator
        if kept is None or kept[0] is not C or kept[1] != self.with_events:
            kept = self._evaluator = (
                C, self.with_events, np.flatnonzero(s.arm_set.dof_mask) if s.n_arms else None,
                *kernels.evaluate_functions((float(t), x, active, self.S, C, self.W, self._O,
                                             d), self.with_events))
        entry, held, fn = kept[3:]
        status, _ = entry(float(t), x, active, held, d, fn)
        if status == kernels.STAGE_EVENTS_NOT_COMPILED:
            self.with_events = True
            return self.evaluate(t, state)
        tau = self._O[5]  # (n, k) padded
        return int(status), d, tau.take(kept[2]) if s.n_arms else np.zeros(0)


def unsupported_joints_note(system) -> str:
    """Why a system's arms are not on the compiled loop (a sentence).

    It names the first joint whose kind the compiled rigid-body pass does not support.
    """
    from multiarm_pin.model.compiled_model import unsupported_joints

    name, kind = unsupported_joints(system.arm_set.model)[0]
    return (f"joint {name!r} is of kind {kind}, which the compiled rigid-body pass does not "
            "support")


def state_from_vector(x: np.ndarray, nq: int, nv: int) -> SystemState:
    """The :class:`SystemState` (copies) of a kernels' state vector ``x``.

    ``x`` in :func:`~multiarm_pin._compiled.layout.state_vector`'s layout.
    """
    q0 = layout.OBJECT_STATE_SIZE
    return SystemState(x[q0:q0 + nq].copy(), x[q0 + nq:q0 + nq + nv].copy(),
                       ObjectState(x[layout.X_POSITION:layout.X_POSITION + 3].copy(),
                                   x[layout.X_QUATERNION:layout.X_QUATERNION + 4].copy(),
                                   x[layout.X_TWIST:layout.X_TWIST + 6].copy()))


__all__ = ["EVENT_KINDS", "RECORDED_SOLVERS", "ContactLoop", "rules_vector", "state_from_vector",
           "unsupported_joints_note"]
