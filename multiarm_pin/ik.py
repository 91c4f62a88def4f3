"""Inverse kinematics on Pinocchio: Levenberg-Marquardt with joint limits.

Puts an arm where a scenario wants it: its tool at a placement (a weld's
``placement_in_object``), or several of its frames (fingertips) at points or on planes
(fingertips on named faces of the object). Every task is a residual ``e(q)`` with a
Jacobian ``∂e/∂q``; all tasks are stacked and minimised by damped least squares
(Levenberg-Marquardt, adaptive damping) from a seed ``q_seed``, with the joints clipped to
their position limits after every step. All quantities are in the world frame [m, rad].

Task residuals (stacked, each with its weight):

- :class:`PoseTarget`: ``log6(oMf_target⁻¹ oMf(q))`` (6,) in the frame's local axes,
  Jacobian ``Jlog6 · J_local``;
- :class:`PointTarget`: ``p_f(q) - p_target`` (3,) in world axes, Jacobian the linear rows of
  the LOCAL_WORLD_ALIGNED frame Jacobian;
- :class:`PlaneTarget`: ``n · p_f(q) - d`` (1,), the signed distance of the frame's origin to
  the plane ``n · x = d``.

Targets may be *primary* (they must be met within ``tol``) or secondary (``primary=False``:
preferences, met as well as the primary tasks allow). Secondary tasks are solved first
together with the primary ones at a small weight; a last phase then refines the primary tasks
alone, so the primary residual ends at the solver's precision and not at a compromise.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from multiarm_pin.exceptions import FrameNotFoundError, InputError, MultiArmError
from multiarm_pin.spatial import as_array

IK_TOLERANCE = 1e-10
"""Default largest primary residual norm accepted as converged [m or rad]."""

SECONDARY_WEIGHT = 0.03
"""Weight of secondary (preference) tasks relative to primary ones."""


class UnreachableError(MultiArmError, ValueError):
    """Inverse kinematics found no configuration meeting the targets (out of reach).

    Attributes:
        residual: the norm of the primary residual left at the best configuration found
            [m for points/planes; mixed m and rad for poses].
        q: (nq,) that best configuration.
        details: a per-target description of what is left.
    """

    def __init__(self, what: str, residual: float, q: np.ndarray, details: str = ""):
        self.residual = float(residual)
        self.q = np.asarray(q, float).copy()
        self.details = details
        msg = (
            f"{what}: out of reach, inverse kinematics left a residual of {self.residual:.3g} "
            "(tolerance met nowhere from the seed and its perturbations)"
        )
        if details:
            msg += f"; {details}"
        super().__init__(msg)


@dataclass(frozen=True)
class PoseTarget:
    """A frame's full placement in the world.

    Attributes:
        frame: frame name in the model.
        placement: target world placement ``oMf`` (``pin.SE3``).
        primary: must be met (True) or is a preference (False).
    """

    frame: str
    placement: pin.SE3
    primary: bool = True


@dataclass(frozen=True)
class PointTarget:
    """A frame's origin at a world point.

    Attributes:
        frame: frame name in the model.
        point: (3,) target position in the world [m].
        primary: must be met (True) or is a preference (False).
    """

    frame: str
    point: np.ndarray
    primary: bool = True


@dataclass(frozen=True)
class PlaneTarget:
    """A frame's origin on the plane ``normal · x = offset`` (world).

    Attributes:
        frame: frame name in the model.
        normal: (3,) unit normal in world axes.
        offset: plane offset ``d`` [m].
        primary: must be met (True) or is a preference (False).
    """

    frame: str
    normal: np.ndarray
    offset: float
    primary: bool = True


Target = PoseTarget | PointTarget | PlaneTarget


@dataclass(frozen=True)
class IKResult:
    """Outcome of :func:`solve_ik`.

    Attributes:
        q: (nq,) the configuration found.
        residual: norm of the stacked primary residual at ``q``.
        secondary_residual: norm of the stacked secondary residual at ``q`` (0 if none).
        iterations: Levenberg-Marquardt iterations used (all phases and restarts).
        restarts: perturbed seeds tried after the first one.
        at_limit: (nq,) bool, joints sitting on a position limit.
    """

    q: np.ndarray
    residual: float
    secondary_residual: float
    iterations: int
    restarts: int
    at_limit: np.ndarray


class _Problem:
    """Targets resolved to frame ids, with residual/Jacobian evaluation."""

    def __init__(self, model: pin.Model, targets: Sequence[Target]):
        self.model = model
        self.data = model.createData()
        names = [f.name for f in model.frames]
        self.items = []
        for k, tgt in enumerate(targets):
            if not isinstance(tgt, PoseTarget | PointTarget | PlaneTarget):
                raise InputError(
                    f"IK target {k}: expected PoseTarget, PointTarget or PlaneTarget, "
                    f"got {type(tgt).__name__}"
                )
            if not model.existFrame(tgt.frame):
                raise FrameNotFoundError(tgt.frame, names, model.name)
            fid = model.getFrameId(tgt.frame)
            if isinstance(tgt, PoseTarget):
                if not isinstance(tgt.placement, pin.SE3):
                    raise InputError(f"IK target {k}: placement must be a pin.SE3")
                data = tgt.placement.copy()
            elif isinstance(tgt, PointTarget):
                data = as_array(tgt.point, (3,), f"IK target {k} ({tgt.frame}) point")
            else:
                n = as_array(tgt.normal, (3,), f"IK target {k} ({tgt.frame}) normal")
                norm = np.linalg.norm(n)
                if norm < 1e-12:
                    raise InputError(f"IK target {k} ({tgt.frame}): plane normal is zero")
                data = (n / norm, float(tgt.offset) / norm)
            self.items.append((tgt, fid, data))
        # joint-limit clipping only on one-coordinate joints (revolute/prismatic)
        lo = np.full(model.nq, -np.inf)
        hi = np.full(model.nq, np.inf)
        for j in model.joints[1:]:
            if j.nq == 1 and j.nv == 1:
                lo[j.idx_q] = model.lowerPositionLimit[j.idx_q]
                hi[j.idx_q] = model.upperPositionLimit[j.idx_q]
        lo[~np.isfinite(lo) | (lo < -1e10)] = -np.inf
        hi[~np.isfinite(hi) | (hi > 1e10)] = np.inf
        self.lower, self.upper = lo, hi

    def evaluate(self, q: np.ndarray, primary_only: bool, w2: float):
        """Stacked weighted residual, Jacobian, and the primary/secondary residual norms."""
        model, data = self.model, self.data
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        es, Js = [], []
        p2 = s2 = 0.0
        for tgt, fid, tdata in self.items:
            if primary_only and not tgt.primary:
                continue
            oMf = data.oMf[fid]
            if isinstance(tgt, PoseTarget):
                dM = tdata.actInv(oMf)
                e = pin.log6(dM).vector
                J = pin.Jlog6(dM) @ pin.getFrameJacobian(
                    model, data, fid, pin.ReferenceFrame.LOCAL
                )
            else:
                Jl = pin.getFrameJacobian(
                    model, data, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
                )[:3]
                if isinstance(tgt, PointTarget):
                    e = oMf.translation - tdata
                    J = Jl
                else:
                    n, d = tdata
                    e = np.array([n @ oMf.translation - d])
                    J = n[None, :] @ Jl
            if tgt.primary:
                p2 += float(e @ e)
                w = 1.0
            else:
                s2 += float(e @ e)
                w = w2
            es.append(w * e)
            Js.append(w * J)
        return np.concatenate(es), np.vstack(Js), np.sqrt(p2), np.sqrt(s2)

    def step(self, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
        return np.clip(pin.integrate(self.model, q, dq), self.lower, self.upper)


def _lm(problem: _Problem, q: np.ndarray, primary_only: bool, w2: float, max_iter: int,
        tol: float):
    """Levenberg-Marquardt from ``q``; returns (q, primary norm, secondary norm, iterations)."""
    e, J, pn, sn = problem.evaluate(q, primary_only, w2)
    cost = float(e @ e)
    lam = 1e-3
    it = 0
    while it < max_iter:
        if primary_only and pn < tol:
            break
        it += 1
        g = J.T @ e
        H = J.T @ J
        if np.linalg.norm(g) < 1e-15:
            break
        accepted = False
        for _ in range(12):
            dq = -np.linalg.solve(H + lam * np.eye(len(g)), g)
            q_new = problem.step(q, dq)
            e_new, J_new, pn_new, sn_new = problem.evaluate(q_new, primary_only, w2)
            c_new = float(e_new @ e_new)
            if c_new < cost:
                q, e, J, pn, sn, cost = q_new, e_new, J_new, pn_new, sn_new, c_new
                lam = max(lam / 3.0, 1e-12)
                accepted = True
                break
            lam *= 5.0
        if not accepted:
            break
    return q, pn, sn, it


def solve_ik(
    model: pin.Model,
    targets: Sequence[Target],
    q_seed=None,
    *,
    tol: float = IK_TOLERANCE,
    max_iter: int = 200,
    restarts: int = 10,
    seed: int = 0,
    what: str = "inverse kinematics",
) -> IKResult:
    """Find ``q`` meeting all primary targets, as near as possible to the secondary ones.

    Args:
        model: the Pinocchio model (its frames' world placements are the targets' frame).
        targets: :class:`PoseTarget` / :class:`PointTarget` / :class:`PlaneTarget` list.
        q_seed: (nq,) starting configuration (default: the neutral one clipped to limits).
        tol: largest primary residual norm accepted [m, rad].
        max_iter: iterations per phase.
        restarts: extra attempts from the seed perturbed (uniformly, ±0.5 rad, seeded) when
            the first one fails; the best is kept.
        seed: random seed of the perturbations.
        what: label for the error message (e.g. ``"arms[1] (left): tool placement"``).

    Returns:
        :class:`IKResult`; ``q`` respects the joint position limits.

    Raises:
        InputError: bad seed or targets; FrameNotFoundError: unknown frame.
        UnreachableError: no configuration meets the primary targets within ``tol``
            (carries the remaining residual and the best ``q``).
    """
    if not targets:
        raise InputError(f"{what}: no IK targets given")
    problem = _Problem(model, targets)
    if q_seed is None:
        q0 = pin.neutral(model)
    else:
        q0 = as_array(q_seed, (model.nq,), f"{what}: q_seed (nq={model.nq})")
    q0 = np.clip(q0, problem.lower, problem.upper)
    has_secondary = any(not t.primary for t, _, _ in problem.items)
    rng = np.random.default_rng(seed)
    best = None
    total_it = 0
    attempts = 0
    for attempt in range(restarts + 1):
        attempts = attempt
        if attempt == 0:
            q = q0.copy()
        else:
            q = problem.step(q0, rng.uniform(-0.5, 0.5, model.nv))
        if has_secondary:
            q, _, _, it = _lm(problem, q, False, SECONDARY_WEIGHT, max_iter, tol)
            total_it += it
        q, pn, _, it = _lm(problem, q, True, 0.0, max_iter, tol)
        total_it += it
        if best is None or pn < best[1]:
            best = (q, pn)
        if pn < tol:
            break
    q, pn = best
    if pn >= tol:
        raise UnreachableError(what, pn, q, _describe(problem, q))
    sn = problem.evaluate(q, False, 1.0)[3] if has_secondary else 0.0
    at_limit = (np.abs(q - problem.lower) < 1e-9) | (np.abs(q - problem.upper) < 1e-9)
    return IKResult(q=q, residual=pn, secondary_residual=sn, iterations=total_it,
                    restarts=attempts, at_limit=at_limit)


def _describe(problem: _Problem, q: np.ndarray) -> str:
    """Per-target remaining error at ``q``, for messages."""
    pin.framesForwardKinematics(problem.model, problem.data, q)
    parts = []
    for tgt, fid, tdata in problem.items:
        if not tgt.primary:
            continue
        oMf = problem.data.oMf[fid]
        if isinstance(tgt, PoseTarget):
            err = pin.log6(tdata.actInv(oMf)).vector
            dp = np.linalg.norm(oMf.translation - tdata.translation)
            parts.append(f"{tgt.frame}: position error {dp:.3g} m, orientation error "
                         f"{np.linalg.norm(err[3:]):.3g} rad")
        elif isinstance(tgt, PointTarget):
            parts.append(f"{tgt.frame}: {np.linalg.norm(oMf.translation - tdata):.3g} m from its "
                         "point")
        else:
            n, d = tdata
            parts.append(f"{tgt.frame}: {n @ oMf.translation - d:+.3g} m from its plane")
    return "; ".join(parts)


def ik_tool_placement(arm, placement: pin.SE3, q_seed=None, **kwargs) -> IKResult:
    """Configuration putting an arm's tool frame at a world placement.

    Args:
        arm: a :class:`multiarm_pin.arm.Arm` (base placement baked into its model).
        placement: target tool placement in the world (``pin.SE3``).
        q_seed: (nq,) starting configuration.
        **kwargs: passed to :func:`solve_ik`.

    Raises:
        UnreachableError: the placement is out of reach (message gives the errors left).
    """
    tool = arm.model.frames[arm.tool_frame_id].name
    kwargs.setdefault("what", f"arm {arm.name!r}: tool placement")
    return solve_ik(arm.model, [PoseTarget(tool, placement)], q_seed, **kwargs)


def ik_frame_points(arm, frames: Sequence[str], points, q_seed=None, **kwargs) -> IKResult:
    """Configuration putting several frames of an arm (fingertips) at world points at once.

    Args:
        arm: a :class:`multiarm_pin.arm.Arm`.
        frames: K frame names.
        points: (K, 3) target positions in the world [m].
        q_seed: (nq,) starting configuration.
        **kwargs: passed to :func:`solve_ik`.
    """
    pts = as_array(points, (len(frames), 3), "IK points (K, 3)")
    kwargs.setdefault("what", f"arm {arm.name!r}: frames {list(frames)}")
    return solve_ik(arm.model, [PointTarget(f, p) for f, p in zip(frames, pts, strict=True)],
                    q_seed, **kwargs)


__all__ = [
    "IK_TOLERANCE",
    "IKResult",
    "PlaneTarget",
    "PointTarget",
    "PoseTarget",
    "Target",
    "UnreachableError",
    "ik_frame_points",
    "ik_tool_placement",
    "solve_ik",
]
