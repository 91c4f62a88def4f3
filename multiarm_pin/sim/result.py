"""The record of a run: :class:`SimulationResult`, the recorder that fills it, its size.

:func:`~multiarm_pin.sim.simulation.simulate` samples every ``dt`` into a
:class:`Recorder` and returns its :class:`SimulationResult`; on an error or interrupt the
samples so far are attached to the exception (:func:`partial_result`). :func:`record_bytes`
is the memory a record takes, checked before allocating it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from multiarm_pin.dynamics import Solution
from multiarm_pin.model.rigid_object import ObjectState
from multiarm_pin.sim.contact_events import ContactEvent
from multiarm_pin.system import ContactRows, Evaluation, MultiArmSystem, SystemState

if TYPE_CHECKING:  # pragma: no cover - typing only
    from multiarm_pin.sim.stepper import Stepper


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
        tau_commanded: (T, nv) joint torques the controller commanded [N m]: ``tau`` itself
            unless the run saturates the actuators (``simulate(torque_limit=...)``), where
            ``tau = clip(tau_commanded, -limit, limit)``.
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
            largest penetration ``-φ`` of separated rows [m] (not of support rows beside a
            finite support's rectangle, or fallen past its edge, nor of fingertips that
            started beside their face and have not been above its plane since: they
            penetrate nothing).
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
        events: every separation, touchdown and off-edge event (:class:`ContactEvent`), in
            time order.
        contact_labels: ``(block, row, label)`` of every real row.
        torque_limit: (nv,) the saturation bounds [N m or N] of the run (``inf``: none), or
            None when it did not saturate.
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
    tau_commanded: np.ndarray | None = None
    torque_limit: np.ndarray | None = None

    @property
    def total_energy(self) -> np.ndarray:
        """(T,) kinetic + potential energy [J]."""
        return self.kinetic_energy + self.potential_energy

    def state(self, k: int) -> SystemState:
        """The :class:`SystemState` of sample ``k``."""
        return _sample_state(self.q, self.v, self.object_position, self.object_quaternion,
                             self.object_twist, k)

    def arm_wrench(self, n_arms: int) -> np.ndarray:
        """(T, n_arms, 6) each arm's wrench on the object ``[f; m]`` [N, N m], world axes.

        ``f = Σ μ_r n_r`` over the arm's rows and ``m = Σ (p_r - x) × μ_r n_r``, the moment
        about the object's COM ``x`` (``object_position``); ``p_r`` and ``n_r`` are the rows'
        recorded contact points and push directions, so ``[f; m]`` is ``W_o,i μ_i``, the arm's
        share of the wrench the object's Newton-Euler equations see. The arms are the first
        ``n_arms`` blocks (the supports' block, if any, comes after them).
        """
        f = self.mu[:, :n_arms, :, None] * self.normals[:, :n_arms]
        r = self.contact_points[:, :n_arms] - self.object_position[:, None, None, :]
        return np.concatenate([f.sum(axis=2), np.cross(r, f).sum(axis=2)], axis=-1)

class Recorder:
    """Preallocated arrays of T samples, filled one sample at a time by :meth:`record`."""

    def __init__(self, system: MultiArmSystem, T: int, solver: str, max_warnings: int):
        n, m = system.n_blocks, system.rows_max
        self.system = system
        self.requested = solver
        self.max_warnings = max_warnings  # separation warnings kept (the rest are counted)
        self.t = np.zeros(T)
        self.q = np.zeros((T, system.nq))
        self.v = np.zeros((T, system.nv))
        self.p = np.zeros((T, 3))
        self.quat = np.zeros((T, 4))
        self.twist = np.zeros((T, 6))
        self.tau = np.zeros((T, system.nv))
        self.tau_cmd = None  # (T, nv) when the run saturates (start_saturation)
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
        self._labels = None  # (block, row) -> label, built at the first warning
        self.count = 0

    def record(self, k: int, t: float, state: SystemState, sol: Solution, ev: Evaluation,
               tau: np.ndarray, ct: ContactRows, stepper: Stepper) -> None:
        """Store sample ``k`` (time ``t`` [s], its solution, torques and rows)."""
        s = self.system
        self.t[k] = t
        self.q[k] = state.q
        self.v[k] = state.v
        self.p[k] = state.obj.position
        self.quat[k] = state.obj.quaternion
        self.twist[k] = state.obj.twist
        self.tau[k] = tau
        if self.tau_cmd is not None:
            self.tau_cmd[k] = stepper.commanded
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
        beside = stepper.beside(ct)
        if beside is not None:  # below the plane beside (or under) a finite support
            free &= ~beside
        stepper.update_beside_start(ct)
        free &= ~stepper.beside_start  # fingertips that started beside their face
        viol = np.concatenate([np.abs(ct.phi[held]), np.maximum(-ct.phi[free], 0.0), [0.0]])
        self.violation[k] = float(viol.max())
        self.active[k] = stepper.active
        if stepper.wrench is not None:
            self.wrench[k] = stepper.wrench(t)
        self.solver[k] = sol.solver
        negative = s.contact_unilateral & (sol.mu < 0.0)
        for i, j in zip(*np.nonzero(negative & ~self._negative), strict=True):
            self.n_warnings += 1
            if len(self.warnings) < self.max_warnings:
                self.warnings.append(
                    f"t = {t:.6g} s: contact {self._label(i, j)} (arm {i}): multiplier "
                    f"μ = {sol.mu[i, j]:.4g} N < 0, a frictionless contact would separate"
                )
        self._negative = negative
        singular = sol.solver == "singular" and self.requested == "auto"
        if singular and not self._singular:
            self.switches.append(float(t))
        self._singular = singular
        self.count = k + 1

    def _label(self, block: int, row: int) -> str:
        """The contact's name, ``"<arm>:<contact>"`` or ``"<support>[point]"`` (as in events)."""
        if self._labels is None:
            self._labels = {(b, r): lab for b, r, lab in self.system.contact_labels}
        return self._labels.get((block, row), f"{block}:{row}")

    def start_saturation(self) -> None:
        """Record the commanded torques too (a run whose actuators saturate)."""
        self.tau_cmd = np.zeros_like(self.tau)

    def state(self, k: int) -> SystemState:
        """The state recorded at sample ``k`` (copies)."""
        return _sample_state(self.q, self.v, self.p, self.quat, self.twist, k)

    def mark_recorded(self, count: int) -> None:
        """Samples up to ``count`` were recorded by the compiled loop.

        (:mod:`multiarm_pin.sim.contact_loop`: no unilateral multiplier is negative, the mixed
        LCP decides them, and no solve is the singular-arm variant, the stepper takes those
        steps: so no warning and no solver switch is pending.)
        """
        self._negative[:] = False
        self._singular = False
        self.count = int(count)

    def result(self, integrator, dt, baumgarte, wall, stepper: Stepper,
               n: int | None = None) -> SimulationResult:
        """The record as a :class:`SimulationResult`, its first ``n`` samples (all: None)."""
        n = len(self.t) if n is None else int(n)
        s = self.system
        warnings = [  # a grasp contact letting go is worth a warning (a support's is not)
            f"t = {e.t:.6g} s: contact {e.label} (arm {e.block}): separates (multiplier "
            f"μ = 0 N; holding it would need a pulling force)"
            for e in stepper.events if e.kind == "separation" and e.block < s.n_arms
        ][:self.max_warnings] + list(self.warnings) + [  # a controller's own (ObjectPD holding)
            w for w in getattr(stepper.controller, "warnings", ()) if isinstance(w, str)
        ] + list(stepper.notes)
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
            tau_commanded=self.tau[:n] if self.tau_cmd is None else self.tau_cmd[:n],
            torque_limit=stepper.torque_limit,
        )



def _sample_state(q, v, position, quaternion, twist, k: int) -> SystemState:
    """Sample ``k`` of recorded arrays ``(T, ...)`` as a :class:`SystemState` (copies)."""
    return SystemState(q[k].copy(), v[k].copy(),
                       ObjectState(position[k].copy(), quaternion[k].copy(), twist[k].copy()))


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

def human_bytes(n: float) -> str:
    """``n`` bytes as a short text with a binary unit (``"1.5 MiB"``)."""
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

