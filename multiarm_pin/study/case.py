"""Running one case of a study: the function each Dask task (or a plain loop) calls.

:func:`run_case` never raises for a failing case (unreachable inverse kinematics, singular
system, invalid overridden value, separated grasp ...): it returns a row with
``status = "error"`` and the error message, so a failure is one row of the table, never
the end of the study. It writes nothing: the driver writes the row and the summary, so the
same function runs on a remote cluster whose workers do not share the driver's disk.
"""

from __future__ import annotations

import os
import socket
import time
import traceback
import uuid
from dataclasses import dataclass

import numpy as np

from multiarm_pin.exceptions import MultiArmError


@dataclass(frozen=True)
class CaseTask:
    """Everything a worker needs to run one case (picklable, small).

    Attributes:
        case_id: ``case_00042``. key: the case's hash (see :class:`~.spec.Case`).
        index: position in the study. params: the case's parameter values (table columns).
        mode: ``simulate`` or ``grasp``. base_file: absolute path of the base file (relative
        URDF paths resolve from its folder). base_data: the parsed base file.
        overrides: ``{key path: value}``. metrics: names of the metrics to record.
    """

    case_id: str
    key: str
    index: int
    params: dict
    mode: str
    base_file: str
    base_data: dict
    overrides: dict
    metrics: tuple[str, ...]


def run_case(task: CaseTask) -> dict:
    """Run one case and return its result.

    Returns:
        ``{"row": {...}, "summary": {...}}``: the row has ``case_id``, ``key``, ``index``,
        the parameters, every requested metric (NaN on failure), ``status`` (``ok`` or
        ``error``), ``error`` (message or empty), ``worker`` (host:pid) and ``run_token`` (a
        fresh random id per execution: a re-run case gets a new one). The summary is the
        run's ``summary.json`` content (simulate) or the grasp report (grasp), plus the
        overrides.
    """
    t0 = time.perf_counter()
    summary: dict = {"case_id": task.case_id, "overrides": task.overrides,
                     "params": task.params}
    try:
        if task.mode == "grasp":
            values, extra = _grasp_case(task)
        else:
            values, extra = _simulation_case(task)
        summary.update(extra)
        status, error = "ok", ""
    except _StoppedCaseError as exc:
        summary.update(exc.extra)
        values, status, error = exc.values, "error", f"RunStoppedError: {exc}"
    except MultiArmError as exc:
        values, status, error = {}, "error", f"{type(exc).__name__}: {exc}"
    except Exception as exc:  # noqa: BLE001 - a case's bug is its row, not the study's end
        values, status = {}, "error"
        error = f"{type(exc).__name__}: {exc} (unexpected; " \
                f"{traceback.format_exc(limit=-3).strip().splitlines()[-3:]})"
    wall = time.perf_counter() - t0
    row: dict = {"case_id": task.case_id, "key": task.key, "index": task.index}
    row.update(task.params)
    for m in task.metrics:
        row[m] = float(values.get(m, np.nan))
    if "wall_time" in task.metrics and status != "ok":
        row["wall_time"] = wall
    row.update(status=status, error=error, case_wall_time=wall,
               worker=f"{socket.gethostname()}:{os.getpid()}", run_token=uuid.uuid4().hex)
    summary.update(status=status, error=error, case_wall_time=wall)
    return {"row": row, "summary": summary}


def _simulation_case(task: CaseTask) -> tuple[dict, dict]:
    """Build and simulate the overridden scenario as ``multiarm-pin run`` does, no files.

    The scenario's feasibility is applied as the run applies it
    (:mod:`multiarm_pin.app.run_feasibility`): bodies colliding at the initial state are
    bad input, the collision scan runs beside the simulation, and a ``stop`` policy ends the
    run at its first violation: :class:`_StoppedCaseError` then carries the metrics of the
    samples up to and including the violation.
    """
    from multiarm_pin.app.precheck import precheck_warnings
    from multiarm_pin.app.run_feasibility import apply_policies, check_initial_state, run_monitors
    from multiarm_pin.app.runner import (
        input_warnings,
        scenario_controller,
        simulate_built,
        summarize,
    )
    from multiarm_pin.app.scenario import build_scenario, parse_scenario
    from multiarm_pin.exceptions import RunStoppedError, ScenarioError
    from multiarm_pin.sim.simulation import partial_result
    from multiarm_pin.study.metrics import simulation_metrics
    from multiarm_pin.study.spec import apply_overrides

    data = apply_overrides(task.base_data, task.overrides)
    sc = parse_scenario(data, task.base_file)
    sim = sc.simulation
    if sim.duration < sim.dt:
        raise ScenarioError(sc.file, "simulation.duration", f"{sim.duration:g} s is shorter "
                            f"than the time step simulation.dt = {sim.dt:g} s")
    built = build_scenario(sc, load_visuals=False)
    controller = scenario_controller(built)
    scene = check_initial_state(built)
    warnings = input_warnings(built, sim.duration) + precheck_warnings(built, sim.dt)
    monitors = run_monitors(built, scene)
    status, stopped = "complete", None
    t0 = time.perf_counter()
    try:
        result = simulate_built(built, controller, sim.duration, sim.dt, sim.solver,
                                monitors=monitors)
    except RunStoppedError as exc:
        result, status, stopped = partial_result(exc), "failed", str(exc)
    wall = time.perf_counter() - t0
    status, error, report = apply_policies(built, result, scene, status, None, stopped,
                                           monitors)
    summary = summarize(built, result, sim.solver, wall)
    summary.update(input_warnings=list(warnings), status=status, error=error,
                   t_end=float(result.t[-1]))
    summary.update(report.as_summary())
    values = simulation_metrics(built, result, controller, summary, report)
    extra = {"run": summary, "metrics": values}
    if status != "complete":
        raise _StoppedCaseError(error, values, extra)
    return values, extra


class _StoppedCaseError(MultiArmError):
    """A case that a ``limits:`` ``stop`` policy ended.

    Its row is an error row that keeps the metrics of the samples simulated up to and
    including the violation (its ``feasible`` is 0).
    """

    def __init__(self, message: str, values: dict, extra: dict):
        super().__init__(message)
        self.values, self.extra = values, extra


def _grasp_case(task: CaseTask) -> tuple[dict, dict]:
    from multiarm_pin.study.metrics import grasp_metrics
    from multiarm_pin.study.spec import apply_overrides

    t0 = time.perf_counter()
    data = apply_overrides(task.base_data, task.overrides)
    grasp, length_scale = grasp_of(data, task.base_file)
    values = grasp_metrics(grasp, length_scale)
    values["wall_time"] = time.perf_counter() - t0
    points = [c.point.tolist() for c in grasp.contacts]
    return values, {"grasp": {"points": points, "length_scale": length_scale},
                    "metrics": values}


def grasp_of(data: dict, file: str):
    """The grasp of a grasp file's data, or of a scenario's fingertip contacts.

    The same reading as ``multiarm-pin grasp`` (:mod:`multiarm_pin.app.grasp_input`).

    Returns:
        ``(grasp, length_scale [m])``.

    Raises:
        ScenarioError: invalid data, a contact point off its face (names the key path), or
            a scenario with no fingertip contacts.
    """
    from multiarm_pin.app.grasp_input import grasp_input_from_data

    gf = grasp_input_from_data(data, file).grasp_file
    return gf.grasp, gf.length_scale


__all__ = ["CaseTask", "grasp_of", "run_case"]
