"""The ``multiarm-pin`` command line.

Subcommands:
    ``run SCENARIO.yaml``   simulate a scenario, write results, plots and a replay page
    ``replay DIR``          serve the replay of a finished run from a Meshcat server
    ``grasp FILE.yaml``     grasp analysis report (form closure, margin, seventh contact)
    ``sweep STUDY.yaml``    a study (sweep / Monte Carlo) of a scenario or grasp, on Dask
    ``demo``                run the default scenario (the README's main command)
    ``info``                load arms and an object and print their key quantities
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from multiarm_pin.exceptions import MultiArmError

REPO_ROOT = Path(__file__).resolve().parents[2]
DEFAULT_SCENARIO = REPO_ROOT / "scenarios" / "two_ur5_box.yaml"


def _info(args: argparse.Namespace) -> int:
    """Load two arms and an object and print their key quantities."""
    import pinocchio as pin

    from multiarm_pin.model.arm import Arm
    from multiarm_pin.model.rigid_object import ObjectState, RigidObject

    np.set_printoptions(precision=4, suppress=True)
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
        q = q0.get(arm.name, arm.neutral())
        t = arm.terms(q, np.zeros(arm.nv))
        print(f"arm {arm.name} ({arm.source}): nq={arm.nq} nv={arm.nv} tool={arm.tool_frame}")
        print(f"  q = {q}")
        print(f"  tool position [m] = {t.tool_position}")
        print(f"  mass matrix diagonal [kg m^2] = {np.diag(t.M)}")
        print(f"  gravity torque [N m] = {t.gravity}")
        print(f"  cond(J M^-1 J^T) = {t.Lambda_condition:.3g}")
        if t.has_operational_space_inertia:
            print(f"  operational-space inertia diag = {np.diag(t.Lambda)}")
    obj = RigidObject.box([0.8, 0.4, 0.3], 4.0)
    state = ObjectState.create([0.6, 0.0, 0.4])
    print("object: box 0.8 x 0.4 x 0.3 m, 4 kg")
    print(f"  inertia about COM [kg m^2] = {np.diag(obj.inertia)}")
    print(f"  M_o diagonal = {np.diag(obj.mass_matrix(state.rotation))}")
    h_o = obj.bias_wrench(state.rotation, state.twist, np.array([0, 0, -9.81]))
    print(f"  h_o (gravity wrench) = {h_o}")
    return 0


def _version() -> str:
    """The installed package version (the source tree's when not installed)."""
    from multiarm_pin import __version__

    return __version__


def _build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="multiarm-pin",
        description="Multi-arm manipulation of large objects: grasp analysis, dynamics, replay.",
        epilog="exit codes: 0 done, 1 run failed (partial results kept), 2 bad input, "
               "130 interrupted (partial results kept)",
    )
    parser.add_argument("--version", action="version",
                        version=f"%(prog)s {_version()}")
    sub = parser.add_subparsers(dest="command", required=True)

    from multiarm_pin.grasp import cli as grasp_cli

    p = sub.add_parser("grasp", help="grasp analysis of a YAML grasp file")
    grasp_cli.configure_parser(p)
    p.set_defaults(func=grasp_cli.run)

    from multiarm_pin.app import runner

    p = sub.add_parser("run", help="simulate a scenario file")
    runner.configure_run_parser(p)
    p.set_defaults(func=runner.run_command)
    p = sub.add_parser("replay", help="serve the replay of a finished run")
    runner.configure_replay_parser(p)
    p.set_defaults(func=runner.replay_command)
    from multiarm_pin.study import cli as study_cli

    p = sub.add_parser("sweep", help="run a study (sweep / Monte Carlo) on Dask")
    study_cli.configure_parser(p)
    p.set_defaults(func=study_cli.run)
    p = sub.add_parser("demo", help=f"run the default scenario ({DEFAULT_SCENARIO.name})")
    p.add_argument("--out", default="results/demo", help="output folder (default results/demo)")
    p.add_argument("--duration", type=float, default=None, help="override the duration [s]")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--overwrite", action="store_true",
                   help="replace a results folder of another scenario file")
    p.set_defaults(func=_demo)

    p = sub.add_parser("info", help="print key quantities of two arms and an object")
    p.set_defaults(func=_info)
    return parser


def _demo(args: argparse.Namespace) -> int:
    from multiarm_pin.app import runner

    ns = argparse.Namespace(
        scenario=str(DEFAULT_SCENARIO),
        out=args.out,
        solver=None,
        duration=args.duration,
        quiet=args.quiet,
        overwrite=args.overwrite,
    )
    return runner.run_command(ns)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``multiarm-pin``; returns the exit code.

    0 done; 1 a run failed after its simulation started; 2 bad input (the message names the
    file, the key path and what was expected); 130 interrupted (Ctrl-C).
    """
    parser = _build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except MultiArmError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
