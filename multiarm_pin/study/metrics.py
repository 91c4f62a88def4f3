"""Per-case metrics of a study: from a simulation, or from a grasp analysis.

Simulation metrics (mode ``simulate``), each a float (NaN when it does not apply):

- ``max_constraint_violation`` [m]: max over time of ``max |φ|`` (the run's summary);
- ``min_contact_force`` [N]: least push of a unilateral (fingertip) contact over the run,
  or, without unilateral contacts, the least constraint multiplier;
- ``separations``: number of contact separations: the run's ``separation`` events when the
  simulation records events, otherwise the number of unilateral contacts whose multiplier
  went negative (each would have separated);
- ``tracking_error`` [m] and ``tracking_error_rotation`` [rad]: max over time of the
  object's position error and rotation angle from the ``object_pd`` reference (NaN for
  other controllers);
- ``peak_joint_torque`` [N m]: max over time and joints of ``|τ|``;
- ``torque_limit_ratio``: max over time and joints of ``|τ_j| / τ_max,j`` (the arm model's
  effort limits; NaN when no joint has one);
- ``within_limits``: 1.0 when the run stayed finite, no joint exceeded its effort limit and
  no unilateral contact pulled or separated, else 0.0;
- ``feasible``: 1.0 when the run's feasibility report
  (:func:`multiarm_pin.feasibility.feasibility_report`: joint limits and collisions at every
  recorded sample, as ``summary.json``'s ``feasible``) found no violation, else 0.0;
- ``min_clearance`` [m]: the smallest distance between two bodies that may not touch over
  the run (the least of the report's ``clearance`` categories; negative: a penetration;
  NaN without arms);
- ``torque_limit_ratio[<arm>]``: ``torque_limit_ratio`` of one arm (one metric per arm of
  the base scenario, by its name);
- ``wall_time`` [s]: the simulation's wall time.

Grasp metrics (mode ``grasp``): ``form_closure`` (1.0/0.0), ``margin`` (LP margin ε*),
``epsilon`` (Ferrari-Canny radius), ``rank`` (of the wrench matrix), ``wall_time`` [s].
"""

from __future__ import annotations

import numpy as np

SIMULATION_METRICS = ("max_constraint_violation", "min_contact_force", "separations",
                      "tracking_error", "tracking_error_rotation", "peak_joint_torque",
                      "torque_limit_ratio", "within_limits", "feasible", "min_clearance",
                      "wall_time")
"""Metrics of mode ``simulate`` (besides one ``torque_limit_ratio[<arm>]`` per arm)."""
GRASP_METRICS = ("form_closure", "margin", "epsilon", "rank", "wall_time")
"""Metrics of mode ``grasp``."""
BOOLEAN_METRICS = ("within_limits", "feasible", "form_closure")
"""Metrics that are verdicts (1.0 true, 0.0 false): the report plots their fraction."""


def arm_metric(arm: str) -> str:
    """The name of one arm's peak torque ratio metric: ``torque_limit_ratio[<arm>]``."""
    return f"torque_limit_ratio[{arm}]"


def metric_names(mode: str, arm_names=()) -> tuple[str, ...]:
    """Metric names of a study mode (``simulate`` or ``grasp``).

    Args:
        mode: the study mode.
        arm_names: the base scenario's arms (``simulate``: one ``torque_limit_ratio[<arm>]``
            each, after the others).
    """
    if mode != "simulate":
        return GRASP_METRICS
    return SIMULATION_METRICS + tuple(arm_metric(a) for a in arm_names)


def simulation_metrics(built, result, controller, summary: dict,
                       feasibility=None) -> dict[str, float]:
    """Every simulation metric of one run (see the module docstring).

    Args:
        built: the :class:`~multiarm_pin.app.scenario.BuiltScenario`.
        result: its :class:`~multiarm_pin.sim.simulation.SimulationResult`.
        controller: the controller used (its ``trajectory`` gives the reference), or None.
        summary: the run's ``summary.json`` content (:func:`multiarm_pin.app.runner.summarize`).
        feasibility: the run's :class:`~multiarm_pin.feasibility.FeasibilityReport` (``feasible``,
            ``min_clearance``, the per-arm ratios), or None (those are NaN).

    Returns:
        ``{name: float}`` for every name of :func:`metric_names` with the built arms.
    """
    system = built.system
    uni = np.asarray(system.unilateral, dtype=bool)
    mask = np.asarray(system.constraint_set.mask, dtype=bool)
    mu = np.asarray(result.mu)
    uni_mu = mu[:, uni & mask]
    if uni_mu.size:
        min_force = float(uni_mu.min())
    else:
        real = mu[:, mask]
        min_force = float(real.min()) if real.size else float("nan")
    separations = count_separations(summary, uni_mu)
    pos_err, rot_err = tracking_errors(controller, result)
    tau = np.abs(np.asarray(result.tau))
    peak = float(tau.max()) if tau.size else float("nan")
    ratio = torque_limit_ratio(built, tau)
    finite = bool(summary.get("finite", True))
    ok = (finite and not (np.isfinite(ratio) and ratio > 1.0)
          and separations == 0 and not (uni_mu.size and min_force < 0.0))
    return {
        "max_constraint_violation": float(summary["max_constraint_violation"]),
        "min_contact_force": min_force,
        "separations": float(separations),
        "tracking_error": pos_err,
        "tracking_error_rotation": rot_err,
        "peak_joint_torque": peak,
        "torque_limit_ratio": ratio,
        "within_limits": 1.0 if ok else 0.0,
        "wall_time": float(summary["wall_time"]),
        **feasibility_metrics(built, feasibility),
    }


def feasibility_metrics(built, report) -> dict[str, float]:
    """``feasible``, ``min_clearance`` [m] and ``torque_limit_ratio[<arm>]`` of a report.

    Args:
        built: the built scenario (its arms' names).
        report: a :class:`~multiarm_pin.feasibility.FeasibilityReport`, or None (all NaN).
    """
    arms = [a.name for a in built.arms]
    if report is None:
        return {"feasible": float("nan"), "min_clearance": float("nan"),
                **{arm_metric(a): float("nan") for a in arms}}
    gaps = [float(v) for v in report.clearance.values() if v is not None]
    out = {"feasible": 1.0 if report.feasible else 0.0,
           "min_clearance": min(gaps) if gaps else float("nan")}
    for a in arms:
        ratios = [j["peak_torque_ratio"] for j in report.limits.get(a, {}).values()
                  if j.get("peak_torque_ratio") is not None]
        out[arm_metric(a)] = float(max(ratios)) if ratios else float("nan")
    return out


def count_separations(summary: dict, unilateral_mu: np.ndarray) -> int:
    """Contact separations of a run.

    Args:
        summary: the run's summary; its ``events`` list (``kind: separation``) is used when
            the simulation records events.
        unilateral_mu: (T, U) multipliers [N] of the unilateral contacts (fallback: the
            number of columns that went negative).
    """
    events = summary.get("events")
    if isinstance(events, list):
        return sum(1 for e in events if isinstance(e, dict) and e.get("kind") == "separation")
    if unilateral_mu.size == 0:
        return 0
    return int(np.sum(np.any(unilateral_mu < 0.0, axis=0)))


def tracking_errors(controller, result) -> tuple[float, float]:
    """Max position error [m] and rotation error [rad] of the object from its reference.

    Returns:
        ``(nan, nan)`` when the controller has no object trajectory.
    """
    traj = getattr(controller, "trajectory", None)
    if traj is None:
        return float("nan"), float("nan")
    from multiarm_pin.sim.trajectories import pose_error
    from multiarm_pin.spatial import quaternion_to_rotation

    pos, rot = 0.0, 0.0
    for t, p, q in zip(result.t, result.object_position, result.object_quaternion,
                       strict=True):
        ref = traj(float(t))
        e = pose_error(ref.position, ref.rotation, p, quaternion_to_rotation(q))
        pos = max(pos, float(np.linalg.norm(e[:3])))
        rot = max(rot, float(np.linalg.norm(e[3:])))
    return pos, rot


def torque_limit_ratio(built, abs_tau: np.ndarray) -> float:
    """``max |τ_j| / τ_max,j`` over the run and the joints that have an effort limit.

    Args:
        built: the built scenario (arms' models give ``effortLimit`` [N m]).
        abs_tau: (T, nv) ``|τ|`` [N m] in the arm set's velocity order.
    """
    limits = []
    for arm in built.arms:
        lim = np.asarray(arm.model.effortLimit, dtype=float)[: arm.nv]
        limits.append(lim if lim.size == arm.nv else np.full(arm.nv, np.nan))
    lim = np.concatenate(limits) if limits else np.zeros(0)
    if abs_tau.size == 0 or lim.size != abs_tau.shape[1]:
        return float("nan")
    ok = np.isfinite(lim) & (lim > 0)
    if not np.any(ok):
        return float("nan")
    return float(np.max(abs_tau[:, ok].max(axis=0) / lim[ok]))


def grasp_metrics(grasp, length_scale: float = 1.0) -> dict[str, float]:
    """Form closure, LP margin, Ferrari-Canny ε and rank of a grasp.

    Args:
        grasp: a :class:`~multiarm_pin.grasp.contacts.Grasp`.
        length_scale: ``L`` [m] dividing the moments.
    """
    from multiarm_pin.grasp.form_closure import form_closure

    fc = form_closure(grasp, length_scale=length_scale, allow_fewer=True)
    return {"form_closure": 1.0 if fc.form_closure else 0.0, "margin": fc.margin,
            "epsilon": fc.ferrari_canny, "rank": float(fc.rank)}


__all__ = [
    "BOOLEAN_METRICS",
    "arm_metric",
    "feasibility_metrics",
    "GRASP_METRICS",
    "SIMULATION_METRICS",
    "count_separations",
    "grasp_metrics",
    "metric_names",
    "simulation_metrics",
    "torque_limit_ratio",
    "tracking_errors",
]
