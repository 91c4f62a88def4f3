"""A scenario run's feasibility: its initial collisions, its ``stop`` monitors, its report.

:func:`check_initial_state` refuses a scenario whose initial state has two bodies in
collision (a :class:`~multiarm_pin.exceptions.ScenarioError`: bad input, exit 2).
:func:`run_monitors` gives the simulation the monitors of the kinds whose ``limits:`` policy
is ``stop`` (:mod:`multiarm_pin.feasibility.monitors`): the run ends while it runs, at the
first violation (:class:`~multiarm_pin.exceptions.RunStoppedError`; exit 1, the samples up to
and including it kept). :func:`apply_policies` computes the run's
:class:`~multiarm_pin.feasibility.FeasibilityReport` and the error naming the violation that
stopped it.
"""

from __future__ import annotations

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


def run_monitors(built, scene) -> tuple:
    """The monitors of the scenario's ``stop`` policies, and its collision scan.

    The collision scan runs while the run runs whatever the policy (on a worker thread,
    beside the simulation: :func:`~multiarm_pin.sim.simulation.simulate`'s ``monitors``);
    the report reuses it.
    """
    from multiarm_pin.feasibility.monitors import feasibility_monitors

    return feasibility_monitors(built.system, built.scenario.limits.stops(), scene)


def apply_policies(built, result, scene, status: str, error: str | None,
                   stopped: str | None = None, monitors=()):
    """The run's feasibility report, and the error of a run its ``stop`` policies ended.

    Args:
        built: the built scenario.
        result: the run's (possibly partial) result.
        scene: its collision scene (None: no arms).
        status: ``"complete"``, ``"failed"`` or ``"interrupted"``.
        error: the run's error so far.
        stopped: the message of the :class:`~multiarm_pin.exceptions.RunStoppedError` that
            ended the run, if one did.
        monitors: the run's monitors (:func:`run_monitors`): a collision monitor's scan of
            a whole run is reused.

    Returns:
        ``(status, error, report)``: a stopped run is failed, its error naming the first
        violation of a ``stop`` kind (the sample it ended on). An interrupted run is checked
        against the limits only (its results are written at once).
    """
    from multiarm_pin.feasibility import feasibility_report

    sc = built.scenario
    if status == "interrupted":  # write what was simulated at once: the limits only
        return status, error, feasibility_report(built.system, result, ground=sc.ground,
                                                 collisions=False)
    scans = [m.scan for m in monitors if getattr(m, "scan", None) is not None]
    report = feasibility_report(built.system, result, ground=sc.ground, scene=scene,
                                scan=scans[0] if scans else None)
    if stopped is not None:
        first = report.first(sc.limits.stops())
        what = (f"limits.{first.kind}: stop: {first.describe()}" if first is not None
                else stopped)
        status, error = "failed", f"{sc.file}: {what}"
    return status, error, report


__all__ = ["apply_policies", "check_initial_state", "run_monitors"]
