"""The ``run`` and ``replay`` commands: simulate a scenario, write its results, replay them.

``multiarm-pin run SCENARIO.yaml [--out DIR] [--solver NAME] [--duration S]`` writes into DIR:

- ``trajectory.npz``: ``t`` (T,), ``object_position`` (T, 3), ``object_quaternion`` (T, 4,
  ``[x, y, z, w]``), ``object_twist`` (T, 6, ``[ẋ; ω]`` world axes), for each arm A
  ``q_A`` (T, nq), ``v_A`` (T, nv), ``tau_A`` (T, nv), ``mu_A`` (T, N_A) (contact multipliers
  [N], positive = pushing), ``phi_A`` (T, N_A) (gaps [m]); ``constraint_violation`` (T,)
  = max |φ| over held contacts and the penetration of separated ones [m];
  ``contact_points`` (T, K, 3) [m] and ``contact_forces`` (T, K, 3) [N] (force on the
  object, world axes) of the K contacts of all arms in order, then of the supports;
  ``contact_labels`` (K,) and ``contact_active`` (T, K) (touching: in the active set, or
  bilateral); for each support S ``mu_S``, ``phi_S`` (T, P_S); ``support_names`` (S,) and
  ``support_planes`` (S, 6) (plane point and normal, world); ``external_wrench`` (T, 6);
  the contact events ``event_t`` (E,) [s], ``event_contact`` (E,) (index in K) and
  ``event_kind`` (E,) (``separation`` / ``touchdown``);
  ``kinetic_energy``, ``potential_energy`` (T,) [J]; ``momentum`` (T, 6).
- ``summary.json``: scenario name, solver, steps, wall time, max constraint violation,
  min contact force, warnings (contact separations, solver switches), ``input_warnings``
  (legal but suspicious input values, also printed on stderr before the run), per-arm
  details (tool frame and offset, q0 and where it came from), ``status`` (``complete``,
  ``failed`` or ``interrupted``), ``error`` (the message, or null) and ``t_end`` (the last
  simulated time [s]);
  ``events`` (every separation and touchdown: time, contact, arm or support).
- ``object_pose.png``, ``contact_forces.png``, ``constraint_violation.png``.
- ``replay.html``: a self-contained Meshcat page replaying the run offline.
- ``scenario.yaml``: the scenario (URDF paths absolute), so that ``multiarm-pin replay DIR``
  can rebuild the arms.
"""

from __future__ import annotations

import argparse
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
import pinocchio as pin
import yaml

from multiarm_pin.app.results_io import (
    ResultsWriter,
    deferred_signals,
    prepare_output,
    safe_component,
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
    InputError,
    MultiArmError,
    OutputError,
    RunFailedError,
    RunInterrupted,
    ScenarioError,
)

REPLAY_FPS = 30
"""Frames per second of the replay page."""


# ----------------------------------------------------------------------------- progress
class ProgressBar:
    """A one-line text progress bar on a stream (stderr by default).

    Redraws at most every ``min_interval`` seconds; shows nothing for runs shorter than
    ``delay`` seconds of wall time (short runs stay quiet). On a stream that is not a
    terminal (a log file, CI) it writes one line per tenth of the run instead of redrawing.
    """

    def __init__(self, label: str, total_time: float, stream=None, width: int = 30,
                 delay: float = 0.5, min_interval: float = 0.1):
        self.label, self.total_time, self.width = label, float(total_time), width
        self.stream = sys.stderr if stream is None else stream
        self.delay, self.min_interval = delay, min_interval
        self.start = time.perf_counter()
        self._last = -1.0
        self.shown = False
        isatty = getattr(self.stream, "isatty", None)
        self.interactive = bool(isatty()) if callable(isatty) else False
        self._next_tenth = 0.1

    def __call__(self, fraction: float) -> None:
        """Update with the fraction done (0..1)."""
        now = time.perf_counter()
        elapsed = now - self.start
        if elapsed < self.delay and fraction < 1.0:
            return
        if fraction < 1.0 and now - self._last < self.min_interval:
            return
        f = min(max(float(fraction), 0.0), 1.0)
        if not self.interactive:
            if f < self._next_tenth and f < 1.0:
                return
            self._next_tenth = (int(f * 10 + 1e-9) + 1) / 10
        self._last = now
        n = int(round(f * self.width))
        eta = elapsed * (1 - f) / f if f > 0 else float("nan")
        start, end = ("\r", "") if self.interactive else ("", "\n")
        self.stream.write(
            f"{start}{self.label} [{'#' * n}{'-' * (self.width - n)}] {100 * f:5.1f}% "
            f"t = {f * self.total_time:.3f}/{self.total_time:.3f} s, "
            f"{elapsed:.1f} s elapsed, ~{eta:.1f} s left {end}"
        )
        self.stream.flush()
        self.shown = True

    def close(self) -> None:
        """End the line if anything was drawn."""
        if self.shown and self.interactive:
            self.stream.write("\n")
            self.stream.flush()


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


def trajectory_arrays(built: BuiltScenario, result) -> dict[str, np.ndarray]:
    """The ``trajectory.npz`` arrays of a run (see the module docstring for keys/shapes)."""
    return system_trajectory_arrays(built.system, result)


def system_trajectory_arrays(system, result) -> dict[str, np.ndarray]:
    """:func:`trajectory_arrays` of a simulation of a ``MultiArmSystem`` built without a file."""
    aset = system.arm_set
    out = {
        "t": result.t,
        "object_position": result.object_position,
        "object_quaternion": result.object_quaternion,
        "object_twist": result.object_twist,
        "constraint_violation": result.constraint_violation,
        "kinetic_energy": result.kinetic_energy,
        "potential_energy": result.potential_energy,
        "momentum": result.momentum,
    }
    points, forces = [], []
    for i, arm in enumerate(system.arms):
        N = int(system.constraint_set.N[i])
        out[f"q_{arm.name}"] = result.q[:, aset.q_slices[i]]
        out[f"v_{arm.name}"] = result.v[:, aset.v_slices[i]]
        out[f"tau_{arm.name}"] = result.tau[:, aset.v_slices[i]]
        out[f"mu_{arm.name}"] = result.mu[:, i, :N]
        out[f"phi_{arm.name}"] = result.phi[:, i, :N]
        points.append(result.contact_points[:, i, :N])
        forces.append(result.mu[:, i, :N, None] * result.normals[:, i, :N])
    n, sup = system.n_arms, system.supports
    for k, spt in enumerate(sup.supports):
        rows = np.flatnonzero(sup.support_index == k)
        out[f"mu_{spt.name}"] = result.mu[:, n, rows]
        out[f"phi_{spt.name}"] = result.phi[:, n, rows]
    if sup.n_rows:
        K = sup.n_rows
        points.append(result.contact_points[:, n, :K])
        forces.append(result.mu[:, n, :K, None] * result.normals[:, n, :K])
    out["contact_points"] = np.concatenate(points, axis=1)
    out["contact_forces"] = np.concatenate(forces, axis=1)
    mask = system.contact_mask
    held = result.active | (mask & ~system.contact_unilateral)[None]
    out["contact_active"] = held[:, mask]
    out["contact_labels"] = np.array([lab for _, _, lab in system.contact_labels], dtype=str)
    out["external_wrench"] = result.external_wrench
    out["support_names"] = np.array([sp.name for sp in sup.supports], dtype=str)
    out["support_planes"] = np.array([np.concatenate([sp.point, sp.normal])
                                      for sp in sup.supports]).reshape(-1, 6)
    flat = -np.ones(mask.shape, dtype=int)
    flat[mask] = np.arange(int(mask.sum()))
    out["event_t"] = np.array([e.t for e in result.events], dtype=float)
    out["event_contact"] = np.array([flat[e.block, e.row] for e in result.events], dtype=int)
    out["event_kind"] = np.array([e.kind for e in result.events], dtype=str)
    return {k: np.ascontiguousarray(v) for k, v in out.items()}


def summarize(built: BuiltScenario, result, solver: str, wall_time: float) -> dict:
    """The ``summary.json`` content: run settings, physical checks and warnings."""
    system = built.system
    mask = np.asarray(system.contact_mask)
    mu = result.mu
    real = mu[:, mask]
    n = system.n_arms
    uni_mu = mu[:, :n, :system.N_max][:, np.asarray(system.unilateral)]  # the arms' rows
    sup_mu = mu[:, n, :system.supports.n_rows] if system.supports.n_rows else mu[:, :0, 0]
    e = result.kinetic_energy + result.potential_energy
    arms = []
    for i, (arm, spec) in enumerate(zip(built.arms, built.scenario.arms, strict=True)):
        ik = built.ik[i]
        arms.append({
            "name": arm.name,
            "source": arm.source,
            "tool_frame": arm.tool_frame,
            "tool_offset": {"position": [float(x) for x in arm.tool_offset.translation],
                            "quaternion": [float(x) for x in
                                           pin.Quaternion(arm.tool_offset.rotation).coeffs()]},
            "nq": arm.nq,
            "joint": spec.joint.type,
            "constraints": int(system.constraint_set.N[i]),
            "q0": [float(x) for x in built.q0[i]],
            "q0_from": "q0" if ik is None else "inverse kinematics",
            "ik_residual": None if ik is None else float(ik.residual),
            "min_contact_force": float(mu[:, i, mask[i]].min()),
            "max_contact_force": float(mu[:, i, mask[i]].max()),
            "separations": sum(1 for e in result.events
                               if e.block == i and e.kind == "separation"),
        })
    warnings = list(result.warnings)
    if uni_mu.size and uni_mu.min() < 0:
        warnings.append(
            f"a unilateral (fingertip) contact pulls: min contact force {uni_mu.min():.4g} N "
            "(the contact would separate)")
    if result.solver_switches:
        warnings.append(f"solver switched to the singular-arm variant at t = "
                        f"{[round(float(x), 6) for x in result.solver_switches]} s")
    sim = built.scenario.simulation
    return {
        "scenario": built.scenario.name,
        "scenario_file": str(Path(built.scenario.file).resolve()),
        "solver": solver,
        "solvers_used": sorted({str(s) for s in np.asarray(result.solver)}),
        "integrator": result.integrator,
        "dt": float(result.dt),
        "duration": float(result.t[-1] - result.t[0]),
        "steps": int(len(result.t) - 1),
        "samples": int(len(result.t)),
        "wall_time": float(wall_time),
        "baumgarte": None if result.baumgarte is None else list(result.baumgarte),
        "controller": built.scenario.controller.type,
        "max_constraint_violation": float(np.max(result.constraint_violation)),
        "min_contact_force": float(real.min()) if real.size else None,
        "max_contact_force": float(real.max()) if real.size else None,
        "min_unilateral_contact_force": float(uni_mu.min()) if uni_mu.size else None,
        "max_support_force": float(sup_mu.max()) if sup_mu.size else None,
        "energy_change": float(e[-1] - e[0]),
        "object_displacement": float(np.linalg.norm(result.object_position[-1]
                                                    - result.object_position[0])),
        "finite": bool(all(np.all(np.isfinite(a)) for a in
                           (result.q, result.v, result.mu, result.object_position,
                            result.object_twist))),
        "arms": arms,
        "supports": [{"name": sp.name, "point": sp.point.tolist(), "normal": sp.normal.tolist(),
                      "points": int(len(sp.points)), "restitution": sp.restitution}
                     for sp in system.supports.supports],
        "external_wrench": [{"from": a, "to": b, "wrench": w.tolist()}
                            for a, b, w in built.scenario.object.external_wrench],
        "events": [e.as_dict() for e in result.events],
        "warnings": warnings,
        "requested": {"duration": sim.duration, "dt": sim.dt},
    }


def replay_parts(arms, obj, trajectory: dict):
    """Replay inputs (:mod:`multiarm_pin.app.replay`) from arms, object and trajectory arrays.

    Returns:
        ``(replay_arms, replay_object, replay_contacts)``.
    """
    from multiarm_pin.app.replay import ReplayArm, ReplayContacts, ReplayObject, ReplaySupport

    def finite(a, limit=1e12):  # a failed run may end on huge or NaN values: drawable
        return np.clip(np.nan_to_num(np.asarray(a, float), nan=0.0, posinf=limit,
                                     neginf=-limit), -limit, limit)

    rarms = [ReplayArm(a.name, a.model, a.visual_model, pin.SE3.Identity(),
                       finite(trajectory[f"q_{a.name}"], 1e3)) for a in arms]
    quat = np.array(trajectory["object_quaternion"], float)
    bad = ~np.all(np.isfinite(quat), axis=1) | (np.linalg.norm(np.nan_to_num(quat), axis=1)
                                                 < 1e-9)
    quat[bad] = [0.0, 0.0, 0.0, 1.0]
    robj = ReplayObject(obj.shape, finite(trajectory["object_position"], 1e6), quat)
    rc = None
    if trajectory["contact_points"].shape[1] > 0:
        labels = [str(x) for x in trajectory.get("contact_labels", [])]
        supports = []
        for name, plane in zip(trajectory.get("support_names", []),
                               trajectory.get("support_planes", np.zeros((0, 6))), strict=True):
            rows = [k for k, lab in enumerate(labels) if lab.startswith(f"{name}[")]
            a, n = plane[:3], plane[3:]
            pts = trajectory["contact_points"][0, rows]
            pts = pts - ((pts - a) @ n)[:, None] * n  # projected onto the plane
            c = pts.mean(axis=0)
            half = float(np.max(np.linalg.norm(pts - c, axis=1), initial=0.0)) + 0.1
            supports.append(ReplaySupport(str(name), c, n, half))
        touching = trajectory.get("contact_active")
        rc = ReplayContacts(finite(trajectory["contact_points"], 1e6),
                            finite(trajectory["contact_forces"]),
                            None if touching is None else np.asarray(touching, dtype=bool),
                            supports)
    return rarms, robj, rc


def _scenario_copy(scenario: Scenario, duration: float, solver: str) -> str:
    data = dict(scenario.data)
    head = (f"# copy of {Path(scenario.file).resolve()} as run (URDF paths made absolute)\n"
            f"# run with solver={solver}, duration={duration} s\n")
    return head + yaml.safe_dump(data, sort_keys=False, default_flow_style=None)


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
        html: write ``replay.html`` (starts a temporary Meshcat server, a few seconds).
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
        t_end = float(result.t[-1])
        try:
            _say(f"writing results to {target}", quiet)
            files, traj, summary = _write_results(writer.path, built, result, solver, wall,
                                                  T, sc, html, plots, status, error,
                                                  input_warns)
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
                   error: str | None, input_warns: list[str]) -> tuple[dict, dict, dict]:
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
    files["scenario"] = folder / "scenario.yaml"
    files["scenario"].write_text(_scenario_copy(sc, T, solver), encoding="utf-8")
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


# ----------------------------------------------------------------------------- replay
REQUIRED_ARRAYS = ("t", "object_position", "object_quaternion", "contact_points",
                   "contact_forces")
"""Arrays of ``trajectory.npz`` that the replay needs (besides each arm's ``q_A``)."""


def load_run(run_dir) -> tuple[Scenario, dict, dict]:
    """Read a results folder: its scenario copy, trajectory arrays and summary.

    A partial run (``summary.json`` ``"status"`` ``"failed"`` or ``"interrupted"``) loads
    like a complete one; its arrays end at ``"t_end"``.

    Raises:
        InputError: the folder or one of its files is missing, empty, truncated or not what
            ``multiarm-pin run`` writes (names the file and what was expected).
    """
    import zipfile

    d = Path(run_dir)
    missing = [f for f in ("scenario.yaml", "trajectory.npz") if not (d / f).is_file()]
    if not d.is_dir() or missing:
        raise InputError(f"{d}: not a results folder of 'multiarm-pin run' (missing "
                         f"{', '.join(missing) or 'folder'})")
    sc = load_scenario(d / "scenario.yaml")
    f = d / "trajectory.npz"
    try:
        with np.load(f, allow_pickle=False) as z:
            traj = {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, KeyError) as exc:
        size = f.stat().st_size
        raise InputError(f"{f}: not a readable trajectory ({size} bytes; empty or truncated, "
                         f"e.g. by an interrupted write): {type(exc).__name__}: {exc}; expected "
                         "the numpy .npz archive written by 'multiarm-pin run'") from None
    needed = [*REQUIRED_ARRAYS, *(f"q_{a.name}" for a in sc.arms)]
    absent = [k for k in needed if k not in traj]
    if absent:
        raise InputError(f"{f}: missing arrays {absent}; expected those written by "
                         "'multiarm-pin run'")
    T = len(traj["t"])
    if T == 0:
        raise InputError(f"{f}: holds no samples (t is empty)")
    bad = [k for k in needed if len(traj[k]) != T]
    if bad:
        raise InputError(f"{f}: arrays {bad} do not have {T} samples like 't'")
    summary = {}
    sf = d / "summary.json"
    if sf.is_file():
        try:
            summary = json.loads(sf.read_text(encoding="utf-8"))
        except (UnicodeDecodeError, ValueError) as exc:
            raise InputError(f"{sf}: not valid JSON ({exc})") from None
        if not isinstance(summary, dict):
            raise InputError(f"{sf}: expected a JSON object")
    return sc, traj, summary


def run_status(summary: dict) -> str:
    """One line describing a run's status from its summary (``complete`` or partial)."""
    status = summary.get("status", "complete")
    if status == "complete":
        return "complete run"
    t_end = summary.get("t_end")
    requested = (summary.get("requested") or {}).get("duration")
    when = f" at t = {t_end:.6g} s" if isinstance(t_end, int | float) else ""
    of = f" of {requested:g} s" if isinstance(requested, int | float) else ""
    why = f": {summary['error']}" if summary.get("error") else ""
    return f"partial run ({status}{when}{of}){why}"


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


# ----------------------------------------------------------------------------- CLI
def configure_run_parser(p: argparse.ArgumentParser) -> None:
    """Arguments of ``multiarm-pin run``."""
    p.add_argument("scenario", help="scenario YAML file")
    p.add_argument("--out", default=None, help="results folder (default results/<name>)")
    p.add_argument("--solver", default=None,
                   help="forward-dynamics solver: object_first, dense_kkt, auto, singular")
    p.add_argument("--duration", type=float, default=None, help="simulated time [s]")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--no-html", dest="html", action="store_false",
                   help="skip the replay page (faster)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace a results folder of another scenario file")


def run_command(args: argparse.Namespace) -> int:
    """``multiarm-pin run``: simulate, write results, print where they are.

    Returns:
        0 for a complete run, 1 for a run that failed after its simulation started, 130 for
        an interrupted run (Ctrl-C, SIGTERM); partial results are written in both cases.
    """
    html = getattr(args, "html", True)
    try:
        res = run_scenario(args.scenario, args.out, args.solver, args.duration,
                           quiet=bool(args.quiet), html=html,
                           overwrite=bool(getattr(args, "overwrite", False)))
    except RunFailedError as exc:
        print(f"error: {exc}", file=sys.stderr)
        if exc.out_dir is not None:
            print(f"partial results (status failed, t_end = {exc.t_end:.6g} s): {exc.out_dir}; "
                  f"replay them with: multiarm-pin replay {exc.out_dir}", file=sys.stderr)
        return 1
    except RunInterrupted as exc:
        print(f"interrupted: {exc}", file=sys.stderr)
        if exc.out_dir is not None:
            status = "interrupted"
            with contextlib.suppress(OSError, ValueError):
                status = json.loads((Path(exc.out_dir) / "summary.json").read_text(
                    encoding="utf-8")).get("status", status)
            what = "partial results" if status != "complete" else "results"
            print(f"{what} (status {status}, t_end = {exc.t_end:.6g} s): {exc.out_dir}; "
                  f"replay them with: multiarm-pin replay {exc.out_dir}", file=sys.stderr)
        return 130
    s = res.summary
    out = res.out_dir.resolve()
    print(f"scenario {s['scenario']}: {s['steps']} steps of {s['dt']:g} s "
          f"({s['integrator']}, solver {s['solver']}) in {s['wall_time']:.2f} s wall time")
    forces = ("none" if s["min_contact_force"] is None else
              f"{s['min_contact_force']:.4g} .. {s['max_contact_force']:.4g} N")
    print(f"  max constraint violation {s['max_constraint_violation']:.3g} m, contact forces "
          f"{forces}")
    if s.get("events"):
        e0 = s["events"][0]
        print(f"  {len(s['events'])} contact events (separations, touchdowns); first: "
              f"{e0['kind']} of {e0['label']} at t = {e0['t']:.4g} s")
    for w in s["warnings"][:10]:
        print(f"  warning: {w}")
    if len(s["warnings"]) > 10:
        print(f"  ... {len(s['warnings']) - 10} more warnings in summary.json")
    print(f"results: {out}")
    print(f"  trajectory: {out / 'trajectory.npz'}")
    print(f"  summary:    {out / 'summary.json'}")
    pngs = ("object_pose.png", "contact_forces.png", "constraint_violation.png")
    print("  plots:      " + ", ".join(str(out / f) for f in pngs))
    if "replay" in res.files:
        print(f"replay (open in a browser, works offline): {out / 'replay.html'}")
    print(f"live replay: multiarm-pin replay {out}")
    return 0


def configure_replay_parser(p: argparse.ArgumentParser) -> None:
    """Arguments of ``multiarm-pin replay``."""
    p.add_argument("dir", help="results folder written by 'multiarm-pin run'")
    p.add_argument("--fps", type=float, default=REPLAY_FPS, help="frames per second")
    p.add_argument("--open", action="store_true", help="open the page in the browser")
    p.add_argument("--no-block", "--once", dest="block", action="store_false",
                   help="check that the server answers, then stop (for scripts and tests)")


def replay_command(args: argparse.Namespace) -> int:
    """``multiarm-pin replay DIR``: serve the run and print its URL until Ctrl-C."""
    from multiarm_pin.app.replay import close_visualizer

    summary = load_run(args.dir)[2]
    if summary.get("status", "complete") != "complete":
        print(f"note: {Path(args.dir).resolve()} holds a {run_status(summary)}; replaying what "
              "was simulated", flush=True)
    url, vis = serve_run(args.dir, fps=args.fps, open_browser=bool(getattr(args, "open", False)))
    try:
        print(f"replay of {Path(args.dir).resolve()} ({run_status(summary).split(':')[0]}) "
              f"served at {url}", flush=True)
        if not getattr(args, "block", True):
            status = http_status(url)
            print(f"server answered HTTP {status}; stopping (--no-block)")
            return 0 if status == 200 else 1
        print("press Ctrl-C to stop", flush=True)
        try:
            while True:
                time.sleep(1.0)
        except KeyboardInterrupt:
            print("stopped")
        return 0
    finally:
        close_visualizer(vis)


__all__ = [
    "REPLAY_FPS",
    "ProgressBar",
    "RunOutput",
    "configure_replay_parser",
    "configure_run_parser",
    "http_status",
    "load_run",
    "make_controller",
    "run_status",
    "replay_command",
    "replay_parts",
    "run_command",
    "run_scenario",
    "serve_run",
    "simulate_built",
    "summarize",
    "trajectory_arrays",
]
