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
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from multiarm_pin.dynamics import SOLVERS, Solution
from multiarm_pin.dynamics import solve as solve_dynamics
from multiarm_pin.exceptions import DynamicsError, InputError, MultiArmError
from multiarm_pin.rigid_object import ObjectState
from multiarm_pin.spatial import integrate_quaternion, quaternion_derivative
from multiarm_pin.system import Evaluation, MultiArmSystem, SystemState

INTEGRATORS = ("rk4", "rk45", "semi_implicit")
"""Names accepted by :func:`simulate`."""

MAX_WARNINGS = 200
"""Contact-separation warnings kept in a result (the rest are counted)."""

Controller = Callable[[float, SystemState, Evaluation], np.ndarray]
"""``controller(t, state, evaluation) -> tau (nv,)``; ``evaluation`` holds the blocks at τ = 0."""


@dataclass
class SimulationResult:
    """Record of a run, sampled every ``dt`` (T samples, n arms, N_max constraints per arm).

    Attributes:
        t: (T,) times [s].
        q: (T, nq) arms' configurations; v: (T, nv) velocities.
        object_position: (T, 3) [m]; object_quaternion: (T, 4) ``[x, y, z, w]``;
        object_twist: (T, 6) ``[ẋ; ω]`` world axes.
        tau: (T, nv) joint torques applied [N m].
        mu: (T, n, N_max) contact multipliers [N] (positive = pushing; 0 on padding).
        phi: (T, n, N_max) gaps [m]; phi_dot: (T, n, N_max) gap rates [m/s].
        contact_points: (T, n, N_max, 3) world contact points [m];
        normals: (T, n, N_max, 3) world push directions.
        object_acceleration: (T, 6) ``[ẍ; ω̇]``; qdd: (T, nv) joint accelerations.
        kinetic_energy: (T,) [J]; potential_energy: (T,) [J] (gravity, zero at z = 0).
        momentum: (T, 6) total ``[linear; angular]`` momentum of arms and object about the
            world origin [kg m/s, kg m²/s].
        constraint_violation: (T,) ``max |φ|`` over real contacts [m].
        solver: (T,) name of the solver used at each sample.
        warnings: contact separations (unilateral contact with ``μ < 0``) with time and
            arm/contact index, at each onset.
        solver_switches: times [s] at which the ``auto`` solver switched to the singular-arm
            variant (onsets).
        wall_time: seconds spent in :func:`simulate`.
        integrator, dt, baumgarte: the settings used.
        unilateral: (n, N_max) bool mask of unilateral contacts.
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
    """Evaluates the closed-loop dynamics and records samples."""

    def __init__(self, system: MultiArmSystem, controller, solver: str, baumgarte):
        self.system = system
        self.controller = controller
        self.solver = solver
        self.baumgarte = baumgarte
        self.model = system.arm_set.model

    def evaluate(self, t: float, state: SystemState):
        """Blocks, controller and forward dynamics at ``(t, state)``; errors carry the time."""
        try:
            return self._evaluate(t, state)
        except MultiArmError as exc:  # same type, message prefixed with the time
            if exc.args and isinstance(exc.args[0], str) and not exc.args[0].startswith("t = "):
                exc.args = (f"t = {t:.6g} s: {exc.args[0]}", *exc.args[1:])
            raise

    def _evaluate(self, t: float, state: SystemState):
        s = self.system
        ev = s.blocks(state, None, self.baumgarte)
        if self.controller is None:
            tau = np.zeros(s.nv)
            blocks = ev.blocks
        else:
            try:
                tau = np.asarray(self.controller(t, state, ev), dtype=float)
            except MultiArmError as exc:  # NaN or no solution at this state: with the time
                raise DynamicsError(f"t = {t:.6g} s: controller: {exc}") from exc
            if tau.shape != (s.nv,):
                raise InputError(
                    f"controller returned torques of shape {tau.shape}, expected ({s.nv},)"
                )
            if not np.all(np.isfinite(tau)):
                raise DynamicsError(f"t = {t:.6g} s: controller returned NaN or infinite torques")
            blocks = ev.blocks.with_torques(s.pad(tau))
        try:
            sol = solve_dynamics(blocks, self.solver)
        except DynamicsError as exc:
            raise DynamicsError(f"t = {t:.6g} s: {exc}") from exc
        return sol, ev, tau

    def derivative(self, state: SystemState, sol: Solution) -> np.ndarray:
        """Tangent ``[q̇ (nv); v̇ (nv); ṗ (3); q̇uat (4); ȧ (6)]``."""
        o = state.obj
        return np.concatenate([state.v, self.system.unpad(sol.qdd), o.twist[:3],
                               quaternion_derivative(o.quaternion, o.twist[3:]), sol.a_o])

    def advance(self, state: SystemState, d: np.ndarray, h: float) -> SystemState:
        nv = self.system.nv
        q = pin.integrate(self.model, state.q, h * d[:nv])
        v = state.v + h * d[nv:2 * nv]
        o = state.obj
        p = o.position + h * d[2 * nv:2 * nv + 3]
        quat = o.quaternion + h * d[2 * nv + 3:2 * nv + 7]
        quat = quat / np.linalg.norm(quat)
        tw = o.twist + h * d[2 * nv + 7:]
        return SystemState(q, v, ObjectState(p, quat, tw))


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
    initial_tol: float = 1e-6,
    velocity_tol: float = 1e-6,
    rtol: float = 1e-9,
    atol: float = 1e-11,
    max_record_bytes: int | None = None,
) -> SimulationResult:
    """Simulate the closed-loop system from ``initial_state`` for ``duration`` seconds.

    Args:
        system: the system.
        initial_state: the state at t = 0; must satisfy the joints (``|φ| <= initial_tol``
            [m], ``|φ̇| <= velocity_tol`` [m/s]) unless ``check_initial`` is False.
        controller: ``controller(t, state, evaluation) -> tau (nv,)`` (see
            :mod:`multiarm_pin.controllers`), or None for zero torque.
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
    stepper = _Stepper(system, controller, solver, baumgarte)
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
    try:
        _integrate(stepper, rec, state, times, integrator, rtol, atol, report)
    except BaseException as exc:  # keep what was simulated, for the caller to save
        exc.partial_result = rec.result(integrator, dt, baumgarte,
                                         time.perf_counter() - t_start, rec.count)
        raise
    report(1.0)
    return rec.result(integrator, dt, baumgarte, time.perf_counter() - t_start)


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
        system: the system (its nq, nv, arms and N_max set the per-sample size).
        n_samples: T.
    """
    nm = system.n_arms * system.N_max
    per_sample = 1 + system.nq + 4 * system.nv + 3 + 4 + 6 + 6 + 3 * nm + 6 * nm + 2 + 6 + 1
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
    system = stepper.system
    n_steps = len(times) - 1
    dt = float(times[1] - times[0]) if n_steps > 0 else 0.0
    if integrator == "rk45":
        _run_rk45(stepper, rec, state, times, rtol, atol, report)
    else:
        every = max(1, n_steps // 100)
        for k in range(n_steps + 1):
            t = times[k]
            sol, ev, tau = stepper.evaluate(t, state)
            rec.record(k, t, state, sol, ev, tau)
            if k == n_steps:
                break
            if integrator == "rk4":
                d1 = stepper.derivative(state, sol)
                s2 = stepper.advance(state, d1, 0.5 * dt)
                d2 = stepper.derivative(s2, stepper.evaluate(t + 0.5 * dt, s2)[0])
                s3 = stepper.advance(state, d2, 0.5 * dt)
                d3 = stepper.derivative(s3, stepper.evaluate(t + 0.5 * dt, s3)[0])
                s4 = stepper.advance(state, d3, dt)
                d4 = stepper.derivative(s4, stepper.evaluate(t + dt, s4)[0])
                state = stepper.advance(state, (d1 + 2.0 * d2 + 2.0 * d3 + d4) / 6.0, dt)
            else:  # semi-implicit Euler
                v = state.v + dt * system.unpad(sol.qdd)
                tw = state.obj.twist + dt * sol.a_o
                o = state.obj
                state = SystemState(
                    pin.integrate(stepper.model, state.q, dt * v), v,
                    ObjectState(o.position + dt * tw[:3],
                                integrate_quaternion(o.quaternion, tw[3:], dt), tw),
                )
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
            sol, ev, tau = stepper.evaluate(times[k], s)
            rec.record(k, times[k], s, sol, ev, tau)
            k += 1
            continue
        message = ode.step()
        if ode.status == "failed":
            raise DynamicsError(f"rk45 integration failed at t = {ode.t:.6g} s: {message}")


class _Recorder:
    def __init__(self, system: MultiArmSystem, T: int, solver: str):
        n, m = system.n_arms, system.N_max
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
        self.solver = np.empty(T, dtype=object)
        self.warnings: list[str] = []
        self.n_warnings = 0
        self.switches: list[float] = []
        self._negative = np.zeros((n, m), dtype=bool)
        self._singular = False
        self.count = 0

    def record(self, k: int, t: float, state: SystemState, sol: Solution, ev: Evaluation,
               tau: np.ndarray) -> None:
        s = self.system
        ct = ev.constraints
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
        self.violation[k] = float(np.max(np.abs(ct.phi[ct.mask]))) if ct.mask.any() else 0.0
        self.solver[k] = sol.solver
        negative = s.unilateral & (sol.mu < 0.0)
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

    def result(self, integrator, dt, baumgarte, wall, n: int | None = None) -> SimulationResult:
        """The record as a :class:`SimulationResult`, its first ``n`` samples (all: None)."""
        n = len(self.t) if n is None else int(n)
        warnings = list(self.warnings)
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
            unilateral=np.array(self.system.unilateral), integrator=integrator, dt=dt,
            baumgarte=None if baumgarte is None else tuple(float(x) for x in baumgarte),
            warnings=warnings, solver_switches=list(self.switches), wall_time=wall,
        )


__all__ = [
    "INTEGRATORS",
    "Controller",
    "SimulationResult",
    "default_record_limit",
    "partial_result",
    "record_bytes",
    "simulate",
]
