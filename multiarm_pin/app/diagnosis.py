"""Causes of a failed run or an unreachable pose, named with the arm, the joint and the time.

A run that ends in an error of the dynamics (an event storm, "more than 50 contact events in
one step", or a failed solve, "W_o has rank 2 < 6") is the symptom; :func:`failure_causes`
looks at what was simulated for the usual causes, and the runner appends them to the error:

- a time step too large for the fastest closed-loop rate (:func:`fastest_rate`: Baumgarte's
  ``s² + 2α s + β²``, the controller's gains, ``sqrt(λ_max(M⁻¹ K_p))`` for joint-space
  stiffness): ``dt · rate`` beyond the integrator's stability limit
  (:data:`STABILITY_LIMITS`, on the negative real axis) or beyond 1;
- a singular arm: the smallest singular value of its tool Jacobian (6 x nv,
  LOCAL_WORLD_ALIGNED) below :data:`SINGULAR_FRACTION` of its value at t = 0;
- torques over the URDF effort limits (recorded applied torques), with the peak.

:func:`w_first_hint` explains an unreachable pose whose quaternion looks written in
``[w, x, y, z]`` order (scenarios use ``[x, y, z, w]``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np
import pinocchio as pin

from multiarm_pin.exceptions import MultiArmError

STABILITY_LIMITS = {"rk4": 2.785, "semi_implicit": 2.0}
"""Largest ``|λ| dt`` of a decaying real mode each fixed-step integrator keeps stable."""

SINGULAR_FRACTION = 0.1
"""An arm whose smallest tool-Jacobian singular value falls below this fraction of its
value at t = 0 is reported as singular."""

CONTINUOUS_STEP = 0.5
"""Largest configuration change [rad] between two samples across which a sign change of
``det J`` counts as a crossed singularity (larger: the state jumped)."""

IDENTITY_LIKE = 0.9
"""A quaternion whose last component (w as written) exceeds this in absolute value (unit
norm) is taken as meant ``[x, y, z, w]`` and not tried reordered."""

MAX_JACOBIAN_SAMPLES = 2000
"""Recorded samples at most at which the Jacobians are evaluated (evenly spaced, plus the
last)."""


def _mode_rate(k: float, c: float) -> float:
    """Largest ``|s|`` [1/s] of ``s² + c s + k = 0`` (an acceleration-level PD)."""
    if k <= 0 and c <= 0:
        return 0.0
    roots = np.roots([1.0, float(c), float(k)])
    return float(np.abs(roots).max())


def fastest_rate(built, state, controller=None) -> tuple[float, str]:
    """The fastest closed-loop rate [1/s] of a scenario and where it comes from.

    Args:
        built: the built scenario.
        state: the state at which the arms' mass matrices are taken (joint-space gains).
        controller: the run's controller, or None (built from the scenario when possible).

    Returns:
        ``(rate, source)``; ``rate`` is the largest ``|s|`` among the modes considered.
    """
    sc, system = built.scenario, built.system
    cands = []
    a, b = sc.simulation.baumgarte
    cands.append((_mode_rate(b * b, 2.0 * a),
                  f"the Baumgarte gains simulation.baumgarte (alpha = {a:g}, beta = {b:g} 1/s)"))
    if controller is None and system.n_arms and sc.controller.type != "none":
        from multiarm_pin.sim.controllers import make_controller

        try:
            controller = make_controller(sc.controller.type, system, **sc.controller.params)
        except MultiArmError:
            controller = None
    kind = sc.controller.type
    if controller is not None and kind == "object_pd":
        for kp_name, kd_name in (("kp", "kd"), ("null_kp", "null_kd"), ("hold_kp", "hold_kd")):
            kp = np.atleast_1d(getattr(controller, kp_name, 0.0))
            kd = np.atleast_1d(getattr(controller, kd_name, 0.0))
            r = max(_mode_rate(float(p), float(d)) for p, d in
                    zip(np.broadcast_to(kp, max(kp.size, kd.size)),
                        np.broadcast_to(kd, max(kp.size, kd.size)), strict=True))
            cands.append((r, f"the controller gains controller.{kp_name} = {kp.max():g}, "
                             f"{kd_name} = {kd.max():g}"))
    elif controller is not None and kind == "joint_pd":
        kp, kd = np.asarray(controller.kp, float), np.asarray(controller.kd, float)
        for arm, sl, qs in zip(system.arms, system.arm_set.v_slices, system.arm_set.q_slices,
                               strict=True):
            M = pin.crba(arm.model, arm.model.createData(), np.asarray(state.q)[qs])
            M = np.triu(M) + np.triu(M, 1).T  # whichever triangle Pinocchio filled
            Mi = np.linalg.inv(M)
            n = arm.nv
            A = np.block([[np.zeros((n, n)), np.eye(n)],
                          [-Mi @ np.diag(kp[sl]), -Mi @ np.diag(kd[sl])]])
            r = float(np.abs(np.linalg.eigvals(A)).max())
            cands.append((r, f"the joint-space gains controller.kp, kd on arm {arm.name!r} "
                             f"(fastest mode of M⁻¹K, sqrt(λ_max(M⁻¹ K_p)) = "
                             f"{np.sqrt(np.abs(np.linalg.eigvals(Mi @ np.diag(kp[sl]))).max()):.4g}"
                             " 1/s)"))
    return max(cands, key=lambda c: c[0])


def step_too_large(built, state, dt: float, controller=None, threshold: float | None = None
                   ) -> str:
    """A sentence if ``dt`` times the fastest closed-loop rate exceeds ``threshold``.

    Args:
        built: the built scenario.
        state: the state for the joint-space modes.
        dt: the time step [s].
        controller: the run's controller or None.
        threshold: the largest ``dt · rate`` accepted; default the integrator's stability
            limit (:data:`STABILITY_LIMITS`; none for ``rk45``, which adapts its step).

    Returns:
        The sentence, or ``""``.
    """
    integ = built.scenario.simulation.integrator
    limit = STABILITY_LIMITS.get(integ)
    if threshold is None:
        threshold = limit
    if threshold is None:
        return ""
    rate, source = fastest_rate(built, state, controller)
    if dt * rate <= threshold:
        return ""
    beyond = (f", beyond the stability limit {limit:g} of {integ}" if limit is not None
              and dt * rate > limit else ", more than 1 (the step is longer than the time "
              "constant)")
    return (f"dt = {dt:g} s is too large for {source}: their fastest mode has rate "
            f"{rate:.4g} 1/s (time constant {1.0 / rate:.3g} s) and dt · rate = {dt * rate:.3g}"
            f"{beyond}; use a dt well below {1.0 / rate:.3g} s")


def tool_jacobian(arm, q: np.ndarray) -> np.ndarray:
    """An arm's tool Jacobian (6, nv), LOCAL_WORLD_ALIGNED, at ``q``."""
    data = arm.model.createData()
    return pin.computeFrameJacobian(arm.model, data, np.asarray(q, float), arm.tool_frame_id,
                                    pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)


def jacobian_singular_values(arm, q: np.ndarray) -> np.ndarray:
    """Singular values of an arm's tool Jacobian (6 x nv, LOCAL_WORLD_ALIGNED) at ``q``."""
    return np.linalg.svd(tool_jacobian(arm, q), compute_uv=False)


def singular_arms(built, result) -> list[str]:
    """Arms that reached or crossed a singularity during the recorded samples.

    An arm is reported when the smallest singular value of its tool Jacobian falls below
    :data:`SINGULAR_FRACTION` of its value at t = 0, or (square Jacobians) when ``det J``
    changes sign between two successive samples whose configurations differ by less than
    :data:`CONTINUOUS_STEP` (a path through ``det J = 0``).
    """
    system = built.system
    T = len(result.t)
    if not system.n_arms or T == 0:
        return []
    idx = np.unique(np.r_[np.linspace(0, T - 1, min(T, MAX_JACOBIAN_SAMPLES)).astype(int),
                          T - 1])
    idx = idx[np.isfinite(result.q[idx]).all(axis=1)]  # a run ending in NaN: the samples before
    if idx.size == 0:
        return []
    out = []
    for arm, qs in zip(system.arms, system.arm_set.q_slices, strict=True):
        q = result.q[:, qs]
        J = [tool_jacobian(arm, q[k]) for k in idx]
        smin = np.array([np.linalg.svd(j, compute_uv=False).min() for j in J])
        s0 = float(smin[0])
        crossed = ""
        if arm.nv == 6:
            det = np.array([np.linalg.det(j) for j in J])
            step = np.linalg.norm(np.diff(q[idx], axis=0), axis=1)
            flips = np.flatnonzero((np.sign(det[1:]) * np.sign(det[:-1]) < 0)
                                   & (step < CONTINUOUS_STEP))
            if flips.size:
                a, b = idx[flips[0]], idx[flips[0] + 1]
                crossed = (f"it crosses a singularity (det J changes sign) between t = "
                           f"{result.t[a]:.4g} s and {result.t[b]:.4g} s")
        j = int(np.argmin(smin))
        low = smin[j] < SINGULAR_FRACTION * s0
        if not (low or crossed):
            continue
        parts = [f"arm {arm.name!r} is singular: the smallest singular value of its tool "
                 f"Jacobian falls to {smin[j]:.3g} at t = {result.t[idx[j]]:.4g} s "
                 f"({smin[j] / s0:.3g}x its {s0:.3g} at t = 0)"]
        if crossed:
            parts.append(crossed)
        out.append("; ".join(parts))
    return out


def torques_over_limits(built, result) -> list[str]:
    """Joints whose recorded torque exceeded the URDF effort limit: the peak and its time.

    The commanded torque (``tau_commanded``): where the actuators saturate, the applied one
    never exceeds the limit, and the command that asked for more is the cause.
    """
    from multiarm_pin.feasibility.limits import arm_limits

    system = built.system
    if not system.n_arms or len(result.t) == 0:
        return []
    rows = []
    commanded = getattr(result, "tau_commanded", None)
    commanded = result.tau if commanded is None else commanded
    for arm, sl in zip(system.arms, system.arm_set.v_slices, strict=True):
        tau = np.asarray(commanded)[:, sl]
        limits = arm_limits(arm)
        effort, names = limits.effort, list(limits.joints)
        ratio = np.abs(tau) / effort[None, :]
        ratio[~np.isfinite(ratio)] = 0.0
        for c in range(arm.nv):
            k = int(np.argmax(ratio[:, c]))
            if ratio[k, c] > 1.0:
                first = int(np.argmax(ratio[:, c] > 1.0))
                rows.append((ratio[k, c], f"arm {arm.name!r} joint {names[c]!r}: "
                             f"{tau[k, c]:.5g} N m at t = {result.t[k]:.4g} s, "
                             f"{ratio[k, c]:.3g}x its effort limit "
                             f"{effort[c]:g} N m (over it from t = "
                             f"{result.t[first]:.4g} s)"))
    rows.sort(key=lambda r: -r[0])
    if not rows:
        return []
    more = f" (and {len(rows) - 3} more joints)" if len(rows) > 3 else ""
    return ["torques beyond the limits: " + "; ".join(r[1] for r in rows[:3]) + more]


def failure_causes(built, result, dt: float, controller=None) -> list[str]:
    """The likely causes of a failed run, most fundamental first.

    Args:
        built: the built scenario.
        result: the partial :class:`~multiarm_pin.sim.result.SimulationResult` (samples up
            to the failure).
        dt: the run's time step [s].
        controller: the run's controller, or None.

    Returns:
        Sentences naming the arm, the joint and the time (empty: none of the checks found a
        cause).
    """
    out = []
    if len(result.t):
        msg = step_too_large(built, built.initial_state, dt, controller, 1.0)
        if msg:
            out.append(msg)
    out += singular_arms(built, result)
    out += torques_over_limits(built, result)
    return out


def describe_failure(built, result, dt: float, controller=None) -> str:
    """:func:`failure_causes` as one text to append to the error message."""
    try:
        with np.errstate(all="ignore"):
            causes = failure_causes(built, result, dt, controller)
    except (MultiArmError, ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
        return f"; the causes could not be checked ({type(exc).__name__}: {exc})"
    t = f"{result.t[-1]:.4g} s" if len(result.t) else "the start"
    if not causes:
        return (f"; checked up to t = {t}: no arm near a singularity, no torque beyond the "
                "effort limits, dt within the closed-loop rates")
    text = f"; likely cause: {causes[0]}"
    if len(causes) > 1:
        text += " (also found, which may follow from it: " + "; ".join(causes[1:]) + ")"
    return text


def _quaternion_keys(data: dict, index: int) -> list[tuple[str, list]]:
    """``(key path, [a, b, c, d])`` of every quaternion written for arm ``index``'s pose."""
    out = []
    pose = (data.get("object") or {}).get("pose") or {}
    if isinstance(pose, dict) and isinstance(pose.get("quaternion"), list):
        out.append(("object.pose.quaternion", pose["quaternion"]))
    arms = data.get("arms") or []
    arm = arms[index] if index < len(arms) and isinstance(arms[index], dict) else {}
    joint = arm.get("joint") if isinstance(arm.get("joint"), dict) else {}
    for key in ("placement_in_object", "placement_in_tool"):
        p = joint.get(key)
        if isinstance(p, dict) and isinstance(p.get("quaternion"), list):
            out.append((f"arms[{index}].joint.{key}.quaternion", p["quaternion"]))
    for key in ("base", "tool_offset"):
        p = arm.get(key)
        if isinstance(p, dict) and isinstance(p.get("quaternion"), list):
            out.append((f"arms[{index}].{key}.quaternion", p["quaternion"]))
    return out


def _reordered(q) -> np.ndarray:
    """``[a, b, c, d]`` read as ``[w, x, y, z]``, written ``[x, y, z, w]``: ``[b, c, d, a]``."""
    q = np.asarray(q, float)
    q = q / np.linalg.norm(q)
    return np.array([q[1], q[2], q[3], q[0]])


def _placement(q_xyzw: np.ndarray, position) -> pin.SE3:
    from multiarm_pin.spatial import quaternion_to_rotation

    return pin.SE3(quaternion_to_rotation(q_xyzw), np.asarray(position, float))


def w_first_hint(scenario, spec, reachable: Callable[[object, pin.SE3], bool]) -> str:
    """A sentence if an arm's unreachable pose may come from a quaternion written w-first.

    For each quaternion ``[a, b, c, d]`` of the object's pose and of the arm's joint
    placements, the pose is tried again with it read as ``[w, x, y, z]`` (i.e. ``[b, c, d,
    a]`` in the scenario's ``[x, y, z, w]``); if that is reachable, the sentence says so.
    Otherwise a quaternion whose first component is near ±1 and last near 0 (the identity
    written w-first) is pointed out. A quaternion near the identity as written (last
    component above :data:`IDENTITY_LIKE`) is left alone.

    Args:
        scenario: the :class:`~multiarm_pin.app.scenario.Scenario`.
        spec: the arm's :class:`~multiarm_pin.app.scenario.specs.ArmSpec`.
        reachable: ``reachable(spec, object_placement) -> bool``: the arm's inverse
            kinematics for a modified spec or object placement.

    Returns:
        The sentence (starting with ``"; "``), or ``""``.
    """
    hints = []
    oMo = scenario.object.placement
    for key, raw in _quaternion_keys(scenario.data, spec.index):
        try:
            q = np.asarray(raw, float)
        except (TypeError, ValueError):
            continue
        if q.shape != (4,) or not np.isfinite(q).all() or np.linalg.norm(q) == 0:
            continue
        alt = _reordered(q)
        if np.isclose(abs(alt @ (q / np.linalg.norm(q))), 1.0, atol=1e-12):
            continue  # the same rotation either way
        if abs(q[3]) / np.linalg.norm(q) > IDENTITY_LIKE:
            continue  # near the identity as written [x, y, z, w]: most likely meant so
        s, o = spec, oMo
        if key == "object.pose.quaternion":
            o = _placement(alt, oMo.translation)
        elif key.endswith("placement_in_object.quaternion"):
            J = spec.joint.placement_in_object
            s = replace(spec, joint=replace(spec.joint,
                                            placement_in_object=_placement(alt, J.translation)))
        elif key.endswith("placement_in_tool.quaternion"):
            J = spec.joint.placement_in_tool
            s = replace(spec, joint=replace(spec.joint,
                                            placement_in_tool=_placement(alt, J.translation)))
        else:
            s = None  # base and tool offset are baked into the arm's model: not retried
        text = f"[{', '.join(f'{v:g}' for v in np.asarray(raw, float))}]"
        fixed = f"[{', '.join(f'{v:.6g}' for v in alt)}]"
        try:
            ok = s is not None and reachable(s, o)
        except MultiArmError:
            ok = False
        if ok:
            hints.append(f"{key} {text} may be written [w, x, y, z]: quaternions are "
                         f"[x, y, z, w], and reordered so, {fixed}, arm {spec.name!r} "
                         "reaches its pose")
        elif abs(q[0]) / np.linalg.norm(q) > 0.9 and abs(q[3]) / np.linalg.norm(q) < 0.1:
            hints.append(f"{key} {text} looks written [w, x, y, z] (first component near "
                         f"±1, last near 0); quaternions are [x, y, z, w]: did you mean "
                         f"{fixed}?")
    return "".join(f"; {h}" for h in hints)


__all__ = [
    "CONTINUOUS_STEP",
    "IDENTITY_LIKE",
    "MAX_JACOBIAN_SAMPLES",
    "SINGULAR_FRACTION",
    "STABILITY_LIMITS",
    "describe_failure",
    "failure_causes",
    "fastest_rate",
    "jacobian_singular_values",
    "singular_arms",
    "step_too_large",
    "tool_jacobian",
    "torques_over_limits",
    "w_first_hint",
]
