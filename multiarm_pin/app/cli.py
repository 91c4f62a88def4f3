"""The ``multiarm-pin`` command line.

Subcommands:
    ``run SCENARIO.yaml``   simulate a scenario, write results, plots and a replay page
    ``replay DIR``          serve the replay of a finished run from a Meshcat server
    ``grasp FILE.yaml``     grasp analysis report (form closure, margin, seventh contact)
    ``sweep STUDY.yaml``    a study (sweep / Monte Carlo) of a scenario or grasp, on Dask
    ``design SPEC.yaml``    find where the arms and the contacts go: ranked scenarios
    ``demo``                run the shipped default scenario (the README's main command)
    ``scenarios``           list the shipped scenario, grasp and study files
    ``info [SCENARIO]``     a scenario's (or two default arms') key quantities

The argument parsing of ``run``, ``replay``, ``demo`` and ``scenarios`` lives here; the work is
done by :mod:`multiarm_pin.app.runner` (``grasp``, ``sweep`` and ``design`` bring their own
parsers from :mod:`multiarm_pin.app.grasp_cli`, :mod:`multiarm_pin.study.cli` and
:mod:`multiarm_pin.design.cli`).

Twins: ``multiarm_pin.design.cli`` and ``multiarm_pin.study.cli`` (the same role one package
down: each is its package's subcommand of this command line, ``design`` and ``sweep``, whose
``configure_parser`` and ``run`` this module wires in).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from multiarm_pin.app import REPLAY_FPS
from multiarm_pin.data import DEMO_SCENARIO, data_path, shipped_files
from multiarm_pin.exceptions import (
    MultiArmError,
    ResultsNotMovedError,
    RunFailedError,
    RunInterrupted,
)

# The work of each subcommand (numpy, Pinocchio, the compiled kernels, meshcat, Dask...) is
# imported by the subcommand, so `multiarm-pin --help` or a bad argument answers at once.


def _info(args: argparse.Namespace) -> int:
    """Print the key quantities of a scenario's arms and object (or of a default pair).

    With a scenario file: its arms (robot, tool frame, the arm's joints with their types, the
    joint to the object), built and placed as ``run`` builds them (q0 given or found by
    inverse kinematics), the object, and the supports. Without one: a UR5 and a Panda beside a
    4 kg box.
    """
    import numpy as np

    np.set_printoptions(precision=4, suppress=True)
    if getattr(args, "scenario", None):
        return _info_scenario(args.scenario)
    import pinocchio as pin

    from multiarm_pin.model.arm import Arm
    from multiarm_pin.model.rigid_object import ObjectState, RigidObject

    arms = [
        Arm.from_robot_name(
            "ur5", name="left", base_placement=pin.SE3(np.eye(3), np.array([0.0, 0.5, 0.0]))
        ),
        Arm.from_robot_name(
            "panda", name="right", base_placement=pin.SE3(np.eye(3), np.array([0.0, -0.5, 0.0]))
        ),
    ]
    q0 = {"left": np.array([0.0, -1.2, 1.6, -0.4, 1.57, 0.0])}
    for arm in arms:
        _print_arm(arm, q0.get(arm.name, arm.neutral()))
    obj = RigidObject.box([0.8, 0.4, 0.3], 4.0)
    print("object: box 0.8 x 0.4 x 0.3 m, 4 kg")
    _print_object(obj, ObjectState.create([0.6, 0.0, 0.4]), np.array([0, 0, -9.81]))
    return 0


def _print_arm(arm, q, joints: bool = False, joint_to_object: str = "", q_source: str = "") -> None:
    """The key quantities of one arm at ``q`` (its base and joints with their types when asked)."""
    import numpy as np

    t = arm.terms(q, np.zeros(arm.nv))
    print(f"arm {arm.name} ({arm.source}): nq={arm.nq} nv={arm.nv} tool={arm.tool_frame}")
    if joints:
        print(f"  base position [m] = {arm.base_placement.translation}")
        m = arm.model
        kinds = [f"{m.names[j]} ({_joint_kind(m.joints[j].shortname())})"
                 for j in range(1, m.njoints)]
        print(f"  joints: {', '.join(kinds)}")
    if joint_to_object:
        print(f"  joint to the object: {joint_to_object}")
    print(f"  q = {q}" + (f" ({q_source})" if q_source else ""))
    print(f"  tool position [m] = {t.tool_position}")
    print(f"  mass matrix diagonal [kg m^2] = {np.diag(t.M)}")
    print(f"  gravity torque [N m] = {t.gravity}")
    print(f"  cond(J M^-1 J^T) = {t.Lambda_condition:.3g}")
    if t.has_operational_space_inertia:
        print(f"  operational-space inertia diag = {np.diag(t.Lambda)}")


def _joint_kind(shortname: str) -> str:
    """Pinocchio's joint model name in words (``JointModelRZ`` -> ``revolute z``)."""
    import re

    name = shortname.removeprefix("JointModel")
    words = {"R": "revolute", "P": "prismatic", "RUB": "continuous"}
    m = re.fullmatch(r"(RUB|R|P)([XYZ])", name)
    if m:
        return f"{words[m.group(1)]} {m.group(2).lower()}"
    return {"RevoluteUnaligned": "revolute (axis)", "PrismaticUnaligned": "prismatic (axis)",
            "RevoluteUnboundedUnaligned": "continuous (axis)"}.get(name, name.lower())


def _print_object(obj, state, gravity) -> None:
    """Inertia, ``M_o`` and the gravity wrench ``h_o`` of the object at ``state``."""
    import numpy as np

    print(f"  inertia about COM [kg m^2] = {np.diag(obj.inertia)}")
    print(f"  M_o diagonal = {np.diag(obj.mass_matrix(state.rotation))}")
    h_o = obj.bias_wrench(state.rotation, state.twist, gravity)
    print(f"  h_o (gravity wrench) = {h_o}")


def _info_scenario(path: str) -> int:
    """``multiarm-pin info SCENARIO``: build the scenario as ``run`` does and describe it."""
    from multiarm_pin.app.scenario import build_scenario, load_scenario

    sc = load_scenario(path)
    built = build_scenario(sc, load_visuals=False)
    print(f"scenario {sc.name} ({sc.file}): {len(sc.arms)} arm(s), {len(sc.supports)} "
          f"support(s), gravity {sc.gravity} m/s^2")
    for spec, arm, q, ik in zip(sc.arms, built.arms, built.q0, built.ik, strict=True):
        joint = spec.joint.type
        if spec.joint.contacts:
            joint += " (" + ", ".join(f"{c.tip} on {c.face}" for c in spec.joint.contacts) + ")"
        _print_arm(arm, q, joints=True, joint_to_object=joint,
                   q_source="q0 of the file" if ik is None else "found by inverse kinematics")
    o = sc.object
    shape = (f"box {' x '.join(f'{x:g}' for x in o.size)} m" if o.shape_type == "box"
             else f"polyhedron of {len(o.vertices)} vertices")
    print(f"object: {shape}, {o.mass:g} kg, at {o.position} m")
    _print_object(built.obj, built.initial_state.obj, sc.gravity)
    for s in sc.supports:
        points = ("the object's vertices" if isinstance(s.points, str)
                  else f"{len(s.points)} object points")
        print(f"support {s.name}: plane through {s.point} m, normal {s.normal}, contacts at "
              f"{points}, restitution {s.restitution:g}")
    return 0


def _version() -> str:
    """The installed package version (the source tree's when not installed)."""
    from multiarm_pin import __version__

    return __version__


def _command(argv: Sequence[str]) -> str:
    """The subcommand named in ``argv`` (its first positional argument), or ``""``."""
    return next((a for a in argv if not a.startswith("-")), "")


def _build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of ``multiarm-pin``.

    Args:
        command: the subcommand about to run: the ``grasp`` and ``sweep`` arguments (whose
            modules import the grasp analysis and the study packages) are added only for it;
            None adds every subcommand's arguments.
    """
    parser = argparse.ArgumentParser(
        prog="multiarm-pin",
        description="Multi-arm manipulation of large objects: grasp analysis, dynamics, replay.",
        epilog="exit codes: 0 done, 1 run failed (partial results kept), 2 bad input, "
               "130 interrupted (partial results kept)",
    )
    parser.add_argument("--version", action="version",
                        version=f"%(prog)s {_version()}")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("grasp", help="grasp analysis of a YAML grasp file")
    if command in (None, "grasp"):
        from multiarm_pin.app import grasp_cli

        grasp_cli.configure_parser(p)
        p.set_defaults(func=grasp_cli.run)

    p = sub.add_parser("run", help="simulate a scenario file")
    configure_run_parser(p)
    p.set_defaults(func=run_command)
    p = sub.add_parser("replay", help="serve the replay of a finished run")
    configure_replay_parser(p)
    p.set_defaults(func=replay_command)
    p = sub.add_parser("sweep", help="run a study (sweep / Monte Carlo) on Dask")
    if command in (None, "sweep"):
        from multiarm_pin.study import cli as study_cli

        study_cli.configure_parser(p)
        p.set_defaults(func=study_cli.run)
    p = sub.add_parser("design", help="find where the arms and the contacts go (ranked "
                       "scenarios, a report, the best design's run)")
    if command in (None, "design"):
        from multiarm_pin.design import cli as design_cli

        design_cli.configure_parser(p)
        p.set_defaults(func=design_cli.run)
    p = sub.add_parser("demo", help=f"run the shipped default scenario ({DEMO_SCENARIO})")
    p.add_argument("--out", default="results/demo", help="output folder (default results/demo)")
    p.add_argument("--duration", type=float, default=None, help="override the duration [s]")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--overwrite", action="store_true",
                   help="replace a results folder of another scenario file")
    p.set_defaults(func=_demo)
    p = sub.add_parser("scenarios", help="list the shipped scenario, grasp, study and design "
                       "files")
    p.set_defaults(func=_scenarios)

    p = sub.add_parser("info", help="print the key quantities of a scenario's arms and object "
                       "(default: two arms and a box)")
    p.add_argument("scenario", nargs="?", default=None, metavar="SCENARIO",
                   help="scenario YAML file: its arms, tool frames, joints, object and supports")
    p.set_defaults(func=_info)
    p = sub.add_parser("precompile", help="optional: run the shipped scenarios once each so "
                       "that numba compiles and caches their kernels (`make precompile`): "
                       "their first runs then compile nothing")
    p.add_argument("--scenarios", nargs="+", default=None, metavar="NAME",
                   help="only these shipped scenarios (default: all)")
    p.set_defaults(func=_precompile)
    return parser


def _precompile(args: argparse.Namespace) -> int:
    """``multiarm-pin precompile``: :mod:`multiarm_pin.app.precompile`."""
    from multiarm_pin.app import precompile

    return precompile.main([] if args.scenarios is None else ["--scenarios", *args.scenarios])


def _demo(args: argparse.Namespace) -> int:
    """``multiarm-pin demo``: ``run`` on the shipped default scenario, from any folder."""
    ns = argparse.Namespace(
        scenario=str(data_path("scenarios", DEMO_SCENARIO)),
        out=args.out,
        solver=None,
        duration=args.duration,
        quiet=args.quiet,
        overwrite=args.overwrite,
    )
    return run_command(ns)


def _scenarios(args: argparse.Namespace) -> int:
    """``multiarm-pin scenarios``: the shipped files, with their descriptions."""
    from multiarm_pin.yaml_reader import load_yaml_file

    for folder, command in (("scenarios", "run"), ("scenarios/grasps", "grasp"),
                            ("scenarios/studies", "sweep"), ("scenarios/designs", "design")):
        print(f"{folder} (multiarm-pin {command} FILE): {data_path(*folder.split('/'))}")
        for f in shipped_files(folder):
            data = load_yaml_file(f)
            text = data.get("description", "") if isinstance(data, dict) else ""
            line = " ".join(str(text).split())
            print(f"  {f.name:<32} {line if len(line) <= 72 else line[:69] + '...'}")
    return 0


# ----------------------------------------------------------------------------- run, replay
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
        0 for a complete run, 1 for a run that failed after its simulation started (or whose
        results could not be moved into ``--out``: the message says where they are kept), 130
        for an interrupted run (Ctrl-C, SIGTERM); partial results are written in each case.
    """
    from multiarm_pin.app.runner import run_scenario

    html = getattr(args, "html", True)
    try:
        res = run_scenario(args.scenario, args.out, args.solver, args.duration,
                           quiet=bool(args.quiet), html=html,
                           overwrite=bool(getattr(args, "overwrite", False)))
    except ResultsNotMovedError as exc:  # the run finished; its results are kept elsewhere
        print(f"error: {exc}", file=sys.stderr)
        print(f"results kept in: {exc.kept}", file=sys.stderr)
        return 1
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
        kinds = ", ".join(sorted({str(e.get("kind")) for e in s["events"]}))
        print(f"  {len(s['events'])} contact events ({kinds}); first: "
              f"{e0['kind']} of {e0['label']} at t = {e0['t']:.4g} s")
    if s.get("feasible") is False:
        from multiarm_pin.app.run_results import feasibility_lines

        for line in feasibility_lines(s):
            print(line)
    for w in s["warnings"][:10]:
        print(f"  warning: {w}")
    if len(s["warnings"]) > 10:
        print(f"  ... {len(s['warnings']) - 10} more warnings in summary.json")
    print(f"results: {out}")
    print(f"  trajectory: {out / 'trajectory.npz'}")
    print(f"  summary:    {out / 'summary.json'}")
    pngs = [p.name for p in res.files.values() if p.suffix == ".png"]
    if pngs:
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
    from multiarm_pin.app.replay_phases import phase_table, replay_phases
    from multiarm_pin.app.run_results import load_run, run_status
    from multiarm_pin.app.runner import http_status, serve_run

    sc, traj, summary = load_run(args.dir)
    phases = phase_table(replay_phases(sc, traj), float(traj["t"][-1]))
    if summary.get("status", "complete") != "complete":
        print(f"note: {Path(args.dir).resolve()} holds a {run_status(summary)}; replaying what "
              "was simulated", flush=True)
    url, vis = serve_run(args.dir, fps=args.fps, open_browser=bool(getattr(args, "open", False)))
    try:
        print(f"replay of {Path(args.dir).resolve()} ({run_status(summary).split(':')[0]}) "
              f"served at {url}", flush=True)
        if phases:  # the live viewer has no overlay: the phases are listed here
            print(f"phases ({sc.controller.type}; replay.html shows them on its timeline):")
            for p in phases:
                press = ", ".join(p["press"]) or "none"
                print(f"  {p['t']:8.3f} - {p['end']:8.3f} s  {p['name']} ({p['kind']}, motion "
                      f"until {p['motion_end']:.3f} s), supports pressing: {press}"
                      + (f", released: {', '.join(p['release'])}" if p["release"] else ""))
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


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``multiarm-pin``; returns the exit code.

    0 done; 1 a run failed after its simulation started; 2 bad input (the message names the
    file, the key path and what was expected); 130 interrupted (Ctrl-C).
    """
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = _build_parser(_command(argv))
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except MultiArmError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader of our output stopped (`| head`): not an error of ours
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":
    sys.exit(main())
