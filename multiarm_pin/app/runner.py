"""Running a scenario: build it, simulate it, write its results atomically, serve a replay.

:func:`run_scenario` is ``multiarm-pin run`` without the command line (:mod:`multiarm_pin.app.cli`):
it checks the output folder, builds the scenario, simulates it with a progress bar
(:mod:`multiarm_pin.app.progress`) and writes the files described in
:mod:`multiarm_pin.app.run_results` through :mod:`multiarm_pin.app.results_io`, keeping the
partial results of a failed or interrupted run. :func:`serve_run` replays a results folder.
"""

from __future__ import annotations

import contextlib
import json
import signal
import sys
import threading
import time
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from multiarm_pin.app.progress import ProgressBar
from multiarm_pin.app.results_io import (
    ResultsWriter,
    deferred_signals,
    prepare_output,
    safe_component,
)
from multiarm_pin.app.run_feasibility import apply_policies, check_initial_state
from multiarm_pin.app.run_results import (
    REPLAY_FPS,
    load_run,
    replay_parts,
    scenario_copy,
    summarize,
    trajectory_arrays,
)
from multiarm_pin.app.scenario import (
    BuiltScenario,
    Scenario,
    build_arm,
    build_object,
    build_scenario,
    load_scenario,
)
from multiarm_pin.app.scenario_checks import input_warnings
from multiarm_pin.exceptions import (
    MultiArmError,
    OutputError,
    RunFailedError,
    RunInterrupted,
    ScenarioError,
)


# ----------------------------------------------------------------------------- running
@dataclass
class RunOutput:
    """What :func:`run_scenario` produced.

    Attributes:
        out_dir: the results folder.
        built: the built scenario (system, initial state...).
        result: the :class:`~multiarm_pin.sim.simulation.SimulationResult`.
        trajectory: the arrays written to ``trajectory.npz``.
        summary: the content of ``summary.json``.
        files: every file written, by role (``trajectory``, ``summary``, ``replay``...).
    """

    out_dir: Path
    built: BuiltScenario
    result: object
    trajectory: dict
    summary: dict
    files: dict = field(default_factory=dict)


def make_controller(built: BuiltScenario):
    """The scenario's controller, built by ``multiarm_pin.sim.controllers.make_controller``.

    Returns:
        A callable ``controller(t, state, evaluation) -> tau`` or None (``type: none``).

    Raises:
        ScenarioError: unknown or bad controller parameters (key ``controller``).
    """
    spec = built.scenario.controller
    if not built.system.n_arms:
        if spec.type != "none":
            raise ScenarioError(built.scenario.file, "controller.type",
                                f"the scenario has no arms, so no controller {spec.type!r}; "
                                "expected 'none' (or no controller key)")
        return None
    from multiarm_pin.sim.controllers import make_controller as factory

    try:
        return factory(spec.type, built.system, **spec.params)
    except MultiArmError as exc:  # bad parameters (the message lists the accepted ones)
        raise ScenarioError(built.scenario.file, "controller", str(exc)) from exc


class _Terminated(KeyboardInterrupt):  # noqa: N818 (an interrupt, not an error)
    """Raised in the main thread by SIGTERM during a run (handled like Ctrl-C)."""

    signal_name = "SIGTERM"


@contextlib.contextmanager
def _sigterm_interrupts():
    """SIGTERM raises :class:`_Terminated` inside the block (main thread only)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        raise _Terminated("terminated by SIGTERM")

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_DFL if previous is None else previous)


def _say(message: str, quiet: bool) -> None:
    if not quiet:
        print(message, file=sys.stderr, flush=True)


def run_scenario(scenario, out=None, solver: str | None = None, duration: float | None = None,
                 quiet: bool = True, html: bool = True, plots: bool = True,
                 overwrite: bool = False) -> RunOutput:
    """Simulate a scenario and write its results, atomically (:mod:`multiarm_pin.app.results_io`).

    The output folder is checked before anything is simulated. If the simulation fails
    (a :class:`~multiarm_pin.exceptions.MultiArmError` once it has started) or is interrupted
    (Ctrl-C / SIGINT, SIGTERM), the samples simulated so far are written with
    ``summary.json`` ``"status"`` ``"failed"`` or ``"interrupted"``, ``"error"`` and
    ``"t_end"``, and :class:`~multiarm_pin.exceptions.RunFailedError` or
    :class:`~multiarm_pin.exceptions.RunInterrupted` is raised (``out_dir`` says where).

    Args:
        scenario: a path to a YAML file, or a :class:`Scenario`.
        out: results folder (default ``results/<scenario name>``, the name made into one safe
            path component).
        solver: overrides ``simulation.solver``.
        duration: overrides ``simulation.duration`` [s] (not shorter than ``simulation.dt``).
        quiet: no progress bar and no messages on stderr (warnings are still printed).
        html: write ``replay.html`` (built in this process, about a second for two UR5s).
        plots: write the PNG plots.
        overwrite: replace a folder holding the results of another scenario file.

    Returns:
        :class:`RunOutput` of a complete run.

    Raises:
        ScenarioError: invalid scenario or overrides (before anything is simulated).
        OutputError: unusable output folder (before anything is simulated).
        RunFailedError: the simulation failed after it started (partial results written).
        RunInterrupted: Ctrl-C or SIGTERM (partial results written when there were any).
    """
    from multiarm_pin.sim.simulation import default_record_limit, partial_result, record_bytes

    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    sim = sc.simulation
    if solver is not None:
        from multiarm_pin.app.scenario import SOLVER_NAMES, did_you_mean

        if solver not in SOLVER_NAMES:
            raise ScenarioError(sc.file, "--solver", f"unknown solver {solver!r}"
                                f"{did_you_mean(solver, SOLVER_NAMES)}; expected one of "
                                f"{', '.join(SOLVER_NAMES)}")
    if duration is not None:
        if not (np.isfinite(duration) and duration > 0):
            raise ScenarioError(sc.file, "--duration", f"expected a positive duration [s], got "
                                f"{duration}")
        if duration < sim.dt:
            raise ScenarioError(sc.file, "--duration", f"{duration:g} s is shorter than the "
                                f"time step simulation.dt = {sim.dt:g} s")
    solver = solver or sim.solver
    T = float(duration) if duration is not None else sim.duration
    dt = sim.dt
    target = prepare_output(out if out is not None else Path("results") / safe_component(sc.name),
                            sc.file, overwrite)
    with ResultsWriter(target, sc.file) as writer, _sigterm_interrupts():
        built = build_scenario(sc, load_visuals=html)
        controller = make_controller(built)
        n_samples = int(np.floor(T / dt + 1e-9)) + 1
        need, limit = record_bytes(built.system, n_samples), default_record_limit()
        if need > limit:
            key = "--duration" if duration is not None else "simulation.duration"
            raise ScenarioError(sc.file, key, f"{T:g} s at dt = {dt:g} s is {n_samples} samples "
                                f"needing ~{need / 2**30:.3g} GiB of memory (limit "
                                f"{limit / 2**30:.3g} GiB, half the machine's memory); shorten "
                                "the duration or lengthen simulation.dt")
        scene = check_initial_state(built)  # bodies colliding at t = 0: bad input
        input_warns = input_warnings(built, T)
        for w in input_warns:
            print(f"warning: {w}", file=sys.stderr, flush=True)
        bar = None if quiet else ProgressBar(f"{safe_component(sc.name)}", T)
        t0 = time.perf_counter()
        status, error, internal = "complete", None, None
        try:
            result = simulate_built(built, controller, T, dt, solver, bar)
        except KeyboardInterrupt as exc:
            result, status = partial_result(exc), "interrupted"
            error = f"interrupted by {getattr(exc, 'signal_name', 'SIGINT')}"
            signal_name = getattr(exc, "signal_name", "SIGINT")
            if result is None or len(result.t) == 0:
                raise RunInterrupted(f"{sc.file}: {error} before the first sample; nothing "
                                     "written", None, None, signal_name) from None
        except MultiArmError as exc:
            result = partial_result(exc)
            if result is None:  # refused before integrating: an input error
                raise ScenarioError(sc.file, "", str(exc)) from exc
            status = "failed"
            error = f"{sc.file}: simulation failed: {exc}"
            if len(result.t) == 0:  # the set-up cannot even start: an input error
                key = "controller" if "controller" in str(exc) else ""
                raise ScenarioError(sc.file, key, f"the simulation cannot start: {exc}") from exc
        except Exception as exc:  # a bug: keep what was simulated, then let it surface
            result, internal = partial_result(exc), exc
            if result is None or len(result.t) == 0:
                raise
            status = "failed"
            error = f"{sc.file}: internal error (a bug): {type(exc).__name__}: {exc}"
        finally:
            if bar is not None:
                bar.close()
        wall = time.perf_counter() - t0
        result, status, error, feasibility = apply_policies(built, result, scene, status, error)
        t_end = float(result.t[-1])
        try:
            _say(f"writing results to {target}", quiet)
            files, traj, summary = _write_results(writer.path, built, result, solver, wall,
                                                  T, sc, html, plots, status, error,
                                                  input_warns, feasibility.as_summary())
            writer.publish()
        except KeyboardInterrupt as exc:
            name = getattr(exc, "signal_name", "SIGINT")
            if writer.published:  # the signal was held back during the swap: all written
                raise RunInterrupted(f"interrupted by {name} just after the results were "
                                     f"written to {target} (status {status})", t_end, target,
                                     name) from None
            raise RunInterrupted(f"interrupted by {name} while writing the results; {target} "
                                 "left as it was", t_end, None, name) from None
        except OSError as exc:
            raise OutputError(f"--out {target}: cannot write the results: "
                              f"{exc.strerror or exc}") from exc
    files = {k: target / p.name for k, p in files.items()}
    if internal is not None:
        _say(f"partial results (status failed, t_end = {t_end:.6g} s) in {target}", False)
        raise internal
    if status == "interrupted":
        raise RunInterrupted(f"{sc.file}: {error} at t = {t_end:.6g} s of {T:g} s; partial "
                             f"results in {target}", t_end, target, signal_name)
    if status == "failed":
        raise RunFailedError(f"{error}; partial results (t = 0 .. {t_end:.6g} s) in {target}",
                             t_end, target, error)
    return RunOutput(target, built, result, traj, summary, files)


def simulate_built(built: BuiltScenario, controller, duration: float, dt: float, solver: str,
                   progress=None):
    """Simulate a built scenario with its simulation settings (integrator, Baumgarte).

    Args:
        built: the built scenario.
        controller: its controller (:func:`make_controller`) or None.
        duration: simulated time [s].
        dt: time step [s].
        solver: forward-dynamics solver name.
        progress: optional ``callable(fraction)``.

    Returns:
        The :class:`~multiarm_pin.sim.simulation.SimulationResult`.
    """
    from multiarm_pin.sim.simulation import simulate

    sim = built.scenario.simulation
    with np.errstate(over="ignore", invalid="ignore"):  # NaN/inf are caught and reported
        return simulate(built.system, built.initial_state, controller, duration, dt,
                        integrator=sim.integrator, solver=solver, baumgarte=sim.baumgarte,
                        progress=progress,
                        external_wrench=built.scenario.object.external_wrench or None)


def _write_results(folder: Path, built: BuiltScenario, result, solver: str, wall: float,
                   T: float, sc: Scenario, html: bool, plots: bool, status: str,
                   error: str | None, input_warns: list[str],
                   feasibility: dict | None = None) -> tuple[dict, dict, dict]:
    """Write every result file into ``folder``; returns (files by role, arrays, summary)."""
    traj = trajectory_arrays(built, result)
    files = {}
    files["trajectory"] = folder / "trajectory.npz"
    # a signal inside savez would leave its ZipFile half-closed, whose destructor then prints
    # a traceback at exit: deliver it right after (the temporary folder is dropped whole)
    with deferred_signals():
        np.savez_compressed(files["trajectory"], **traj)
    summary = summarize(built, result, solver, wall)
    summary["input_warnings"] = list(input_warns)
    summary["requested"]["duration"] = T
    summary.update(status=status, error=error, t_end=float(result.t[-1]))
    summary.update(feasibility or {})
    files["scenario"] = folder / "scenario.yaml"
    files["scenario"].write_text(scenario_copy(sc, T, solver), encoding="utf-8")
    if plots:
        from multiarm_pin.app.plots import write_plots

        for p in write_plots(folder, traj, [a.name for a in built.arms], sc.name,
                             [sp.name for sp in built.system.supports.supports]):
            files[p.stem] = p
    if html:
        from multiarm_pin.app.replay import write_replay_html

        rarms, robj, rc = replay_parts(built.arms, built.obj, traj)
        files["replay"] = write_replay_html(folder / "replay.html", rarms, robj, traj["t"],
                                            rc, fps=REPLAY_FPS)
    files["summary"] = folder / "summary.json"
    summary["files"] = {k: p.name for k, p in files.items()}
    files["summary"].write_text(json.dumps(summary, indent=2), encoding="utf-8")
    return files, traj, summary


def serve_run(run_dir, fps: float = REPLAY_FPS, open_browser: bool = False):
    """Serve a finished run from a Meshcat server (arms with their meshes, object, contacts).

    Args:
        run_dir: a folder written by :func:`run_scenario`.
        fps: frames per second of the replay.
        open_browser: open the page in the default browser.

    Returns:
        ``(url, vis)``; stop with :func:`multiarm_pin.app.replay.close_visualizer` ``(vis)``.
    """
    from multiarm_pin.app.replay import serve_replay

    sc, traj, _ = load_run(run_dir)
    arms = [build_arm(sc, spec, load_visuals=True) for spec in sc.arms]
    obj = build_object(sc)
    rarms, robj, rc = replay_parts(arms, obj, traj)
    return serve_replay(rarms, robj, traj["t"], rc, fps=fps, open_browser=open_browser)


def http_status(url: str, timeout: float = 10.0) -> int:
    """HTTP status code of a GET on ``url`` (used to check the replay server answers)."""
    with urllib.request.urlopen(url, timeout=timeout) as resp:  # noqa: S310 (localhost)
        return int(resp.status)


__all__ = [
    "ProgressBar",
    "RunOutput",
    "http_status",
    "input_warnings",
    "load_run",
    "make_controller",
    "run_scenario",
    "serve_run",
    "simulate_built",
    "summarize",
]
