"""Controllers: joint torques from the time, the state and the blocks of the dynamics.

A controller is a callable ``controller(t, state, evaluation) -> tau (nv,)`` [N m] where
``evaluation`` (:class:`~multiarm_pin.system.Evaluation`) holds the blocks at zero torque
(``h = -nle``), so a controller can use the mass matrices, Jacobians and constraint rows
without recomputing them. Build one by name with :func:`make_controller`:

- ``none``: zero torque;
- ``gravity_compensation``: ``τ = g(q)``, the arms' own weight only (the object's weight is
  not compensated);
- ``joint_pd``: ``τ = g(q) + K_p (q_ref ⊖ q) - K_d v`` (``q_ref`` defaults to the
  configuration at the first call, i.e. ``q0``);
- ``object_pd``: object-level computed torque. A desired object trajectory
  (:class:`~multiarm_pin.trajectories.MinimumJerkTrajectory`; default: hold the pose of the
  first call) and PD on the object pose give a desired acceleration
  ``a_d = a_ref + K_d (v_ref - v_o) + K_p [p_ref - p; log(R_ref Rᵀ)]``. The contact
  multipliers are chosen by :func:`distribute_forces` (every unilateral contact pushes with at
  least ``margin``, forces as small as possible), joint accelerations satisfy the constraints
  with a PD in their null space (relative motion in the joints, redundancy), and the torques
  follow from the arms' equations (:func:`inverse_dynamics`). With these torques the forward
  dynamics returns exactly ``a_d`` and those multipliers.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import pinocchio as pin

from multiarm_pin.dynamics import SystemBlocks
from multiarm_pin.exceptions import DynamicsError, InputError
from multiarm_pin.system import Evaluation, MultiArmSystem, SystemState
from multiarm_pin.trajectories import MinimumJerkTrajectory, pose_error


class Controller:
    """Base class: ``controller(t, state, evaluation) -> tau (nv,)`` [N m].

    Args:
        system: the system it controls.
    """

    name: ClassVar[str] = "controller"

    def __init__(self, system: MultiArmSystem):
        if not isinstance(system, MultiArmSystem):
            raise InputError(f"system: expected a MultiArmSystem, got {type(system).__name__}")
        self.system = system

    def __call__(self, t: float, state: SystemState, evaluation: Evaluation) -> np.ndarray:
        """Joint torques (nv,) [N m] at time ``t`` [s]."""
        raise NotImplementedError


class ZeroTorque(Controller):
    """``τ = 0``."""

    name = "none"

    def __call__(self, t, state, evaluation) -> np.ndarray:
        """(nv,) zeros."""
        return np.zeros(self.system.nv)


class GravityCompensation(Controller):
    """``τ = g(q)``: the arms' own gravity torques (not the object's weight)."""

    name = "gravity_compensation"

    def __call__(self, t, state, evaluation) -> np.ndarray:
        """(nv,) gravity torques [N m]."""
        return self.system.gravity_torques(state.q)


def _gain(value, size: int, name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        arr = np.full(size, float(arr))
    if arr.shape != (size,) or not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise InputError(f"{name}: expected a gain >= 0 or {size} of them, got {value!r}")
    return arr


class JointPD(Controller):
    """``τ = g(q) + K_p (q_ref ⊖ q) - K_d v``.

    Args:
        system: the system.
        kp: stiffness [N m/rad], scalar or (nv,).
        kd: damping [N m s/rad], scalar or (nv,).
        q_ref: (nq,) reference configuration; the configuration at the first call if None.
    """

    name = "joint_pd"

    def __init__(self, system: MultiArmSystem, kp=100.0, kd=20.0, q_ref=None):
        super().__init__(system)
        self.kp = _gain(kp, system.nv, "joint_pd kp")
        self.kd = _gain(kd, system.nv, "joint_pd kd")
        self.q_ref = None
        if q_ref is not None:
            q = np.asarray(q_ref, dtype=float)
            if q.shape != (system.nq,) or not np.all(np.isfinite(q)):
                raise InputError(f"joint_pd q_ref: expected ({system.nq},) numbers, got {q_ref!r}")
            self.q_ref = q

    def __call__(self, t, state, evaluation) -> np.ndarray:
        """(nv,) torques [N m]."""
        if self.q_ref is None:
            self.q_ref = np.array(state.q, dtype=float)
        model = self.system.arm_set.model
        err = pin.difference(model, state.q, self.q_ref)
        return self.system.gravity_torques(state.q) + self.kp * err - self.kd * state.v


# ---------------------------------------------------------------------- force distribution
@dataclass(frozen=True)
class ForceDistribution:
    """Contact multipliers that produce a required wrench on the object.

    Attributes:
        mu: (Σ N_i,) multipliers [N], arm-major (``SystemBlocks.flatten_mu`` order).
        min_unilateral: smallest multiplier among unilateral contacts [N] (inf if none).
        residual: ``‖W_o μ - w‖`` [N, N m].
    """

    mu: np.ndarray
    min_unilateral: float
    residual: float


def distribute_forces(W_o: np.ndarray, wrench: np.ndarray, unilateral: np.ndarray,
                      margin: float = 1.0) -> ForceDistribution:
    """Smallest multipliers producing ``wrench``, every unilateral one at least ``margin``.

    Solves ``min ‖μ‖²`` subject to ``W_o μ = wrench`` and ``μ_k >= margin`` for unilateral k
    (a small QP: SLSQP after an LP feasibility test). Without unilateral contacts it is the
    least-norm solution ``W_o⁺ wrench``.

    Args:
        W_o: (6, K) contact wrenches on the object per unit multiplier (LWA at the COM).
        wrench: (6,) total contact wrench required on the object [N, N m].
        unilateral: (K,) bool, which multipliers must be >= ``margin``.
        margin: smallest push [N] of a unilateral contact (>= 0).

    Returns:
        :class:`ForceDistribution`.

    Raises:
        DynamicsError: no multipliers satisfy the constraints (the contacts cannot produce the
            wrench with every unilateral force >= margin: not a form-closure grasp for it).
    """
    W_o = np.asarray(W_o, dtype=float)
    w = np.asarray(wrench, dtype=float)
    uni = np.asarray(unilateral, dtype=bool)
    K = W_o.shape[1]
    if W_o.shape != (6, K) or w.shape != (6,) or uni.shape != (K,):
        raise InputError(
            f"distribute_forces: expected W_o (6, K), wrench (6,), unilateral (K,); got "
            f"{W_o.shape}, {w.shape}, {uni.shape}"
        )
    if not (np.isfinite(margin) and margin >= 0):
        raise InputError(f"margin: expected a force >= 0 [N], got {margin!r}")
    scale = max(float(np.abs(w).max()), 1.0)
    tol = 1e-9 * scale
    mu = np.linalg.lstsq(W_o, w, rcond=None)[0]
    if not uni.any() or mu[uni].min() >= margin:
        return _distribution(mu, W_o, w, uni)
    from scipy.optimize import linprog, minimize

    bounds = [(margin, None) if u else (None, None) for u in uni]
    lp = linprog(np.zeros(K), A_eq=W_o, b_eq=w, bounds=bounds, method="highs")
    if lp.status != 0:
        raise DynamicsError(
            f"force distribution: no contact forces produce the wrench {np.round(w, 6).tolist()} "
            f"with every unilateral contact pushing >= {margin:g} N ({int(uni.sum())} unilateral "
            f"of {K} contacts; LP: {lp.message})"
        )
    res = minimize(
        lambda x: float(x @ x), lp.x, jac=lambda x: 2.0 * x, method="SLSQP", bounds=bounds,
        constraints=[{"type": "eq", "fun": lambda x: W_o @ x - w, "jac": lambda x: W_o}],
        options={"ftol": 1e-14, "maxiter": 200},
    )
    x = res.x if res.success else lp.x
    x = x + np.linalg.lstsq(W_o, w - W_o @ x, rcond=None)[0]  # restore equality exactly
    if uni.any() and x[uni].min() < margin - 1e-6 * scale:
        x = lp.x
    if np.linalg.norm(W_o @ x - w) > max(tol, 1e-8):
        x = lp.x
    return _distribution(x, W_o, w, uni)


def _distribution(mu, W_o, w, uni) -> ForceDistribution:
    return ForceDistribution(mu, float(mu[uni].min()) if uni.any() else float("inf"),
                             float(np.linalg.norm(W_o @ mu - w)))


# ---------------------------------------------------------------------- inverse dynamics
@dataclass(frozen=True)
class InverseDynamics:
    """Torques for a desired motion and the contact multipliers they go with.

    Attributes:
        tau: (nv,) joint torques [N m].
        qdd: (n, nv_max) joint accelerations (padded).
        mu: (n, N_max) multipliers [N] (padded).
        a_o: (6,) object acceleration ``[ẍ; ω̇]`` (world, COM).
    """

    tau: np.ndarray
    qdd: np.ndarray
    mu: np.ndarray
    a_o: np.ndarray


def inverse_dynamics(system: MultiArmSystem, blocks: SystemBlocks, a_o: np.ndarray,
                     mu: np.ndarray, qdd_secondary: np.ndarray | None = None
                     ) -> InverseDynamics:
    """Joint torques that give the object acceleration ``a_o`` with multipliers ``mu``.

    Joint accelerations: ``q̈_i = (W_iᵀ)⁺ (c_i - W_o,iᵀ a_o) + (I - (W_iᵀ)⁺ W_iᵀ) q̈_sec,i``
    (the constraint rows hold; ``q̈_sec`` acts in their null space: relative motion in the
    joint and redundancy). Torques: ``τ_i = M_i q̈_i - h_i - W_i μ_i`` (thesis Eq 3.10 in joint
    space). ``mu`` must satisfy ``M_o a_o = h_o + Σ W_o,i μ_i`` (see
    :func:`distribute_forces`) for the object equation to hold.

    Args:
        system: the system.
        blocks: blocks at zero torque (``h = -nle``).
        a_o: (6,) desired object acceleration [m/s², rad/s²].
        mu: (n, N_max) multipliers [N], zero on padding.
        qdd_secondary: (n, nv_max) desired joint accelerations in the null space (zero if None).

    Returns:
        :class:`InverseDynamics`.
    """
    b = blocks
    Wt = b.W.transpose(0, 2, 1)  # (n, N_max, nv_max)
    rhs = b.c - np.einsum("nik,i->nk", b.W_o, a_o)
    P = np.linalg.pinv(Wt, rcond=1e-10)  # (n, nv_max, N_max), batched
    qdd = np.einsum("nvk,nk->nv", P, rhs)
    if qdd_secondary is not None:
        sec = qdd_secondary - np.einsum("nvk,nk->nv", P, np.einsum("nkv,nv->nk", Wt, qdd_secondary))
        qdd = qdd + sec
    qdd = qdd * system.arm_set.dof_mask
    tau_p = np.einsum("nuv,nv->nu", b.M, qdd) - b.h - np.einsum("nvk,nk->nv", b.W, mu)
    return InverseDynamics(system.unpad(tau_p), qdd, mu, np.asarray(a_o, dtype=float))


class ObjectPD(Controller):
    """Object-level computed torque on the inverse dynamics with force distribution.

    Args:
        system: the system.
        trajectory: desired object pose over time (a :class:`MinimumJerkTrajectory`, or a
            mapping ``{"times", "positions", "quaternions"}``); hold the first call's pose if
            None.
        kp: pose stiffness [1/s²], scalar or (6,) ``[x y z, rx ry rz]``.
        kd: pose damping [1/s], scalar or (6,).
        margin: least push [N] of every unilateral contact.
        null_kp: stiffness [1/s²] of the joint-space PD in the constraints' null space (keeps
            the joints' relative motion and redundant arms near the first call's ``q``).
        null_kd: its damping [1/s].

    Attributes:
        last: the :class:`InverseDynamics` of the last call (its ``mu`` are the planned forces).
    """

    name = "object_pd"

    def __init__(self, system: MultiArmSystem, trajectory=None, kp=100.0, kd=20.0,
                 margin: float = 1.0, null_kp: float = 25.0, null_kd: float = 10.0):
        super().__init__(system)
        if trajectory is not None and not isinstance(trajectory, MinimumJerkTrajectory):
            try:
                trajectory = MinimumJerkTrajectory(**dict(trajectory))
            except TypeError as exc:
                raise InputError(
                    "object_pd trajectory: expected a MinimumJerkTrajectory or a mapping with "
                    f"times, positions and quaternions, got {trajectory!r}"
                ) from exc
        self.trajectory = trajectory
        self.kp = _gain(kp, 6, "object_pd kp")
        self.kd = _gain(kd, 6, "object_pd kd")
        self.null_kp = float(_gain(null_kp, 1, "object_pd null_kp")[0])
        self.null_kd = float(_gain(null_kd, 1, "object_pd null_kd")[0])
        if not (np.isfinite(margin) and margin >= 0):
            raise InputError(f"object_pd margin: expected a force >= 0 [N], got {margin!r}")
        self.margin = float(margin)
        self.q_ref: np.ndarray | None = None
        self.last: InverseDynamics | None = None

    def desired_acceleration(self, t: float, state: SystemState) -> np.ndarray:
        """(6,) ``a_d = a_ref + K_d (v_ref - v_o) + K_p e`` [m/s², rad/s²], world at the COM."""
        o = state.obj
        if self.trajectory is None:
            self.trajectory = MinimumJerkTrajectory.hold(o.position, o.quaternion)
        ref = self.trajectory(t)
        e = pose_error(ref.position, ref.rotation, o.position, o.rotation)
        return ref.acceleration + self.kd * (ref.twist - o.twist) + self.kp * e

    def __call__(self, t, state, evaluation) -> np.ndarray:
        """(nv,) torques [N m]."""
        s = self.system
        b = evaluation.blocks
        if self.q_ref is None:
            self.q_ref = np.array(state.q, dtype=float)
        a_d = self.desired_acceleration(t, state)
        wrench = b.M_o @ a_d - b.h_o
        fd = distribute_forces(b.stacked_W_o(), wrench, s.unilateral[b.constraint_mask],
                               self.margin)
        mu = b.unflatten_mu(fd.mu)
        err = pin.difference(s.arm_set.model, state.q, self.q_ref)
        sec = s.pad(self.null_kp * err - self.null_kd * state.v)
        self.last = inverse_dynamics(s, b, a_d, mu, sec)
        return self.last.tau


CONTROLLERS: dict[str, type[Controller]] = {
    c.name: c for c in (ZeroTorque, GravityCompensation, JointPD, ObjectPD)
}
"""Controller classes by type name."""


def make_controller(kind: str, system: MultiArmSystem, **params) -> Controller:
    """Build a controller by type name.

    Args:
        kind: one of ``CONTROLLERS`` (``none``, ``gravity_compensation``, ``joint_pd``,
            ``object_pd``).
        system: the system to control.
        **params: the keyword arguments of that controller.

    Raises:
        InputError: unknown type (lists the known ones) or bad parameters.
    """
    if kind not in CONTROLLERS:
        raise InputError(
            f"unknown controller type {kind!r}; known types: {', '.join(sorted(CONTROLLERS))}"
        )
    try:
        return CONTROLLERS[kind](system, **params)
    except TypeError as exc:
        raise InputError(f"controller {kind!r}: bad parameters {sorted(params)}: {exc}") from exc


ControllerFunction = Callable[[float, SystemState, Evaluation], np.ndarray]

__all__ = [
    "CONTROLLERS",
    "Controller",
    "ControllerFunction",
    "ForceDistribution",
    "GravityCompensation",
    "InverseDynamics",
    "JointPD",
    "ObjectPD",
    "ZeroTorque",
    "distribute_forces",
    "inverse_dynamics",
    "make_controller",
]
