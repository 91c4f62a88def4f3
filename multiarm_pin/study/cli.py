"""``multiarm-pin sweep STUDY.yaml --out DIR [--workers N | --scheduler ADDRESS] [--resume]``.

One concept at several layers: the subcommands of ``multiarm-pin`` above the application
shell (``study/cli.py``, ``design/cli.py``; the grasp analysis's is ``app/grasp_cli.py``) hold
their ``configure_parser`` and ``run``, which :mod:`multiarm_pin.app.cli`, the command line
at the top of the layers, wires into the one command line.

Twins: ``multiarm_pin.app.cli`` and ``multiarm_pin.design.cli`` (the same role, a package's
command line, in three packages: ``app.cli`` is the whole ``multiarm-pin`` command line, which
wires in this ``sweep`` subcommand and ``design.cli``'s ``design``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from multiarm_pin.exceptions import StudyError


def configure_parser(p: argparse.ArgumentParser) -> None:
    """Arguments of ``multiarm-pin sweep``."""
    p.add_argument("study", help="study YAML file (see scenarios/studies/)")
    p.add_argument("--out", required=True, help="results folder (rows, summaries, report)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--workers", type=int, default=2,
                   help="worker processes of the local Dask cluster (default 2)")
    g.add_argument("--scheduler", default=None,
                   help="address of an existing Dask scheduler (tcp://host:8786)")
    p.add_argument("--resume", action="store_true",
                   help="continue the study in --out (finished cases are never run again; "
                        "re-running without it skips them too)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    """Run the study, write the table and the report, print where they are."""
    from multiarm_pin.study.execution import Study
    from multiarm_pin.study.report import write_report
    from multiarm_pin.study.store import ResultsFolder

    study = Study.from_file(args.study)
    if args.scheduler is None and args.workers < 1:
        raise StudyError("--workers", "", f"expected a positive number of workers, got "
                         f"{args.workers}")
    out = Path(args.out)
    try:
        table = study.run(out=out, workers=args.workers, scheduler=args.scheduler,
                          resume=bool(args.resume), progress=not args.quiet)
    except KeyboardInterrupt:
        done = len(ResultsFolder(out).finished(study.cases)) if out.is_dir() else 0
        print(f"interrupted: {done} of {len(study.cases)} cases finished and kept in "
              f"{out.resolve()}; continue with: multiarm-pin sweep {args.study} --out "
              f"{args.out} --resume", file=sys.stderr)
        return 130
    report = write_report(out, study.spec, table)
    status = table.column("status").to_pylist()
    n_ok = sum(1 for s in status if s == "ok")
    print(f"study {study.spec.name}: {len(status)} cases, {n_ok} ran, "
          f"{len(status) - n_ok} failed")
    print(f"table:  {(out / 'results.parquet').resolve()}")
    print(f"report: {report.resolve()}")
    return 0
