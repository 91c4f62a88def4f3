"""``multiarm-pin design SPEC.yaml --out DIR [--workers N | --scheduler ADDRESS] [--seed S]``.

One concept at several layers: each layer's ``cli.py`` (``study``, ``design``; the grasp
analysis's is ``app/grasp_cli.py``) holds its own subcommand of ``multiarm-pin``
(``configure_parser`` and ``run``), which :mod:`multiarm_pin.app.cli` wires into the one
command line.

Twins: ``multiarm_pin.app.cli`` and ``multiarm_pin.study.cli`` (the same role, a package's
command line, in three packages: ``app.cli`` is the whole ``multiarm-pin`` command line, which
wires in this ``design`` subcommand and ``study.cli``'s ``sweep``).
"""

from __future__ import annotations

import argparse
import sys


def configure_parser(p: argparse.ArgumentParser) -> None:
    """Arguments of ``multiarm-pin design``."""
    p.add_argument("spec", help="design spec YAML file (see scenarios/designs/)")
    p.add_argument("--out", required=True, help="results folder (designs, report, best run)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--workers", type=int, default=2,
                   help="worker processes of the local Dask cluster (default 2; 1: no Dask)")
    g.add_argument("--scheduler", default=None,
                   help="address of an existing Dask scheduler (tcp://host:8786)")
    p.add_argument("--seed", type=int, default=None, help="overrides the spec's search.seed")
    p.add_argument("--no-run", dest="simulate", action="store_false",
                   help="do not simulate the best design")
    p.add_argument("--overwrite", action="store_true",
                   help="replace a results folder of another spec file")
    p.add_argument("--quiet", action="store_true", help="no progress lines")


def run(args: argparse.Namespace) -> int:
    """Search, write the results folder, print the ranking; exit 1 for an impossible spec."""
    from multiarm_pin.design.report import write_design
    from multiarm_pin.design.search import run_design
    from multiarm_pin.design.spec import load_design
    from multiarm_pin.exceptions import DesignError, DesignImpossibleError

    spec = load_design(args.spec)
    if args.scheduler is None and args.workers < 1:
        raise DesignError("--workers", "", f"expected a positive number of workers, got "
                          f"{args.workers}")

    def say(line: str) -> None:
        if not args.quiet:
            print(f"design {spec.name}: {line}", file=sys.stderr, flush=True)

    if spec.pick_up is not None:
        from multiarm_pin.design.pick_up import use_tilt

        if use_tilt(spec):
            return _run_pick_up(spec, args, say)
        say("the supports leave an overhang fingertips reach (or an arm welds): the plain "
            "design search lifts the box (task strategy auto)")
    try:
        result = run_design(spec, workers=args.workers, scheduler=args.scheduler,
                            seed=args.seed, progress=say)
    except DesignImpossibleError as exc:
        print(f"impossible: {exc}", file=sys.stderr)
        return 1
    out = write_design(result, args.out, simulate=args.simulate,
                       overwrite=bool(args.overwrite), quiet=True)
    print(f"design {spec.name}: {result.evaluated} candidates in {result.wall_time:.1f} s, "
          f"{result.feasible} met every condition")
    for d in result.designs:
        s = ", ".join(f"{k} {v:.4g}" for k, v in d.scores.items() if v is not None)
        print(f"  {d.rank}. candidate {d.index}: objective {d.objective:.4g} ({s})")
    _print_folder(out, args.simulate)
    return 0


def _print_folder(out, simulated: bool) -> None:
    """Where the results folder holds the designs, the report and the best run."""
    print(f"designs: {out / 'designs'}")
    print(f"report:  {out / 'report.md'}")
    if simulated:
        print(f"best run: {out / 'best_run'} (replay: {out / 'best_run' / 'replay.html'})")


def _run_pick_up(spec, args: argparse.Namespace, say) -> int:
    """A pick-up by tilting (:mod:`.pick_up`): plan, write the folder, print the plans."""
    from multiarm_pin.design.pick_up import describe_plan, plan_pick_up
    from multiarm_pin.design.report import write_pick_up
    from multiarm_pin.exceptions import DesignImpossibleError

    try:
        result = plan_pick_up(spec, seed=args.seed, progress=say)
    except DesignImpossibleError as exc:
        print(f"impossible: {exc}", file=sys.stderr)
        return 1
    out = write_pick_up(result, args.out, simulate=args.simulate,
                        overwrite=bool(args.overwrite), quiet=True)
    print(f"design {spec.name}: {len(result.checked)} tilt plans checked in "
          f"{result.wall_time:.1f} s, {len(result.plans)} met every check")
    for k, c in enumerate(result.plans[:spec.top], start=1):
        print(f"  {k}. candidate {c.candidate.index}: {describe_plan(c)}")
    _print_folder(out, args.simulate)
    return 0
