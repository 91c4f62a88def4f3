"""Running a scenario: build it, simulate it, write its results atomically, serve a replay.

:func:`run_scenario` is ``multiarm-pin run`` without the command line (:mod:`multiarm_pin.app.cli`):
it checks the output folder, builds the scenario, simulates it with a progress bar
(:mod:`multiarm_pin.app.progress`) and writes the files described in
:mod:`multiarm_pin.app.run_results` through :mod:`multiarm_pin.app.results_io`, keeping the
partial results of a failed or interrupted run. :func:`serve_run` replays a results folder.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import sys
import tempfile
import threading
import time
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from multiarm_pin.app.diagnosis import describe_failure
from multiarm_pin.app.precheck import precheck_warnings
from multiarm_pin.app.progress import ProgressBar
from multiarm_pin.app.replay_phases import phases_summary, replay_phases
from multiarm_pin.app.results_io import ResultsWriter, safe_component, write_atomic
from multiarm_pin.app.run_feasibility import apply_policies, check_initial_state, run_monitors
from multiarm_pin.app.run_results import (
    REPLAY_FPS,
    load_run,
    plot_names,
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
    RunStoppedError,
    ScenarioError,
    UnsupportedSolverError,
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


def scenario_controller(built: BuiltScenario):
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
    from multiarm_pin.sim.controllers import make_controller

    try:
        return make_controller(spec.type, built.system, **spec.params)
    except MultiArmError as exc:  # bad parameters (the message lists the accepted ones)
        raise ScenarioError(built.scenario.file, "controller", str(exc)) from exc


class _Terminated(KeyboardInterrupt):  # noqa: N818 (an interrupt, not an error)
    """Raised in the main thread by SIGTERM during a run (handled like Ctrl-C)."""

    signal_name = "SIGTERM"


class _RunSignals:
    """SIGINT and SIGTERM during a run: the first one interrupts, later ones wait their turn.

    While *armed*, a signal raises ``KeyboardInterrupt`` (SIGINT) or :class:`_Terminated`
    (SIGTERM) in the main thread and disarms: the signals that follow are held, so the code
    handling the interrupt (writing the trajectory and summary) is never cut short by a
    second Ctrl-C. :meth:`arm` raises the first held one at once, or arms again.
    Installed in the main thread only (elsewhere signals cannot be handled: it does nothing).
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self):
        self.armed = True
        self.held: list[int] = []
        self._previous: dict | None = None

    def __enter__(self) -> _RunSignals:
        if threading.current_thread() is threading.main_thread():
            self._previous = {s: signal.signal(s, self._handler) for s in self.SIGNALS}
        return self

    def __exit__(self, *exc) -> None:
        if self._previous is not None:
            for s, h in self._previous.items():
                signal.signal(s, signal.SIG_DFL if h is None else h)
            self._previous = None

    @staticmethod
    def _raise(signum: int):
        if signum == signal.SIGTERM:
            raise _Terminated("terminated by SIGTERM")
        raise KeyboardInterrupt

    def _handler(self, signum, frame) -> None:
        if self.armed:
            self.armed = False
            self._raise(signum)
        self.held.append(signum)

    def hold(self) -> None:
        """Hold the signals that come from now on (:meth:`arm` raises them)."""
        self.armed = False

    def arm(self) -> None:
        """Raise the first held signal now (the others are dropped), or arm."""
        if self.held:
            signum = self.held[0]
            self.held.clear()
            self._raise(signum)
        self.armed = True

    def take_held(self) -> str | None:
        """The name of the first held signal (None if none), and forget them."""
        name = signal.Signals(self.held[0]).name if self.held else None
        self.held.clear()
        return name


def _say(message: str, quiet: bool) -> None:
    if not quiet:
        print(message, file=sys.stderr, flush=True)


def run_scenario(scenario, out=None, solver: str | None = None, duration: float | None = None,
                 quiet: bool = True, html: bool = True, plots: bool = True,
                 overwrite: bool = False) -> RunOutput:
    """Simulate a scenario and write its results, atomically (:mod:`multiarm_pin.app.results_io`).

    The output folder is locked (one run at a time per folder) and checked before anything
    is simulated; the trajectory and summary are written first, then the plots and page
    (see :func:`_write_results`: a signal while writing keeps what was written). If the
    simulation fails
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
        OutputError: unusable output folder, or another run writing into it (before
            anything is simulated); :class:`~multiarm_pin.exceptions.ResultsNotMovedError`
            after the simulation if the results could not be moved into it (``kept`` says
            where they are).
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
    solver_key = "simulation.solver" if solver is None else "--solver"
    solver = solver or sim.solver
    T = float(duration) if duration is not None else sim.duration
    dt = sim.dt
    writer = ResultsWriter(out if out is not None else Path("results") / safe_component(sc.name),
                           sc.file, overwrite)
    with writer, _RunSignals() as signals:
        target = writer.target
        if writer.in_place:
            _say(f"note: {target} is a mount point (or its parent cannot be written): the "
                 "results are moved into it one file at a time (each file atomically), not "
                 "as a whole folder", quiet)
        built = build_scenario(sc, load_visuals=html)
        controller = scenario_controller(built)
        n_samples = int(np.floor(T / dt + 1e-9)) + 1
        need, limit = record_bytes(built.system, n_samples), default_record_limit()
        if need > limit:
            key = "--duration" if duration is not None else "simulation.duration"
            raise ScenarioError(sc.file, key, f"{T:g} s at dt = {dt:g} s is {n_samples} samples "
                                f"needing ~{need / 2**30:.3g} GiB of memory (limit "
                                f"{limit / 2**30:.3g} GiB, half the machine's memory); shorten "
                                "the duration or lengthen simulation.dt")
        scene = check_initial_state(built)  # bodies colliding at t = 0: bad input
        input_warns = input_warnings(built, T) + precheck_warnings(built, dt)
        for w in input_warns:
            print(f"warning: {w}", file=sys.stderr, flush=True)
        bar = None if quiet else ProgressBar(f"{safe_component(sc.name)}", T)
        t0 = time.perf_counter()
        status, error, internal, signal_name = "complete", None, None, None
        result, stopped = None, None
        monitors = run_monitors(built, scene)
        try:
            result = simulate_built(built, controller, T, dt, solver, bar, monitors=monitors)
            signals.hold()
        except KeyboardInterrupt as exc:  # the signal handler holds the signals that follow
            if result is not None:  # just after the simulation ended: an interrupt of the write
                signals.held.append(signal.SIGTERM if isinstance(exc, _Terminated)
                                    else signal.SIGINT)
            else:
                result, status = partial_result(exc), "interrupted"
                signal_name = getattr(exc, "signal_name", "SIGINT")
                error = f"interrupted by {signal_name}"
                if result is None or len(result.t) == 0:
                    raise RunInterrupted(f"{sc.file}: {error} before the first sample; "
                                         "nothing written", None, None, signal_name) from None
        except RunStoppedError as exc:  # a stop policy: its violation is named below
            signals.hold()
            result, status, stopped = partial_result(exc), "failed", str(exc)
        except MultiArmError as exc:
            signals.hold()
            result = partial_result(exc)
            if result is None:  # refused before integrating: an input error
                key = solver_key if isinstance(exc, UnsupportedSolverError) else ""
                raise ScenarioError(sc.file, key, str(exc)) from exc
            status = "failed"
            error = f"{sc.file}: simulation failed: {exc}"
            if len(result.t):  # name the cause: singular arm, torques over limits, dt
                error += describe_failure(built, result, dt, controller)
            if len(result.t) == 0:  # the set-up cannot even start: an input error
                key = "controller" if "controller" in str(exc) else ""
                raise ScenarioError(sc.file, key, f"the simulation cannot start: {exc}") from exc
        except Exception as exc:  # a bug: keep what was simulated, then let it surface
            signals.hold()
            result, internal = partial_result(exc), exc
            if result is None or len(result.t) == 0:
                raise
            status = "failed"
            error = f"{sc.file}: internal error (a bug): {type(exc).__name__}: {exc}"
        finally:
            if bar is not None:
                bar.close()
        wall = time.perf_counter() - t0
        status, error, feasibility = apply_policies(built, result, scene, status, error, stopped,
                                                    monitors)
        t_end = float(result.t[-1])
        if status == "interrupted":
            _say(f"{error} at t = {t_end:.6g} s of {T:g} s: writing the partial results "
                 "(the trajectory and summary first; another Ctrl-C skips the plots and page)",
                 quiet)
        written = _write_results(writer, signals, built, result, solver, wall, T, sc, html,
                                 plots, status, error, input_warns, quiet,
                                 feasibility.as_summary())
    files, traj, summary = written.files, written.trajectory, written.summary
    if internal is not None:
        _say(f"partial results (status failed, t_end = {t_end:.6g} s) in {target}", False)
        raise internal
    missing = (f"; {', '.join(written.missing)} not written (interrupted again while writing)"
               if written.missing and written.interrupt else "")
    missing += "".join(f"; {p}" for p in written.problems)
    if status == "interrupted":
        raise RunInterrupted(f"{sc.file}: {error} at t = {t_end:.6g} s of {T:g} s; partial "
                             f"results in {target}{missing}", t_end, target, signal_name)
    if written.interrupt is not None:
        what = (f"{', '.join(written.missing)} not written" if written.missing else
                "everything was written")
        raise RunInterrupted(f"{sc.file}: interrupted by {written.interrupt} while writing the "
                             f"results of the {status} run: {what}; the trajectory and summary "
                             f"are in {target}", t_end, target, written.interrupt)
    if status == "failed":
        raise RunFailedError(f"{error}; partial results (t = 0 .. {t_end:.6g} s) in {target}",
                             t_end, target, error)
    if written.problems:
        raise RunFailedError(f"{sc.file}: the run is complete but {'; '.join(written.problems)}"
                             f"; the trajectory and summary are in {target}", t_end, target,
                             written.problems[0])
    return RunOutput(target, built, result, traj, summary, files)


def simulate_built(built: BuiltScenario, controller, duration: float, dt: float, solver: str,
                   progress=None, monitors=()):
    """Simulate a built scenario with its simulation settings (integrator, Baumgarte, compiled).

    With ``limits: {torque: saturate}`` the actuators clip the applied torques to the arms'
    URDF effort limits (``simulate(torque_limit=...)``).

    Args:
        built: the built scenario.
        controller: its controller (:func:`scenario_controller`) or None.
        duration: simulated time [s].
        dt: time step [s].
        solver: forward-dynamics solver name.
        progress: optional ``callable(fraction)``.
        monitors: checks made while it runs (``simulate(monitors=...)``, e.g.
            :func:`~multiarm_pin.app.run_feasibility.run_monitors`).

    Returns:
        The :class:`~multiarm_pin.sim.simulation.SimulationResult`.
    """
    from multiarm_pin.sim.simulation import simulate

    sim = built.scenario.simulation
    limit = None
    if built.scenario.limits.torque == "saturate" and built.system.n_arms:
        from multiarm_pin.feasibility.limits import arm_limits

        limit = np.concatenate([arm_limits(a).effort for a in built.system.arms])
    with np.errstate(over="ignore", invalid="ignore"):  # NaN/inf are caught and reported
        return simulate(built.system, built.initial_state, controller, duration, dt,
                        integrator=sim.integrator, solver=solver, baumgarte=sim.baumgarte,
                        progress=progress,
                        external_wrench=built.scenario.object.external_wrench or None,
                        torque_limit=limit, monitors=monitors, compiled=sim.compiled)


@dataclass
class _Written:
    """What :func:`_write_results` wrote and published.

    Attributes:
        files: every file in the results folder, by role.
        trajectory: the arrays of ``trajectory.npz``.
        summary: the content of ``summary.json``.
        missing: the files not written because of an interrupt while writing.
        interrupt: the signal (``"SIGINT"``, ``"SIGTERM"``) that came while writing, or None.
        problems: why a plot or the page could not be written (one message each).
    """

    files: dict
    trajectory: dict
    summary: dict
    missing: list
    interrupt: str | None
    problems: list


def _write_results(writer: ResultsWriter, signals: _RunSignals, built: BuiltScenario, result,
                   solver: str, wall: float, T: float, sc: Scenario, html: bool, plots: bool,
                   status: str, error: str | None, input_warns: list[str],
                   quiet: bool, feasibility: dict | None = None) -> _Written:
    """Write the results into the writer's staging folder and publish them.

    First, with signals held back, ``trajectory.npz`` (uncompressed: written at disk speed),
    ``scenario.yaml`` and ``summary.json`` (its ``missing_files`` lists the plots and page
    still to come); then, interruptible, the plots and the replay page, each into a name
    of its own and renamed when whole; then, signals held again, the final ``summary.json``
    and the move into place. A signal during the plots or page stops them: the folder is
    published without them and the summary says which files are missing and why
    (``write_interrupted``, a warning). Prints each step unless ``quiet``.

    Raises:
        ResultsNotMovedError: the move into place failed (the staging folder is kept).
    """
    folder, target = writer.path, writer.target
    start = time.perf_counter()
    _say(f"writing results to {target}", quiet)
    traj = trajectory_arrays(built, result, (feasibility or {}).get("violations", ()))
    files = {"trajectory": folder / "trajectory.npz", "scenario": folder / "scenario.yaml",
             "summary": folder / "summary.json"}
    summary = summarize(built, result, solver, wall)
    summary["input_warnings"] = list(input_warns)
    summary["requested"]["duration"] = T
    summary.update(status=status, error=error, t_end=float(result.t[-1]))
    summary.update(feasibility or {})
    phases = phases_summary(sc, traj, summary["events"])
    if phases:
        summary["phases"] = phases
    pending = []
    if plots:
        pending += plot_names(traj, [sp.name for sp in built.system.supports.supports],
                              [a.name for a in built.system.arms])
    if html:
        pending.append("replay.html")
    try:
        np.savez(files["trajectory"], **traj)
        files["scenario"].write_text(scenario_copy(sc, T, solver), encoding="utf-8")
        _write_summary(files, summary, pending, None)  # the plots and page still to come
    except OSError as exc:  # e.g. a full disk: nothing whole to keep
        raise OutputError(f"--out {target}: cannot write the results in {folder}: "
                          f"{exc.strerror or exc}") from exc
    _say(f"  trajectory.npz, scenario.yaml, summary.json: {time.perf_counter() - start:.1f} s",
         quiet)
    steps = []
    if plots:
        steps.append((f"plots ({len(pending) - int(html)} PNG files)",
                      lambda: _write_plots(folder, built, sc, traj)))
    if html:
        steps.append(("replay page", lambda: {"replay": _write_page(folder, built, traj)}))
    interrupt, problems = None, []
    try:
        signals.arm()  # a signal held while the first files were written stops here
        for label, write in steps:
            step = time.perf_counter()
            _say(f"  {label}...", quiet)
            try:
                files.update(write())
            except Exception as exc:  # noqa: BLE001 - the trajectory and summary stay kept
                problems.append(f"{label.split(' (')[0]} not written: {type(exc).__name__}: "
                                f"{exc}")
                print(f"warning: {problems[-1]}", file=sys.stderr, flush=True)
                continue
            _say(f"  {label}: {time.perf_counter() - step:.1f} s", quiet)
        signals.hold()
    except KeyboardInterrupt as exc:  # the handler holds the signals that follow
        interrupt = getattr(exc, "signal_name", "SIGINT")
    written = {p.name for p in files.values()}
    for p in list(folder.iterdir()):  # a plot or page cut short
        if p.name not in written:
            if p.is_dir():
                shutil.rmtree(p, ignore_errors=True)
            else:
                p.unlink()
    missing = [name for name in pending if name not in written]
    notes = list(problems)
    if interrupt is not None and missing:
        notes.append(f"interrupted by {interrupt} while writing the results: "
                     f"{', '.join(missing)} not written (multiarm-pin replay DIR still replays "
                     "the run)")
    try:
        _write_summary(files, summary, missing, interrupt, notes)
    except OSError as exc:  # the first summary stays: it lists the plots and page as missing
        print(f"warning: {folder / 'summary.json'} not updated: {exc.strerror or exc}",
              file=sys.stderr, flush=True)
    writer.publish()
    later = signals.take_held()
    if interrupt is not None:
        _say(f"  interrupted by {interrupt}: {', '.join(missing) or 'nothing'} not written", quiet)
    elif later is not None:
        interrupt = later  # held during the final move: the results are all there
    _say(f"results written to {target} in {time.perf_counter() - start:.1f} s", quiet)
    return _Written({k: target / p.name for k, p in files.items()}, traj, summary, missing,
                    interrupt, problems)


def _write_summary(files: dict, summary: dict, missing: list, interrupt: str | None,
                   notes: list[str] = ()) -> None:
    """Write ``summary.json`` atomically, with the files written, those missing and why."""
    summary["files"] = {k: p.name for k, p in files.items()}
    summary["missing_files"] = list(missing)
    summary["write_interrupted"] = interrupt
    summary["warnings"] += [n for n in notes if n not in summary["warnings"]]
    write_atomic(files["summary"], json.dumps(summary, indent=2).encode("utf-8"))


def _write_plots(folder: Path, built: BuiltScenario, sc: Scenario, traj: dict) -> dict:
    """The PNG plots, drawn into a folder of their own, moved beside the others when all are.

    Returns:
        The plots in ``folder`` by role (their stems).
    """
    from multiarm_pin.app.plots import write_plots

    part = Path(tempfile.mkdtemp(prefix=".plots-", dir=folder))
    try:
        written = write_plots(part, traj, [a.name for a in built.arms], sc.name,
                              [sp.name for sp in built.system.supports.supports],
                              replay_phases(sc, traj))
        out = {}
        for p in written:
            os.replace(p, folder / p.name)
            out[p.stem] = folder / p.name
        return out
    finally:
        shutil.rmtree(part, ignore_errors=True)


def _write_page(folder: Path, built: BuiltScenario, traj: dict) -> Path:
    """``replay.html``, written under another name and renamed when whole."""
    from multiarm_pin.app.replay import write_replay_html

    rarms, robj, rc = replay_parts(built.arms, built.obj, traj)
    part = folder / ".replay.html.part"
    write_replay_html(part, rarms, robj, traj["t"], rc, fps=REPLAY_FPS,
                      title=f"{built.scenario.name}: multiarm-pin replay",
                      phases=replay_phases(built.scenario, traj))
    final = folder / "replay.html"
    os.replace(part, final)
    return final


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
    "scenario_controller",
    "run_scenario",
    "serve_run",
    "simulate_built",
    "summarize",
]
