"""A scenario run's feasibility: its initial collisions, its report, its ``limits:`` policies.

The collision check of the initial state, the report of the recorded samples, and the
``stop`` policies (a run ends at the first violation of a kind set to ``stop``).

:func:`check_initial_state` refuses a scenario whose initial state has two bodies in
collision (a :class:`~multiarm_pin.exceptions.ScenarioError`: bad input, exit 2).
:func:`apply_policies` computes the run's
:class:`~multiarm_pin.feasibility.FeasibilityReport` and, when a kind whose policy is
``stop`` was violated, cuts the record just after the first such violation and makes the run
failed (exit 1, the partial results kept). ``stop`` is decided on the recorded samples once
the simulation has returned: the samples after the violation are simulated, then dropped.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from multiarm_pin.exceptions import ScenarioError


def check_initial_state(built):
    """The built scenario's :class:`~multiarm_pin.feasibility.CollisionScene`, checked at t = 0.

    Raises:
        ScenarioError: bodies in collision at the initial state (names both and the depth).
    """
    from multiarm_pin.feasibility import CollisionScene, check_design

    sc = built.scenario
    if not built.system.n_arms:
        return None
    scene = CollisionScene(built.system, built.initial_state, sc.ground)
    report = check_design(built.system, built.initial_state, scene=scene)
    hits = [v for v in report.violations if v.kind == "collision"]
    if hits:
        what = "; ".join(f"{v.arm}/{v.link} and {v.other} interpenetrate by "
                         f"{-v.value * 1e3:.3g} mm" for v in hits[:5])
        more = f" (and {len(hits) - 5} more pairs)" if len(hits) > 5 else ""
        raise ScenarioError(sc.file, "arms", f"bodies collide at the initial state: {what}"
                            f"{more}; move the arm's base, its q0/q_seed or the object")
    return scene


def truncated(result, n: int):
    """The first ``n`` samples of a :class:`~multiarm_pin.sim.result.SimulationResult`."""
    T = len(result.t)
    changes = {}
    for f in dataclasses.fields(result):
        value = getattr(result, f.name)
        if isinstance(value, np.ndarray) and value.ndim and len(value) == T and \
                f.name != "unilateral":
            changes[f.name] = value[:n]
    t_end = float(result.t[n - 1])
    changes["events"] = [e for e in result.events if e.t <= t_end]
    return dataclasses.replace(result, **changes)


def apply_policies(built, result, scene, status: str, error: str | None):
    """The run's feasibility report, with the ``stop`` policies applied.

    Returns:
        ``(result, status, error, report)``: when a ``stop`` kind was violated, the record up
        to and including the sample of its first violation, status ``"failed"`` and the
        error naming it (unless the run had already failed earlier). An interrupted run
        is checked against the limits only (its results are written at once).
    """
    from multiarm_pin.feasibility import feasibility_report

    sc = built.scenario
    if status == "interrupted":  # write what was simulated at once: the limits only
        return result, status, error, feasibility_report(built.system, result,
                                                         ground=sc.ground, collisions=False)
    report = feasibility_report(built.system, result, ground=sc.ground, scene=scene)
    first = report.first(sc.limits.stops())
    if first is not None and (status == "complete" or first.t_first < float(result.t[-1])):
        n = int(np.searchsorted(result.t, first.t_first, side="right"))
        if n < len(result.t) or status == "complete":
            result = truncated(result, max(n, 1))
            report = feasibility_report(built.system, result, ground=sc.ground, scene=scene)
            status = "failed"
            error = (f"{sc.file}: limits.{first.kind}: stop: {first.describe()}")
    return result, status, error, report


__all__ = ["apply_policies", "check_initial_state", "truncated"]
