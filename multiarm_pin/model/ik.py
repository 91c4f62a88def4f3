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

One module on purpose: the target types are plain data whose only reader is the
stacked problem (each target's residual and Jacobian), and the solve, its phases and its
failure diagnosis all work on that problem; split, every change to a target would touch both.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from multiarm_pin.exceptions import FrameNotFoundError, InputError, UnreachableError
from multiarm_pin.model.arm import frame_id
from multiarm_pin.spatial import as_array, skew

IK_TOLERANCE = 1e-10
"""Default largest primary residual norm accepted as converged [m or rad]."""

SECONDARY_WEIGHT = 0.03
"""Weight of secondary (preference) tasks relative to primary ones."""


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
    """A point fixed to a frame (its origin by default) at a world point.

    Attributes:
        frame: frame name in the model.
        point: (3,) target position in the world [m].
        primary: must be met (True) or is a preference (False).
        offset: (3,) the point in the frame's local axes [m] (None: the origin).
    """

    frame: str
    point: np.ndarray
    primary: bool = True
    offset: np.ndarray | None = None


@dataclass(frozen=True)
class AxisTarget:
    """A direction fixed to a frame along a world direction (2 constraints).

    Residual ``R_f(q) a_local - a_world`` (3,); its Jacobian ``-[R_f a_local]_× J_ω``.

    Attributes:
        frame: frame name in the model.
        axis_local: (3,) unit direction in the frame's axes.
        axis_world: (3,) unit direction in the world.
        primary: must be met (True) or is a preference (False).
    """

    frame: str
    axis_local: np.ndarray
    axis_world: np.ndarray
    primary: bool = True


@dataclass(frozen=True)
class PostureTarget:
    """A preference for configurations near ``q_ref``: residual ``weight · (q ⊖ q_ref)`` (nv,).

    Always secondary; it picks, among the configurations meeting the primary targets, one
    near the seed (a continuous family for a spherical joint, a branch for a weld).

    Attributes:
        q_ref: (nq,) preferred configuration.
        weight: scale relative to the other secondary targets.
    """

    q_ref: np.ndarray
    weight: float = 0.1
    primary: bool = False


@dataclass(frozen=True)
class PlaneTarget:
    """A point fixed to a frame (its origin by default) on the plane ``normal · x = offset``.

    Attributes:
        frame: frame name in the model.
        normal: (3,) unit normal in world axes.
        offset: plane offset ``d`` [m].
        primary: must be met (True) or is a preference (False).
        point: (3,) the point in the frame's local axes [m] (None: the origin).
    """

    frame: str
    normal: np.ndarray
    offset: float
    primary: bool = True
    point: np.ndarray | None = None


Target = PoseTarget | PointTarget | PlaneTarget | AxisTarget | PostureTarget
_TARGET_TYPES = (PoseTarget, PointTarget, PlaneTarget, AxisTarget, PostureTarget)


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


def _local_point(point, label: str) -> np.ndarray:
    return np.zeros(3) if point is None else as_array(point, (3,), f"{label} local point")


def _unit(v, label: str) -> np.ndarray:
    v = as_array(v, (3,), label)
    n = float(np.linalg.norm(v))
    if n < 1e-12:
        raise InputError(f"{label}: direction is zero")
    return v / n


class _Problem:
    """Targets resolved to frame ids, with residual/Jacobian evaluation."""

    def __init__(self, model: pin.Model, targets: Sequence[Target]):
        self.model = model
        self.data = model.createData()
        names = [f.name for f in model.frames]
        self.items = []
        for k, tgt in enumerate(targets):
            if not isinstance(tgt, _TARGET_TYPES):
                raise InputError(
                    f"IK target {k}: expected one of "
                    f"{', '.join(t.__name__ for t in _TARGET_TYPES)}, got {type(tgt).__name__}"
                )
            if isinstance(tgt, PostureTarget):
                q_ref = as_array(tgt.q_ref, (model.nq,), f"IK target {k} (posture) q_ref")
                self.items.append((tgt, -1, (q_ref, float(tgt.weight))))
                continue
            if not model.existFrame(tgt.frame):
                raise FrameNotFoundError(tgt.frame, names, model.name)
            fid = frame_id(model, tgt.frame)
            label = f"IK target {k} ({tgt.frame})"
            if isinstance(tgt, PoseTarget):
                if not isinstance(tgt.placement, pin.SE3):
                    raise InputError(f"IK target {k}: placement must be a pin.SE3")
                data = tgt.placement.copy()
            elif isinstance(tgt, PointTarget):
                data = (as_array(tgt.point, (3,), f"{label} point"),
                        _local_point(tgt.offset, label))
            elif isinstance(tgt, AxisTarget):
                data = (_unit(tgt.axis_local, f"{label} axis_local"),
                        _unit(tgt.axis_world, f"{label} axis_world"))
            else:
                n = as_array(tgt.normal, (3,), f"{label} normal")
                norm = np.linalg.norm(n)
                if norm < 1e-12:
                    raise InputError(f"{label}: plane normal is zero")
                data = (n / norm, float(tgt.offset) / norm, _local_point(tgt.point, label))
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
        # one-coordinate revolute joints: q and q ± 2π place every frame the same
        self.revolute = [j.idx_q for j in model.joints[1:] if j.nq == 1
                         and (j.shortname().startswith("JointModelR")
                              and not j.shortname().startswith("JointModelRUB")
                              or j.shortname() == "JointModelRevoluteUnaligned")]

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
            if isinstance(tgt, PostureTarget):
                q_ref, weight = tdata
                e = weight * pin.difference(model, q_ref, q)
                J = weight * pin.dDifference(model, q_ref, q, pin.ArgumentPosition.ARG1)
                es.append(w2 * e)
                Js.append(w2 * J)
                continue
            oMf = data.oMf[fid]
            if isinstance(tgt, PoseTarget):
                dM = tdata.actInv(oMf)
                e = pin.log6(dM).vector
                J = pin.Jlog6(dM) @ pin.getFrameJacobian(
                    model, data, fid, pin.ReferenceFrame.LOCAL
                )
            else:
                J6 = pin.getFrameJacobian(model, data, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
                if isinstance(tgt, AxisTarget):
                    a = oMf.rotation @ tdata[0]
                    e = a - tdata[1]
                    J = -skew(a) @ J6[3:]
                else:
                    local = tdata[-1]
                    r = oMf.rotation @ local
                    p = oMf.translation + r
                    Jp = J6[:3] - skew(r) @ J6[3:]
                    if isinstance(tgt, PointTarget):
                        e = p - tdata[0]
                        J = Jp
                    else:
                        n, d = tdata[0], tdata[1]
                        e = np.array([n @ p - d])
                        J = n[None, :] @ Jp
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
        targets: :class:`PoseTarget`, :class:`PointTarget`, :class:`PlaneTarget`,
            :class:`AxisTarget`, :class:`PostureTarget` (a preference for the seed's
            neighbourhood).
        q_seed: (nq,) starting configuration (default: the neutral one clipped to limits).
        tol: largest primary residual norm accepted [m, rad].
        max_iter: iterations per phase.
        restarts: when the seed fails, the seed moved by ±0.5 rad along each joint in turn
            is tried (2 nv attempts; of the successes the one nearest the seed is kept: a
            symmetric set, so mirror-symmetric seeds give mirror-symmetric results), then, if
            none succeeded, up to ``restarts`` random perturbations (uniform ±0.5 rad).
        seed: random seed of the random perturbations.
        what: label for the error message (e.g. ``"arms[1] (left): tool placement"``).

    Returns:
        :class:`IKResult`; ``q`` respects the joint position limits, and each revolute
        coordinate is the one of its whole-turn equivalents (``± 2π``) within the limits
        nearest to the seed.

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
    total_it = 0

    def attempt(q: np.ndarray) -> tuple[np.ndarray, float]:
        nonlocal total_it
        if has_secondary:
            q, _, _, it = _lm(problem, q, False, SECONDARY_WEIGHT, max_iter, tol)
            total_it += it
        q, pn, _, it = _lm(problem, q, True, 0.0, max_iter, tol)
        total_it += it
        return _nearest_turn(problem, q, q0), pn

    def distance(q: np.ndarray) -> float:
        return float(np.linalg.norm(pin.difference(model, q0, q)))

    q, pn = attempt(q0.copy())
    best, attempts = (q, pn), 0
    if pn >= tol:
        # the seed moved by ±0.5 rad along each joint in turn: a set that a mirror symmetry
        # (joint signs flipped) maps onto itself, so symmetric seeds keep symmetric results;
        # of the successes, the one nearest the seed wins
        found = []
        for k in range(2 * model.nv):
            dq = np.zeros(model.nv)
            dq[k // 2] = 0.5 if k % 2 == 0 else -0.5
            q, pn = attempt(problem.step(q0, dq))
            attempts += 1
            if pn < tol:
                found.append((distance(q), k, q, pn))
            elif pn < best[1]:
                best = (q, pn)
        if found:
            _, _, q, pn = min(found, key=lambda f: (round(f[0], 9), f[1]))
            best = (q, pn)
        else:
            rng = np.random.default_rng(seed)
            for _ in range(restarts):
                q, pn = attempt(problem.step(q0, rng.uniform(-0.5, 0.5, model.nv)))
                attempts += 1
                if pn < best[1]:
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


def _nearest_turn(problem: _Problem, q: np.ndarray, q_ref: np.ndarray) -> np.ndarray:
    """``q`` with each revolute coordinate turned by whole turns (2π) nearest to ``q_ref``.

    Only within the joint's limits; every frame keeps its placement.
    """
    q = q.copy()
    for c in problem.revolute:
        k = np.round((q_ref[c] - q[c]) / (2 * np.pi))
        for cand in (q[c] + 2 * np.pi * k, q[c] + 2 * np.pi * (k - np.sign(k))):
            if problem.lower[c] <= cand <= problem.upper[c]:
                if abs(cand - q_ref[c]) < abs(q[c] - q_ref[c]):
                    q[c] = cand
                break
    return q


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
        elif isinstance(tgt, AxisTarget):
            c = float(np.clip((oMf.rotation @ tdata[0]) @ tdata[1], -1.0, 1.0))
            parts.append(f"{tgt.frame}: axis {np.arccos(c):.3g} rad from its direction")
        else:
            p = oMf.act(tdata[-1])
            if isinstance(tgt, PointTarget):
                parts.append(f"{tgt.frame}: {np.linalg.norm(p - tdata[0]):.3g} m from its point")
            else:
                parts.append(f"{tgt.frame}: {tdata[0] @ p - tdata[1]:+.3g} m from its plane")
    return "; ".join(parts)


def ik_tool_placement(arm, placement: pin.SE3, q_seed=None, **kwargs) -> IKResult:
    """Configuration putting an arm's tool frame at a world placement.

    Args:
        arm: a :class:`multiarm_pin.model.arm.Arm` (base placement baked into its model).
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
        arm: a :class:`multiarm_pin.model.arm.Arm`.
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
    "AxisTarget",
    "IKResult",
    "PlaneTarget",
    "PointTarget",
    "PoseTarget",
    "PostureTarget",
    "Target",
    "UnreachableError",
    "ik_frame_points",
    "ik_tool_placement",
    "solve_ik",
]
