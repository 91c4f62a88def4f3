"""Joint limits from the URDF (position, velocity, effort) and how a run stays within them.

:func:`arm_limits` reads an arm's limits from its Pinocchio model (``lowerPositionLimit``,
``upperPositionLimit``, ``velocityLimit``, ``effortLimit``, which Pinocchio fills from the
URDF's ``<limit>`` tags). :func:`limit_statistics` compares recorded samples with them:
for each joint its peak ``|τ| / effort``, its peak ``|v| / velocity`` and its smallest
position margin ``min(q - lower, upper - q)`` [rad or m] (negative: outside), and the first
time each limit is exceeded.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

LIMIT_TOLERANCE = 1e-9
"""Slack [rad or m] allowed beyond a joint position limit (rounding of written values)."""

RATIO_TOLERANCE = 1e-9
"""Relative slack beyond a velocity or effort limit (round-off of a value at its limit)."""


@dataclass(frozen=True)
class ArmLimits:
    """The joint limits of one arm, per velocity coordinate (nv).

    Attributes:
        joints: (nv,) joint names.
        lower, upper: (nv,) position limits [rad or m] of one-coordinate joints (``±inf``
            where there is none: continuous joints, unset limits).
        q_index: (nv,) the configuration coordinate of each joint (-1: none, e.g. a
            continuous joint's ``(cos, sin)``).
        velocity: (nv,) largest ``|v|`` [rad/s or m/s] (``inf``: none given).
        effort: (nv,) largest ``|τ|`` [N m or N] (``inf``: none given).
    """

    joints: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    q_index: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray


def one_dof_limits(model) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Position limits of a model's one-coordinate joints.

    Args:
        model: a Pinocchio model.

    Returns:
        ``(lower (nq,), upper (nq,), names (nq,))``: limits [rad or m] (``±inf`` where there is
        none: multi-coordinate joints, unbounded joints) and the joint owning each coordinate.
    """
    lo = np.full(model.nq, -np.inf)
    hi = np.full(model.nq, np.inf)
    names = [""] * model.nq
    for jid in range(1, model.njoints):
        j = model.joints[jid]
        for c in range(j.idx_q, j.idx_q + j.nq):
            names[c] = model.names[jid]
        if j.nq == 1 and j.nv == 1:
            lo[j.idx_q] = model.lowerPositionLimit[j.idx_q]
            hi[j.idx_q] = model.upperPositionLimit[j.idx_q]
    lo[~np.isfinite(lo) | (lo < -1e10)] = -np.inf
    hi[~np.isfinite(hi) | (hi > 1e10)] = np.inf
    bad = lo > hi  # some URDFs leave limits unset (0, 0) on continuous joints
    lo[bad], hi[bad] = -np.inf, np.inf
    return lo, hi, names


def _positive(x: np.ndarray) -> np.ndarray:
    """Limits that are unset (0, negative, NaN) or huge become ``inf``."""
    x = np.array(x, float)
    x[~np.isfinite(x) | (x <= 0) | (x > 1e10)] = np.inf
    return x


def arm_limits(arm) -> ArmLimits:
    """The limits of an :class:`~multiarm_pin.model.arm.Arm` (its model's, from the URDF)."""
    model = arm.model
    lo_q, hi_q, _ = one_dof_limits(model)
    nv = model.nv
    names, lower, upper = [""] * nv, np.full(nv, -np.inf), np.full(nv, np.inf)
    q_index = -np.ones(nv, dtype=int)
    for jid in range(1, model.njoints):
        j = model.joints[jid]
        for c in range(j.idx_v, j.idx_v + j.nv):
            names[c] = model.names[jid]
        if j.nq == 1 and j.nv == 1:
            lower[j.idx_v], upper[j.idx_v] = lo_q[j.idx_q], hi_q[j.idx_q]
            q_index[j.idx_v] = j.idx_q
    return ArmLimits(tuple(names), lower, upper, q_index, _positive(model.velocityLimit),
                     _positive(model.effortLimit))


@dataclass(frozen=True)
class JointStatistics:
    """How one joint used its limits over a run.

    Attributes:
        peak_torque_ratio: ``max |τ| / effort`` (None: no effort limit).
        peak_velocity_ratio: ``max |v| / velocity`` (None: no velocity limit).
        position_margin: ``min(q - lower, upper - q)`` [rad or m] (None: no position limit).
        t_torque, t_velocity, t_position: first time [s] the limit is exceeded, or None.
        peak_torque, peak_velocity: the values at the peaks [N m, rad/s].
    """

    peak_torque_ratio: float | None
    peak_velocity_ratio: float | None
    position_margin: float | None
    t_torque: float | None
    t_velocity: float | None
    t_position: float | None
    peak_torque: float
    peak_velocity: float
    worst_q: float | None


def _first(mask: np.ndarray, t: np.ndarray) -> float | None:
    idx = np.flatnonzero(mask)
    return float(t[idx[0]]) if idx.size else None


def system_limits(system) -> ArmLimits:
    """The limits of every arm of a system, in its coordinates (``q_index`` into its nq)."""
    parts = [arm_limits(a) for a in system.arms]
    aset = system.arm_set
    q_index = [np.where(lim.q_index >= 0, lim.q_index + aset.q_slices[i].start, -1)
               for i, lim in enumerate(parts)]
    if not parts:
        empty = np.zeros(0)
        return ArmLimits((), empty, empty, np.zeros(0, dtype=int), empty, empty)
    return ArmLimits(sum((lim.joints for lim in parts), ()),
                     *(np.concatenate([getattr(lim, f) for lim in parts])
                       for f in ("lower", "upper")),
                     np.concatenate(q_index),
                     *(np.concatenate([getattr(lim, f) for lim in parts])
                       for f in ("velocity", "effort")))


def exceeded(limits: ArmLimits, q: np.ndarray, v: np.ndarray, tau: np.ndarray
             ) -> dict[str, np.ndarray]:
    """Where recorded samples exceed the limits, per kind.

    Args:
        limits: the :class:`ArmLimits` of the coordinates.
        q: (T, nq) configurations [rad or m] (``limits.q_index`` indexes them).
        v: (T, nv) velocities [rad/s or m/s].
        tau: (T, nv) torques [N m or N].

    Returns:
        ``{"torque", "velocity", "position"}`` -> (T, nv) bool: ``|τ| > effort (1 +``
        :data:`RATIO_TOLERANCE` ``)``, ``|v| > velocity (1 + RATIO_TOLERANCE)``, a position
        more than :data:`LIMIT_TOLERANCE` outside its bounds (NaN: not exceeded).
    """
    with np.errstate(invalid="ignore"):
        torque = np.abs(tau) > limits.effort * (1.0 + RATIO_TOLERANCE)
        velocity = np.abs(v) > limits.velocity * (1.0 + RATIO_TOLERANCE)
        position = np.zeros(np.shape(v), dtype=bool)
        has = np.flatnonzero(limits.q_index >= 0)
        if len(has) and len(q):
            x = q[:, limits.q_index[has]]
            position[:, has] = ((x < limits.lower[has] - LIMIT_TOLERANCE)
                                | (x > limits.upper[has] + LIMIT_TOLERANCE))
    return {"torque": torque, "velocity": velocity, "position": position}


def limit_statistics(limits: ArmLimits, t: np.ndarray, q: np.ndarray, v: np.ndarray,
                     tau: np.ndarray) -> list[JointStatistics]:
    """Per joint, peaks, margins and the first violation time over recorded samples.

    Args:
        limits: the arm's :class:`ArmLimits`.
        t: (T,) times [s].
        q: (T, nq) the arm's configurations [rad or m].
        v: (T, nv) its velocities [rad/s or m/s].
        tau: (T, nv) its torques [N m or N].

    Returns:
        One :class:`JointStatistics` per joint (nv), in the model's order.
    """
    over = exceeded(limits, q, v, tau)
    out = []
    for c in range(len(limits.joints)):
        torque, speed = np.abs(tau[:, c]), np.abs(v[:, c])
        tr = vr = margin = worst = None
        t_tau = t_v = t_q = None
        if np.isfinite(limits.effort[c]):
            ratio = torque / limits.effort[c]
            tr = float(ratio.max()) if len(ratio) else 0.0
            t_tau = _first(over["torque"][:, c], t)
        if np.isfinite(limits.velocity[c]):
            ratio = speed / limits.velocity[c]
            vr = float(ratio.max()) if len(ratio) else 0.0
            t_v = _first(over["velocity"][:, c], t)
        i = limits.q_index[c]
        if i >= 0 and len(q) and (np.isfinite(limits.lower[c]) or np.isfinite(limits.upper[c])):
            m = np.minimum(q[:, i] - limits.lower[c], limits.upper[c] - q[:, i])
            k = int(np.argmin(m))
            margin, worst = float(m[k]), float(q[k, i])
            t_q = _first(over["position"][:, c], t)
        out.append(JointStatistics(tr, vr, margin, t_tau, t_v, t_q,
                                   float(torque.max(initial=0.0)),
                                   float(speed.max(initial=0.0)), worst))
    return out


__all__ = ["LIMIT_TOLERANCE", "RATIO_TOLERANCE", "ArmLimits", "JointStatistics", "arm_limits",
           "exceeded", "limit_statistics", "one_dof_limits", "system_limits"]
