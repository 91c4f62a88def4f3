"""The files of a run: its trajectory arrays and summary, and reading a results folder back.

``multiarm-pin run SCENARIO.yaml`` (:func:`multiarm_pin.app.runner.run_scenario`) writes into
its results folder:

- ``trajectory.npz`` (uncompressed): ``t`` (T,), ``object_position`` (T, 3),
  ``object_quaternion`` (T, 4, ``[x, y, z, w]``), ``object_twist`` (T, 6, ``[ẋ; ω]`` world
  axes), for each arm A ``q_A`` (T, nq), ``v_A`` (T, nv), ``tau_A`` (T, nv), ``mu_A``
  (T, N_A) (contact multipliers [N], positive = pushing), ``phi_A`` (T, N_A) (gaps [m]);
  ``constraint_violation`` (T,)
  = max |φ| over held contacts and the penetration of separated ones [m];
  ``contact_points`` (T, K, 3) [m] and ``contact_forces`` (T, K, 3) [N] (force on the
  object, world axes) of the K contacts of all arms in order, then of the supports;
  ``contact_labels`` (K,) and ``contact_active`` (T, K) (touching: in the active set, or
  bilateral); for each support S ``mu_S``, ``phi_S`` (T, P_S); ``support_names`` (S,) and
  ``support_planes`` (S, 6) (plane point and normal, world), ``support_extents`` (S, 2)
  (``[lx, ly]`` [m], NaN for an infinite plane) and ``support_x_axes`` (S, 3) (the
  rectangles' x axes, world); ``external_wrench`` (T, 6);
  the contact events ``event_t`` (E,) [s], ``event_contact`` (E,) (index in K) and
  ``event_kind`` (E,) (``separation`` / ``touchdown`` / ``off_edge``) and
  ``event_impulse`` (E,) (the impact's contact impulse [N s], 0 for none);
  ``kinetic_energy``, ``potential_energy`` (T,) [J]; ``momentum`` (T, 6);
  ``arm_wrench`` (T, n_arms, 6): each arm's wrench on the object ``[f; m]`` [N, N m], world
  axes, the moment about the COM (:meth:`SimulationResult.arm_wrench`); for each arm A
  ``tau_limit_A`` (nv,) its joints' URDF effort limits [N m] (``inf``: none),
  ``joint_names_A`` (nv,) their names, and, when the
  run saturates the actuators, ``tau_commanded_A`` (T, nv) (``tau_A`` is then the applied
  torque); ``unilateral_arms``: the arms with unilateral (fingertip) rows; the collisions'
  time intervals ``collision_link`` (C,) (``"<arm>/<link>"``), ``collision_t0``,
  ``collision_t1`` (C,) [s] (first and last sample of each run of samples in collision;
  the replay draws the link red over them).
- ``summary.json``: scenario name, solver, steps, wall time, max constraint violation,
  min contact force, warnings (contact separations, solver switches), ``input_warnings``
  (legal but suspicious input values, also printed on stderr before the run), per-arm
  details (tool frame and offset, q0 and where it came from), ``status`` (``complete``,
  ``failed`` or ``interrupted``), ``error`` (the message, or null) and ``t_end`` (the last
  simulated time [s]);
  ``events`` (every separation and touchdown: time, contact, arm or support); ``files``
  (the files written, by role), ``missing_files`` (those a signal or an error left out:
  plots, ``replay.html``) and ``write_interrupted`` (the signal that came while writing,
  or null); ``feasible``, ``violations``, ``limits`` and ``clearance``
  (:meth:`multiarm_pin.feasibility.FeasibilityReport.as_summary`); for a ``phased_pd``
  run, ``phases`` (:func:`multiarm_pin.app.replay_phases.phases_summary`: each phase's
  interval and the events in it).
- ``object_pose.png``, ``arm_wrenches.png``, ``joint_torques.png``, ``contact_forces.png``
  (fingertips and supports), ``constraint_violation.png``.
- ``replay.html``: a self-contained Meshcat page replaying the run offline.
- ``scenario.yaml``: the scenario (URDF paths absolute), so that ``multiarm-pin replay DIR``
  can rebuild the arms.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pinocchio as pin
import yaml

from multiarm_pin.app import REPLAY_FPS
from multiarm_pin.app.scenario import BuiltScenario, Scenario, load_scenario
from multiarm_pin.exceptions import InputError


# ----------------------------------------------------------------------------- writing
def trajectory_arrays(built: BuiltScenario, result, violations=()) -> dict[str, np.ndarray]:
    """The ``trajectory.npz`` arrays of a run (see the module docstring for keys/shapes).

    ``violations``: the run's feasibility violations (``summary.json``'s dicts), whose
    collisions give the ``collision_*`` arrays.
    """
    return {**system_trajectory_arrays(built.system, result), **collision_arrays(violations)}


def collision_arrays(violations) -> dict[str, np.ndarray]:
    """``collision_link``, ``collision_t0``, ``collision_t1`` of a run's violations.

    Args:
        violations: ``summary.json``'s ``violations`` (dicts; collisions carry
            ``intervals``).
    """
    rows = [(f"{v['arm']}/{v['link']}", a, b) for v in violations
            if v.get("kind") == "collision" for a, b in v.get("intervals", ())]
    return {"collision_link": np.array([r[0] for r in rows], dtype=str),
            "collision_t0": np.array([r[1] for r in rows], dtype=float),
            "collision_t1": np.array([r[2] for r in rows], dtype=float)}


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
    out["support_extents"] = np.array([sp.extent if sp.finite else (np.nan, np.nan)
                                       for sp in sup.supports], dtype=float).reshape(-1, 2)
    out["support_x_axes"] = np.array([sp.x_axis for sp in sup.supports],
                                     dtype=float).reshape(-1, 3)
    flat = -np.ones(mask.shape, dtype=int)
    flat[mask] = np.arange(int(mask.sum()))
    out["event_t"] = np.array([e.t for e in result.events], dtype=float)
    out["event_contact"] = np.array([flat[e.block, e.row] for e in result.events], dtype=int)
    out["event_kind"] = np.array([e.kind for e in result.events], dtype=str)
    out["event_impulse"] = np.array([e.impulse for e in result.events], dtype=float)
    out["arm_wrench"] = result.arm_wrench(n)
    saturated = result.torque_limit is not None
    from multiarm_pin.feasibility.limits import arm_limits

    for i, arm in enumerate(system.arms):
        limits = arm_limits(arm)  # the URDF's (inf: none given)
        out[f"tau_limit_{arm.name}"] = limits.effort
        out[f"joint_names_{arm.name}"] = np.array(limits.joints, dtype=str)
        if saturated:
            out[f"tau_commanded_{arm.name}"] = result.tau_commanded[:, aset.v_slices[i]]
    uni = system.contact_unilateral[:n].any(axis=1) if n else np.zeros(0, dtype=bool)
    out["unilateral_arms"] = np.array([a.name for a, u in zip(system.arms, uni, strict=True)
                                       if u], dtype=str)
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
                      "points": int(len(sp.points)), "restitution": sp.restitution,
                      "extent": None if sp.extent is None else sp.extent.tolist(),
                      "x_axis": sp.x_axis.tolist()}
                     for sp in system.supports.supports],
        "external_wrench": [{"from": a, "to": b, "wrench": w.tolist()}
                            for a, b, w in built.scenario.object.external_wrench],
        "events": [e.as_dict() for e in result.events],
        "warnings": warnings,
        "requested": {"duration": sim.duration, "dt": sim.dt},
    }


def plot_names(trajectory: dict, support_names=(), arm_names=None) -> list[str]:
    """The PNG files :func:`multiarm_pin.app.plots.write_plots` writes for a run, in order.

    ``contact_states.png`` when the run has contact events or supports; ``arm_wrenches.png``
    with the arms' wrenches (``arm_wrench``); ``joint_torques.png`` with every arm's effort
    limits (``tau_limit_<arm>``); ``object_pose.png``; ``contact_forces.png`` when there are
    forces at named points to show (fingertip arms, ``unilateral_arms``, or supports; every
    arm's rows in a file without ``arm_wrench``); ``constraint_violation.png``.

    Args:
        trajectory: the ``trajectory.npz`` arrays (keys and the events' and arms' entries
            named above are looked at).
        support_names: the supports' names.
        arm_names: the arms' names (default: those with a ``tau_limit_<arm>`` entry).
    """
    if arm_names is None:
        arm_names = [k[len("tau_limit_"):] for k in trajectory if k.startswith("tau_limit_")]
    arm_names, support_names = list(arm_names), list(support_names)
    states = "contact_active" in trajectory and \
        bool(len(trajectory.get("event_t", ())) or len(support_names))
    wrench = "arm_wrench" in trajectory and bool(arm_names)
    limits = bool(arm_names) and all(f"tau_limit_{a}" in trajectory for a in arm_names)
    return [*(["contact_states.png"] if states else []),
            *(["arm_wrenches.png"] if wrench else []),
            *(["joint_torques.png"] if limits else []), "object_pose.png",
            *(["contact_forces.png"] if force_names(trajectory, arm_names, support_names)
              else []), "constraint_violation.png"]


def force_names(trajectory: dict, arm_names, support_names) -> list[str]:
    """The arms and supports whose multipliers ``contact_forces.png`` shows.

    With the arms' wrenches in the file, the fingertip arms (``unilateral_arms``) and the
    supports: their multipliers are forces at named points, a weld's six rows are not (its
    wrench says what it does). Without them (an older file), every arm and support.
    """
    if "arm_wrench" not in trajectory or not len(arm_names):
        return [*arm_names, *support_names]
    uni = trajectory.get("unilateral_arms")
    fingertips = set(np.asarray(uni, dtype=str).tolist()) if uni is not None else set()
    return [a for a in arm_names if a in fingertips] + list(support_names)


def replay_parts(arms, obj, trajectory: dict):
    """Replay inputs (:mod:`multiarm_pin.app.replay`) from arms, object and trajectory arrays.

    The arms carry their links' collisions (``collision_*``: drawn red). The contacts carry
    their labels (``contact_labels``), states (``contact_active``),
    supports (``support_names``, ``support_planes``) and events (``event_t``,
    ``event_kind``, ``event_contact``, ``event_impulse``: 0 when a file predates it).

    Returns:
        ``(replay_arms, replay_object, replay_contacts)``.
    """
    from multiarm_pin.app.replay_scene import (
        ReplayArm,
        ReplayContacts,
        ReplayEvent,
        ReplayObject,
        ReplaySupport,
    )

    def finite(a, limit=1e12):  # a failed run may end on huge or NaN values: drawable
        return np.clip(np.nan_to_num(np.asarray(a, float), nan=0.0, posinf=limit,
                                     neginf=-limit), -limit, limit)

    t = np.asarray(trajectory["t"], float)
    colliding: dict[str, dict[str, np.ndarray]] = {a.name: {} for a in arms}
    for name, t0, t1 in zip(trajectory.get("collision_link", []),
                            trajectory.get("collision_t0", []),
                            trajectory.get("collision_t1", []), strict=True):
        arm, link = str(name).split("/", 1)
        if arm in colliding:
            mask = colliding[arm].setdefault(link, np.zeros(len(t), dtype=bool))
            mask |= (t >= t0) & (t <= t1)
    rarms = [ReplayArm(a.name, a.model, a.visual_model, pin.SE3.Identity(),
                       finite(trajectory[f"q_{a.name}"], 1e3), colliding=colliding[a.name])
             for a in arms]
    quat = np.array(trajectory["object_quaternion"], float)
    bad = ~np.all(np.isfinite(quat), axis=1) | (np.linalg.norm(np.nan_to_num(quat), axis=1)
                                                 < 1e-9)
    quat[bad] = [0.0, 0.0, 0.0, 1.0]
    robj = ReplayObject(obj.shape, finite(trajectory["object_position"], 1e6), quat)
    rc = None
    if trajectory["contact_points"].shape[1] > 0:
        labels = [str(x) for x in trajectory.get("contact_labels", [])]
        supports = []
        names = trajectory.get("support_names", [])
        extents = trajectory.get("support_extents", np.full((len(names), 2), np.nan))
        x_axes = trajectory.get("support_x_axes", np.full((len(names), 3), np.nan))
        for name, plane, extent, x_axis in zip(
                names, trajectory.get("support_planes", np.zeros((0, 6))), extents, x_axes,
                strict=True):
            a, n = plane[:3], plane[3:]
            if np.all(np.isfinite(extent)) and np.all(np.isfinite(x_axis)):
                # a rectangle: drawn as it is, centred at its plane point
                supports.append(ReplaySupport(str(name), a, n, 0.5 * float(np.max(extent)),
                                              extent, x_axis))
                continue
            rows = [k for k, lab in enumerate(labels) if lab.startswith(f"{name}[")]
            pts = trajectory["contact_points"][0, rows]
            pts = pts - ((pts - a) @ n)[:, None] * n  # projected onto the plane
            c = pts.mean(axis=0)
            half = float(np.max(np.linalg.norm(pts - c, axis=1), initial=0.0)) + 0.1
            supports.append(ReplaySupport(str(name), c, n, half))
        touching = trajectory.get("contact_active")
        K = trajectory["contact_points"].shape[1]
        kinds = [str(x) for x in trajectory.get("event_kind", [])]
        impulses = np.nan_to_num(np.asarray(trajectory.get("event_impulse", np.zeros(len(kinds))),
                                            dtype=float), nan=0.0, posinf=0.0, neginf=0.0)
        events = [ReplayEvent(float(te), kind, int(k), float(p)) for te, kind, k, p in
                  zip(trajectory.get("event_t", []), kinds, trajectory.get("event_contact", []),
                      impulses, strict=True)
                  if 0 <= int(k) < K and np.isfinite(te)]
        rc = ReplayContacts(finite(trajectory["contact_points"], 1e6),
                            finite(trajectory["contact_forces"]),
                            None if touching is None else np.asarray(touching, dtype=bool),
                            supports, labels if len(labels) == K else None, events)
    return rarms, robj, rc


def scenario_copy(scenario: Scenario, duration: float, solver: str) -> str:
    """The text of ``scenario.yaml`` in a results folder: the scenario as run, with a header."""
    data = dict(scenario.data)
    head = (f"# copy of {Path(scenario.file).resolve()} as run (URDF paths made absolute)\n"
            f"# run with solver={solver}, duration={duration} s\n")
    return head + yaml.safe_dump(data, sort_keys=False, default_flow_style=None)


# ----------------------------------------------------------------------------- reading back
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


def feasibility_lines(summary: dict, max_lines: int = 8) -> list[str]:
    """The short block the command line prints for a run that was not feasible."""
    vs = summary.get("violations") or []
    out = [f"  NOT FEASIBLE: {len(vs)} violation(s) (summary.json 'violations'):"]
    for v in vs[:max_lines]:
        what = (f"{v['arm']}/{v['link']} and {v['other']}" if v["kind"] == "collision"
                else f"{v['arm']} joint {v['joint']}")
        out.append(f"    {v['kind']}: {what} from t = {v['t_first']:.4g} s, value "
                   f"{v['value']:.4g} (limit {v['limit']:.4g})")
    if len(vs) > max_lines:
        out.append(f"    ... {len(vs) - max_lines} more")
    return out


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


__all__ = [
    "REPLAY_FPS",
    "feasibility_lines",
    "REQUIRED_ARRAYS",
    "load_run",
    "force_names",
    "plot_names",
    "replay_parts",
    "run_status",
    "scenario_copy",
    "summarize",
    "trajectory_arrays",
]
