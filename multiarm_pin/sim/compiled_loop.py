"""The compiled closed loop of :func:`~multiarm_pin.sim.simulation.simulate`: steps in one call.

When a run is a system of arms whose rows are bilateral, or unilateral and all touching, with
no supports (an external wrench schedule may act), under ``object_pd`` with a compiled solver
and RK4 or semi-implicit Euler, every evaluation of a step is the same compiled sequence (arm
terms, blocks, controller, object-first solve) and the Python around it (the stepper's state
objects, the record) is most of the cost. :class:`CompiledLoop` then runs stretches of steps
in one call of :func:`multiarm_pin._compiled.closed_loop.run_rk4`, which computes the arm
terms itself (:func:`multiarm_pin._compiled.rigid_body.rigid_body_pass`, Pinocchio's
algorithms in numba, tested against Pinocchio) and records every sample straight into the run's
:class:`~multiarm_pin.sim.result.Recorder`.

Whatever the kernel cannot decide as the Python path would (a doubtful controller or solver
case, NaN, a unilateral row that stops pushing or separates) it hands back with the sample
where it stopped; :func:`~multiarm_pin.sim.simulation.simulate` takes that step with the
contact loop (:class:`~multiarm_pin.sim.contact_loop.ContactLoop`, which locates the event in
its own kernel) or the :class:`~multiarm_pin.sim.stepper.Stepper` (which raises, falls back or
locates the event exactly as before) and hands the next stretch to the kernel again. The
results equal the Python path's to round-off (tests: ``tests/test_compiled_loop.py``).
"""

from __future__ import annotations

import numpy as np

from multiarm_pin._compiled import closed_loop as kernels
from multiarm_pin._compiled import layout
from multiarm_pin.dynamics.solve import SOLVERS
from multiarm_pin.dynamics.unilateral import UNILATERAL_SOLVERS
from multiarm_pin.model.rigid_object import ObjectState
from multiarm_pin.sim import contact_events as ce
from multiarm_pin.sim.closed_loop import FUSED_SOLVERS
from multiarm_pin.sim.disturbances import WrenchSchedule
from multiarm_pin.sim.result import Recorder
from multiarm_pin.system import SystemState

RECORDED_SOLVER = {False: SOLVERS["object_first"].name, True: UNILATERAL_SOLVERS[0]}
"""The solver recorded at the kernel's samples (the result's ``solver``), as the Python path
names it, by whether the run has unilateral rows: ``object_first`` (the registry's) for
bilateral rows; with unilateral rows, all pushing, the mixed LCP's fast path ``bilateral``
(the same object-first solve)."""


class CompiledLoop:
    """Stretches of RK4 (or semi-implicit Euler) steps of one run in single compiled calls.

    See the module.

    Use :meth:`for_run`, which returns None when the run is not of the kind the kernel does.

    Args:
        stepper: the run's stepper (its system, controller, solver, Baumgarte gains).
        integrator: ``"rk4"`` or ``"semi_implicit"``.
    """

    def __init__(self, stepper, integrator: str = "rk4"):
        s = stepper.system
        self.stepper = stepper
        self.system = s
        path = s.compiled
        self.path = path
        self.model = s.arm_set.compiled_model
        params = layout.with_integrator(path.params, integrator)
        if stepper.baumgarte is not None:
            params = layout.with_baumgarte(params, *stepper.baumgarte)
        self.params = params
        # the semi-implicit step's workspace, None for RK4: the integrator is then in the
        # loop's argument types, and a run compiles the step of its integrator only
        self._semi = np.zeros(s.nv) if integrator == "semi_implicit" else None
        n, k, m = s.n_arms, s.arm_set.nv_max, s.N_max
        self.work = (*self.model.outputs(), np.zeros(path.layout.size), np.zeros((n, k)),
                     np.zeros((n, m)), np.zeros((n, k)))
        self.separation = np.array([ce.SEPARATION_GAP, ce.SEPARATION_SPEED])
        self._stage_args = None  # evaluate()'s kernel arguments, made once per controller
        self._callees = None  # evaluate()'s stage's callees (closed_loop.stage_entry)
        # (controller's trajectory table, run_rk4's entry point, its stage, the stage's callees)
        self._kernel = None
        self._zero = np.zeros(s.nv)
        self._tangent_size = 2 * s.nv + layout.OBJECT_STATE_SIZE
        q0 = layout.OBJECT_STATE_SIZE
        self._x = np.zeros(layout.state_size(s.nq, s.nv))  # evaluate()'s state vector
        self._q_part = slice(q0, q0 + s.nq)
        self._v_part = slice(q0 + s.nq, q0 + s.nq + s.nv)
        self._dofs = np.flatnonzero(s.arm_set.dof_mask)  # (nv,) of the flat (n, nv_max) torques
        self.wrenches = (np.zeros((0, layout.WRENCH_WIDTH)) if stepper.wrench is None
                         else np.array(stepper.wrench.table(), dtype=float))  # one array type
        self.last_status = kernels.STAGE_OK

    CONTROLLER_KERNELS = ("object_pd",)
    """The compiled controllers the kernel runs (names of
    :data:`~multiarm_pin.sim.controllers.CONTROLLER_KERNELS`)."""

    @classmethod
    def declines(cls, stepper, integrator: str) -> str | None:
        """Why a run is not of the kind the kernel does, or None when it is.

        It does: RK4 or semi-implicit Euler, a compiled solver
        (:data:`~multiarm_pin.sim.closed_loop.FUSED_SOLVERS`), arms whose every joint the
        compiled rigid-body pass supports, no supports, a controller whose registry entry's
        kernel (:func:`~multiarm_pin.sim.controllers.controller_kernel`) is one of
        :data:`CONTROLLER_KERNELS`, and no external wrench or a
        :class:`~multiarm_pin.sim.disturbances.WrenchSchedule` itself (its intervals are the
        kernel's table; a subclass with its own ``__call__`` is not), and no torque saturation
        (the kernel adds the controller's torque as it is).
        """
        from multiarm_pin.sim.controllers import controller_kernel

        s = stepper.system
        if integrator not in ("rk4", "semi_implicit"):
            return f"integrator {integrator!r} has no compiled loop (RK4 and semi-implicit only)"
        if stepper.solver not in FUSED_SOLVERS:
            return f"solver {stepper.solver!r} has no compiled path"
        if not s.n_arms or s.supports.n_rows:
            return "a system with supports or without arms is the contact loop's"
        kernel, why = controller_kernel(stepper.controller)
        if kernel not in cls.CONTROLLER_KERNELS:
            return why or (f"the compiled closed loop runs the controllers "
                           f"{', '.join(cls.CONTROLLER_KERNELS)}, not {kernel}")
        if s.arm_set.compiled_model is None:
            return unsupported_joints_note(s)
        if stepper.wrench is not None and type(stepper.wrench) is not WrenchSchedule:
            return f"the external wrench is a {type(stepper.wrench).__name__}"
        if stepper.torque_limit is not None:
            return "torque saturation"
        return None

    @classmethod
    def for_run(cls, stepper, integrator: str) -> CompiledLoop | None:
        """The compiled loop of a run, or None when :meth:`declines` gives a reason."""
        return None if cls.declines(stepper, integrator) else cls(stepper, integrator)

    def ready(self, state: SystemState) -> bool:
        """True when the kernel can take the steps from ``state``: every row touches.

        The first time, the controller fixes its state (reference configuration, held
        points...) from a reference (numpy) evaluation of ``state``
        (:meth:`ObjectPD.prepare`), so that a run compiles no kernel but the loop's.
        """
        s = self.system
        if not np.array_equal(self.stepper.active, s.contact_mask):
            return False
        ctrl = self.stepper.controller
        if ctrl.kernel_inputs() is None:
            ctrl.prepare(state, s.blocks(state, None, self.stepper.baumgarte, reference=True))
        return ctrl.kernel_inputs() is not None

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
            was done (:attr:`last_status` is ``STAGE_OK``); otherwise the Python path takes
            the step from sample ``k`` (:attr:`last_status` says why).
        """
        s = self.system
        ctrl = self.stepper.controller
        o = state.obj
        x = layout.state_vector(o.position, o.quaternion, o.twist, state.q, state.v, self._zero)
        a_pts = np.zeros(ctrl.hold_points_in_tool.shape)
        a_d = np.zeros(6)
        args = self._arguments(rec, x, times, k0, k1, a_pts, a_d)
        status, k = self._kernel[1](*args, *self._kernel[2:])
        tau, mu, qdd = self.work[7:]
        self.last_status = int(status)
        k = int(k)
        done = slice(k0, k)
        if k > k0:
            self._finish_record(rec, times, done)
            ctrl.kernel_planned(tau, mu, qdd, a_pts, a_d)
        return k, state_from_vector(x, s.nq, s.nv)

    def _arguments(self, rec: Recorder, x: np.ndarray, times: np.ndarray, k0: int, k1: int,
                   a_pts: np.ndarray, a_d: np.ndarray) -> tuple:
        """:func:`~multiarm_pin._compiled.closed_loop.run_rk4`'s arguments before ``evaluate``."""
        path = self.path
        (traj, pd_gains, null_gains, hold_tool, hold_obj, hold_n, gains, active, unilateral,
         q_ref) = self.stepper.controller.kernel_inputs()
        J, dJ, M, nle, H, energy, buf, tau, mu, qdd = self.work
        system = (self.model.ints, self.model.floats, q_ref, path.arm_table, path.v_starts,
                  path.contact_tables.ints, path.contact_tables.floats, self.params, path.dims,
                  path.N, path.nv_arm, unilateral, traj, pd_gains, null_gains, hold_tool,
                  hold_obj, hold_n, gains, active, self.wrenches)
        work = (J, dJ, M, nle, H, energy, buf, tau, mu, qdd, a_pts, a_d)
        head = (k0, k1, times, x, *system, self.separation, *work, rec.q, rec.v, rec.p,
                rec.quat, rec.twist, rec.tau, rec.mu, rec.phi, rec.phi_dot, rec.points,
                rec.normals, rec.a_o, rec.qdd, rec.violation, rec.wrench, rec.ke, rec.pe,
                rec.momentum, self._semi)
        if self._kernel is None or self._kernel[0] is not traj:
            # the loop's entry point, its stage and the stage's callees for these types (made
            # once per controller input, whose arrays are the only ones that may change
            # between runs); the entry point without numba's dispatch, which would type the
            # stage's function pointer again at every call
            self._kernel = (traj, *kernels.loop_functions(head, x, *system, *work))
        return head

    def evaluate(self, t: float, state: SystemState) -> tuple[int, np.ndarray, np.ndarray]:
        """One closed-loop evaluation by the kernel of the loop's stages (no record).

        The compiled rigid-body pass, the blocks, ``object_pd`` and the forward dynamics at
        ``(t, state)``, as :func:`~multiarm_pin.sim.closed_loop.closed_loop_evaluation`
        computes them with Pinocchio (see :func:`~multiarm_pin._compiled.closed_loop.
        closed_loop_stage`). The loop must be :meth:`ready` at ``state``.

        Returns:
            ``(status, tangent (2 nv + 13,), tau (nv,) [N m])``: ``STAGE_OK`` or why the
            Python path must decide; the tangent ``[q̇; v̇; ṗ; q̇uat; ȧ]`` as
            ``Stepper.derivative``.
        """
        s = self.system
        ctrl = self.stepper.controller.kernel_inputs()  # the same tuple while it holds
        kept = self._stage_args
        if kept is None or kept[1] is not ctrl:
            path = self.path
            (traj, pd_gains, null_gains, hold_tool, hold_obj, hold_n, gains, active,
             unilateral, q_ref) = ctrl
            J, dJ, M, nle, H, energy, buf, tau, mu, qdd = self.work
            n, k = tau.shape
            self._stage_args = ((self.model.ints, self.model.floats, q_ref, np.empty(s.nv), J,
                                 dJ, M, nle, H, np.empty(0),  # no energies: nothing records
                                 path.arm_table, path.v_starts,
                                 path.contact_tables.ints, path.contact_tables.floats,
                                 self.params, path.dims, path.N, path.nv_arm, unilateral, traj,
                                 pd_gains, null_gains, hold_tool, hold_obj, hold_n, gains,
                                 active, self.wrenches, buf, tau, mu, qdd,
                                 np.empty(hold_tool.shape), np.empty(6),
                                 np.empty(layout.REFERENCE_SIZE), np.empty((3, 3)),
                                 np.empty((n, k))), ctrl)
            kept = self._stage_args
            example = (0.0, self._x, True, *kept[0], np.empty(self._tangent_size))
            self._stage, self._callees = kernels.stage_entry(example)
        o = state.obj
        x = self._x  # read by the kernel only: filled in place (its τ part stays zero)
        x[layout.X_POSITION:layout.X_POSITION + 3] = o.position
        x[layout.X_QUATERNION:layout.X_QUATERNION + 4] = o.quaternion
        x[layout.X_TWIST:layout.X_TWIST + 6] = o.twist
        x[self._q_part] = state.q
        x[self._v_part] = state.v
        d = np.empty(self._tangent_size)
        status = self._stage(float(t), x, True, *kept[0], d, self._callees)
        return int(status), d, self.work[7].take(self._dofs)

    def _finish_record(self, rec: Recorder, times: np.ndarray, done: slice) -> None:
        """What the kernel does not record at samples ``done``: times, active set, solver."""
        rec.t[done] = times[done]
        rec.active[done] = self.stepper.active
        rec.solver[done] = RECORDED_SOLVER[self.stepper.unilateral]
        rec.mark_recorded(done.stop)


def unsupported_joints_note(system) -> str:
    """Why a system's arms are not on the compiled loops (a sentence).

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




__all__ = ["RECORDED_SOLVER", "CompiledLoop", "state_from_vector"]
