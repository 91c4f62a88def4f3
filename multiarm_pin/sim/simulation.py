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

With RK4 or semi-implicit Euler, runs of the kind it takes go to the compiled loop,
:class:`~multiarm_pin.sim.contact_loop.ContactLoop`, which records the same samples and events
(bilateral and unilateral rows, separations, touchdowns and impacts in the kernel); a step it
hands back is taken by the stepper. With a support of finite ``extent`` the steps with a
support point off its rectangle at either end (off-edge events) are the stepper's; a run with
such a step says so once in its warnings (``FINITE_SUPPORTS_NOTE``), a run whose points all
stay on their rectangles does not.

This module holds :func:`simulate` (input checks, the time grid, the rk45 driver); the
evaluations, fixed steps and events are :class:`~multiarm_pin.sim.stepper.Stepper`'s, the
event times :mod:`multiarm_pin.sim.event_location`'s, the record
:mod:`multiarm_pin.sim.result`'s (:class:`SimulationResult` and the record-size helpers are
re-exported here).
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from multiarm_pin._compiled.contact_loop import STAGE_EVENTS_FULL, STAGE_OFF_RECTANGLE, STAGE_OK
from multiarm_pin._compiled.function_pointers import (
    WarmUp,
    compile_with_next,
    forget,
    register_thread_owner,
)
from multiarm_pin._registry import lookup
from multiarm_pin.constraints.joint import INITIAL_GAP_TOLERANCE
from multiarm_pin.dynamics.solve import solver_for_rows
from multiarm_pin.exceptions import DynamicsError, InputError, RunStoppedError
from multiarm_pin.model.rigid_object import ObjectState
from multiarm_pin.sim.contact_events import ContactEvent
from multiarm_pin.sim.contact_loop import FINITE_SUPPORTS_NOTE, ContactLoop
from multiarm_pin.sim.controllers.base import ControllerFunction
from multiarm_pin.sim.disturbances import WrenchSchedule
from multiarm_pin.sim.result import (
    Recorder,
    SimulationResult,
    default_record_limit,
    human_bytes,
    partial_result,
    record_bytes,
)
from multiarm_pin.sim.stepper import Stepper
from multiarm_pin.system import MultiArmSystem, SystemState


@dataclass(frozen=True)
class IntegratorEntry:
    """One integrator of the registry (see the module docstring for the schemes).

    Attributes:
        name: the integrator name (:func:`simulate`'s ``integrator``, scenarios' too).
        order: order of accuracy of the scheme (global error ``O(dt^order)``; rk45's
            Dormand-Prince pair advances with its 5th-order solution).
        adaptive: it chooses its own steps (``rtol``, ``atol``) and outputs on the ``dt``
            grid; not event-aware, so only for systems without unilateral rows and with
            ``nq == nv``.
        description: one line for humans.
    """

    name: str
    order: int
    adaptive: bool
    description: str


INTEGRATORS: dict[str, IntegratorEntry] = {e.name: e for e in (
    IntegratorEntry("rk4", 4, False, "classical fixed-step Runge-Kutta (default)"),
    IntegratorEntry("rk45", 5, True, "scipy's adaptive Dormand-Prince RK45 (the thesis's ode45)"),
    IntegratorEntry("semi_implicit", 1, False,
                    "symplectic Euler: velocities first, then positions with them"),
)}
"""Every integrator, by name (the names :func:`simulate` and scenarios accept)."""

MONITOR_STRETCH = 512
"""Largest number of samples the compiled loop simulates in one call, and that a run's
monitors (:func:`simulate`'s ``monitors``) are shown at once: they see each stretch soon after
it is done."""

MONITOR_STRIDE = 32
"""Samples the stepper records one by one before the monitors are shown them."""

MAX_WARNINGS = 200
"""Contact-separation warnings kept in a result (the rest are counted)."""

Controller = ControllerFunction
"""``controller(t, state, evaluation) -> tau (nv,)`` (the protocol
:class:`~multiarm_pin.sim.controllers.ControllerFunction`)."""


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
    torque_limit=None,
    monitors: Sequence[Monitor] = (),
    compiled: bool = True,
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
        solver: forward-dynamics solver name (:data:`multiarm_pin.dynamics.SOLVERS`). With
            unilateral rows only the solvers whose entry serves them (``auto``,
            ``object_first``: the mixed LCP on the object-first Delassus operator); any other
            is refused, never replaced.
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
        torque_limit: (nv,) bound [N m or N] of each joint's applied torque (``inf``: none),
            or None: the actuators saturate, ``τ = clip(τ_commanded, -limit, limit)`` inside
            the dynamics, and both are recorded (``tau``, ``tau_commanded``). A saturating run
            is integrated by the numpy stepper (the compiled loop adds the controller's
            torque as it is) and its result says so once in ``warnings``.
        monitors: checks made while the run runs (e.g. the ``stop`` policies of
            :mod:`multiarm_pin.feasibility.monitors`): each ``monitor.check(record, k0, k1)``
            is called on every stretch of newly recorded samples ``k0 .. k1 - 1`` (in order,
            each sample once; ``record`` the run's :class:`~multiarm_pin.sim.result.Recorder`,
            its arrays ``(T, ...)`` valid up to ``k1``) and returns the first violating
            sample or None. The run then ends: :class:`~multiarm_pin.exceptions.
            RunStoppedError` is raised, its partial result ending at that sample (the samples
            after it are dropped). Stretches hold at most :data:`MONITOR_STRETCH` samples.
        compiled: True (default): the compiled loop takes the steps it serves. False: every
            step is taken by the numpy reference (the stepper), nothing is compiled for the
            loops; the results equal the compiled run's to rounding.

    Returns:
        :class:`SimulationResult`.

    Any exception raised once the integration has started (a :class:`DynamicsError`, a
    ``KeyboardInterrupt``...) carries the samples completed so far: read them with
    :func:`partial_result`.

    Raises:
        InputError: unknown integrator or solver (lists the known ones), bad ``dt``/duration,
            or a run whose record would not fit in memory (before allocating it).
        UnsupportedSolverError: a solver that cannot serve the system's unilateral rows
            (names the solver and the rows).
        ConstraintError: an initial state that violates the joints.
        DynamicsError: NaN in the state, or no solution of the dynamics (with the time).
        RunStoppedError: a monitor found a violation (``monitor``, ``sample``, ``t``).
    """
    t_start = time.perf_counter()
    if max_record_bytes is None:
        max_record_bytes = default_record_limit()
    lookup(INTEGRATORS, integrator, "integrator")
    solver_for_rows(solver, [label for b, r, label in system.contact_labels
                             if system.contact_unilateral[b, r]])
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
    limit = _torque_limit(system, torque_limit)
    stepper = Stepper(system, controller, solver, baumgarte, external_wrench, limit)
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
            f"needs ~{human_bytes(need)} of memory (limit {human_bytes(max_record_bytes)}); "
            "shorten the duration or lengthen dt"
        )
    times = np.arange(n_steps + 1) * dt
    rec = Recorder(system, len(times), solver, MAX_WARNINGS)
    if limit is not None:
        rec.start_saturation()
        rec.warnings.append("torque saturation: the run is integrated by the numpy stepper "
                            "(the compiled loop does not clip torques)")

    def report(frac: float) -> None:
        if progress is not None:
            progress(min(max(frac, 0.0), 1.0))

    state = SystemState(np.array(initial_state.q, float), np.array(initial_state.v, float),
                        ObjectState(np.array(initial_state.obj.position, float),
                                    _normalised(initial_state.obj.quaternion),
                                    np.array(initial_state.obj.twist, float)))
    if stepper.unilateral:
        # the gaps at t = 0 by the numpy reference: a run the compiled loop takes never needs
        # the Python path's compiled evaluation, which would be compiled for this one call
        stepper.init_active(stepper.blocks_at(0.0, state, reference=True)[1], initial_tol)
    watch = _Watch(monitors, rec, state)
    try:
        _integrate(stepper, rec, state, times, integrator, rtol, atol, report, watch,
                   compiled)
        watch.finish()
    except BaseException as exc:  # keep what was simulated, for the caller to save
        stop = watch.settle()  # a violation found before the failure ends the run there
        if stop is not None and not isinstance(exc, RunStoppedError):
            exc = stop
        n = exc.sample + 1 if isinstance(exc, RunStoppedError) else rec.count
        exc.partial_result = rec.result(integrator, dt, baumgarte,
                                         time.perf_counter() - t_start, stepper, n)
        if exc is stop:
            raise stop from None
        raise
    report(1.0)
    return rec.result(integrator, dt, baumgarte, time.perf_counter() - t_start, stepper)


def _integrate(stepper: Stepper, rec: Recorder, state: SystemState, times: np.ndarray,
               integrator: str, rtol: float, atol: float, report, watch: _Watch,
               compiled: bool = True) -> None:
    """Run the integrator over the time grid, recording every sample (and watching them).

    ``compiled`` False: the compiled loop takes no step (the numpy reference alone).
    """
    n_steps = len(times) - 1
    note = reference_note(stepper, integrator) if compiled else None
    if note is not None:
        stepper.notes.append(note)
    if integrator == "rk45":
        _run_rk45(stepper, rec, state, times, rtol, atol, report, watch)
    else:
        every = max(1, n_steps // 100)
        loop = ContactLoop.for_run(stepper, integrator) if compiled else None
        off_rectangle = False  # a step was the stepper's for a support point off its rectangle
        stretch = _Stretch(every, n_steps, tapered=bool(watch.monitors))
        watch.longest_stretch(stretch.top)
        k = 0
        while True:
            if loop is not None and loop.ready(state):
                # a stretch of steps in one compiled call; the step it hands back, if any, is
                # taken below by the stepper
                with stretch:
                    k, state = loop.run(rec, state, times, k, stretch.end(k))
                watch.recorded(rec, k)
                report(k / n_steps)
                if k > n_steps:
                    break
                if loop.last_status in (STAGE_OK, STAGE_EVENTS_FULL):
                    continue
                handed_back = loop.last_status == STAGE_OFF_RECTANGLE
            else:  # not ready: a row fallen past its support's edge, or no compiled loop
                handed_back = loop is not None and bool(stepper.fallen.any())
            if handed_back and not off_rectangle:
                off_rectangle = True
                stepper.notes.append(FINITE_SUPPORTS_NOTE)
            t = times[k]
            sol, ev, tau, rows = stepper.evaluate(t, state)
            if stepper.separations(t, sol, rows):
                sol, ev, tau, rows = stepper.evaluate(t, state)
            rec.record(k, t, state, sol, ev, tau, rows, stepper)
            watch.recorded(rec, k + 1)
            if k == n_steps:
                break
            state = stepper.advance_with_events(integrator, t, state, sol, times[k + 1] - t,
                                                t_end=times[k + 1])
            if k % every == 0:
                report((k + 1) / n_steps)
            k += 1


REFERENCE_NOTE = "the run is taken by the reference (numpy) stepper, not a compiled loop: {why}"
"""The note (once in a run's warnings) of a run that the compiled loop does not serve, and why."""


def reference_note(stepper: Stepper, integrator: str) -> str | None:
    """The note of a run that the compiled loop declines, or None.

    :meth:`ContactLoop.declines` gives the reason (the integrator, the solver, the
    controller's registry entry, a joint kind...). Torque saturation has a warning of its own.
    """
    why = ContactLoop.declines(stepper, integrator)
    if why is None or stepper.torque_limit is not None:
        return None
    return REFERENCE_NOTE.format(why=why)


class _Stretch:
    """How many samples the next compiled call takes.

    1 % of the run, doubled while a call takes less than :attr:`WALL` seconds, up to 10 % of
    the run and :data:`MONITOR_STRETCH` samples: so that a call's Python around it (unboxing
    its arguments, the record's bookkeeping) stays small against the call,
    while the progress reports and a Ctrl-C (seen between calls) still come every few
    hundredths of a second, and the run's monitors see each stretch soon after it is done.
    """

    WALL = 0.01

    def __init__(self, every: int, n_steps: int, tapered: bool = False):
        self.size = min(every, MONITOR_STRETCH)
        self.top = min(max(every, n_steps // 10), MONITOR_STRETCH)
        self.n_samples = n_steps + 1
        self.tapered = tapered
        self._t0 = 0.0

    def end(self, k: int) -> int:
        """One past the last sample of a call from sample ``k``.

        Tapered (a run with monitors): at most a quarter of the samples left, and at least
        :data:`MONITOR_STRIDE`, so that the checks of the last stretches, which nothing
        simulated beside them hides, are short.
        """
        size = self.size
        if self.tapered:
            size = min(size, max(MONITOR_STRIDE, (self.n_samples - k) // 4))
        return min(self.n_samples, k + size)

    def __enter__(self):
        self._t0 = time.perf_counter()
        return self

    def __exit__(self, *exc) -> None:
        if time.perf_counter() - self._t0 < self.WALL:
            self.size = min(2 * self.size, self.top)


class Monitor(Protocol):
    """A check made while a run runs (:func:`simulate`'s ``monitors``).

    Attributes:
        name: what it watches, for the :class:`~multiarm_pin.exceptions.RunStoppedError` message.
    """

    name: str

    def check(self, record: Recorder, k0: int, k1: int) -> int | None:
        """The first sample in ``[k0, k1)`` that violates what it watches, or None.

        A monitor may also have ``warm_up(record, state)``: call the compiled kernels its
        checks call, on a small example shaped as ``record``'s samples at ``state`` and
        without changing itself, so that they compile beside the run's loop
        (:class:`~multiarm_pin._compiled.function_pointers.WarmUp`); and ``prepare(record)``:
        make what its checks need for a run of ``record``'s samples (a scan's arrays), called
        on the worker thread as the run starts, while the loop is loaded or compiled.
        """


def _prepare(ready: Sequence, rec: Recorder) -> None:
    """Call each monitor's ``prepare`` (:class:`Monitor`) for the run of ``rec``."""
    for prepare in ready:
        prepare(rec)


class _Watch:
    """The run's monitors, called on each stretch of samples once it is recorded for good.

    The seam between the simulation loops and the checks made while a run runs: the loops
    call :meth:`recorded` whenever they hand back to Python (after each compiled stretch, each
    step the stepper takes); the samples not yet shown to the monitors are shown once at
    least :data:`MONITOR_STRIDE` of them wait (every compiled stretch, at most
    :data:`MONITOR_STRETCH` samples, is one call) and at the end of the run. The last sample
    recorded is held back until the next call: a step the compiled loop handed back is taken
    again from it, which records it again.

    The checks of a stretch run on a worker thread while the loop simulates the next one (the
    compiled loop releases the GIL), so on a machine with a free core they add little to a
    run's wall time. The monitors' ``prepare`` runs there first, as the run starts, while the
    loop is loaded or compiled. They stay in order (a stretch's checks start once the previous
    stretch's have ended) and read only samples that are settled (the loops write later ones). A
    violation is raised at the next call (or at :meth:`finish`): the samples simulated since
    are dropped, so the run ends exactly as if the checks had been made in line.

    While the worker is still checking, the samples recorded since wait and are shown
    together once it is done (at most :attr:`batch` samples at once, then the loop waits for
    it): a check's fixed cost is paid once for several stretches where the checks fall behind
    (a machine without a free core), and a stop still comes within two batches of its sample.
    """

    def __init__(self, monitors: Sequence[Monitor], rec: Recorder | None = None,
                 state: SystemState | None = None):
        self.monitors = tuple(monitors)
        self.checked = 0  # samples shown to the monitors
        self.batch = MONITOR_STRETCH  # most samples shown at once
        self._step = 1  # most samples a loop records between two calls
        self._pool: ThreadPoolExecutor | None = None
        self._pending: Future | None = None
        # the monitors' kernels, compiled beside the run's loop if it compiles (else at their
        # first call, on the worker)
        self._warm = () if rec is None or state is None else tuple(
            WarmUp(functools.partial(m.warm_up, rec, state)) for m in self.monitors
            if hasattr(m, "warm_up"))
        if self._warm:
            compile_with_next(self._warm)
        ready = [m.prepare for m in self.monitors if hasattr(m, "prepare")]
        if rec is not None and ready:  # the first check then finds them made
            self._pending = self._worker().submit(_prepare, ready, rec)

    def longest_stretch(self, samples: int) -> None:
        """A loop's calls come at most ``samples`` samples apart.

        Batches then hold at most twice that (and :data:`MONITOR_STRETCH`).
        """
        self._step = max(1, int(samples))
        self.batch = min(MONITOR_STRETCH, 2 * self._step)

    def recorded(self, rec: Recorder, count: int) -> None:
        """Samples ``0 .. count - 1`` are recorded; show the monitors the settled ones.

        Raises:
            RunStoppedError: a monitor found a violation (in this or an earlier stretch).
        """
        if not self.monitors:
            return
        last = count == len(rec.t)
        end = count if last else count - 1
        if end - self.checked < (1 if last else MONITOR_STRIDE):
            return
        busy = self._pending is not None and not self._pending.done()
        if busy and not last and end - self.checked + self._step <= self.batch:
            return  # shown with the next ones, once the worker is done
        k0, self.checked = self.checked, end
        self._raise(self._collect())
        if last:
            self._raise(self._check(rec, k0, end))
            return
        self._pending = self._worker().submit(self._check, rec, k0, end)

    def end_worker(self) -> None:
        """End the worker thread now, its check under way done; its result is kept.

        Called by :func:`~multiarm_pin._compiled.function_pointers.compile_all` before a
        loop compiles in the middle of a run (at its first stretch, the worker thread started
        to prepare the checks), so that it may fork children to compile: the next stretch
        starts a new thread.
        """
        self._close()

    def finish(self) -> None:
        """The run's end: wait for the last checks (raises their violation) and stop the thread."""
        try:
            self._raise(self._collect())
        finally:
            self._close()

    def settle(self) -> RunStoppedError | None:
        """After a failure: wait for the checks under way; the violation they found, if any."""
        try:
            return self._collect()
        except BaseException:  # the run's own failure is what the caller raises
            return None
        finally:
            self._close()

    def _worker(self) -> ThreadPoolExecutor:
        """The worker thread that checks the stretches (started at the first need)."""
        if self._pool is None:
            self._pool = ThreadPoolExecutor(1, thread_name_prefix="multiarm-pin-monitors")
            register_thread_owner(self)
        return self._pool

    def _collect(self) -> RunStoppedError | None:
        pending, self._pending = self._pending, None
        return pending.result() if pending is not None else None

    def _close(self) -> None:
        if self._warm:
            forget(self._warm)
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None

    def _check(self, rec: Recorder, k0: int, k1: int) -> RunStoppedError | None:
        first, by = None, None
        for m in self.monitors:
            s = m.check(rec, k0, k1)
            if s is not None and (first is None or s < first):
                first, by = int(s), m.name
        if first is None:
            return None
        t = float(rec.t[first])
        return RunStoppedError(f"t = {t:.6g} s: {by}: stop at the first violation (sample "
                               f"{first})", by, first, t)

    @staticmethod
    def _raise(stop: RunStoppedError | None) -> None:
        if stop is not None:
            raise stop


def _torque_limit(system: MultiArmSystem, torque_limit) -> np.ndarray | None:
    """``torque_limit`` checked: None, or (nv,) positive bounds (``inf`` allowed)."""
    if torque_limit is None:
        return None
    lim = np.array(torque_limit, dtype=float)
    if lim.shape != (system.nv,) or np.isnan(lim).any() or not (lim > 0.0).all():
        raise InputError(f"torque_limit: expected {system.nv} positive bounds [N m or N] "
                         f"(inf: none), got {np.asarray(torque_limit).tolist()!r}")
    return lim


def _normalised(q) -> np.ndarray:
    q = np.array(q, dtype=float)
    return q / np.linalg.norm(q)


def _run_rk45(stepper: Stepper, rec: Recorder, state: SystemState, times: np.ndarray,
              rtol: float, atol: float, report, watch: _Watch) -> None:
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
            watch.recorded(rec, k)
            continue
        message = ode.step()
        if ode.status == "failed":
            raise DynamicsError(f"rk45 integration failed at t = {ode.t:.6g} s: {message}")



__all__ = [
    "INTEGRATORS",
    "IntegratorEntry",
    "MONITOR_STRETCH",
    "MONITOR_STRIDE",
    "REFERENCE_NOTE",
    "ContactEvent",
    "Monitor",
    "Controller",
    "SimulationResult",
    "default_record_limit",
    "partial_result",
    "record_bytes",
    "reference_note",
    "simulate",
]
