#!/usr/bin/env python
"""Benchmark: the n-arm closed-loop table of this checkout against an earlier commit (issue 24).

``closed_loop.py``'s weld table (``n`` UR5s welded to one box, ``object_pd``) is measured
in a ``git worktree`` of ``--base`` and in this checkout, one process after the other in the
order base, this, this, base for each round, so that a machine that speeds up or slows down
during the run weighs on both alike. Each process loads its kernels from its own tree's
numba cache (a first quick run of each fills it; its compile is not timed). The report gives
each case's medians over the processes of each side and their ratio (this / base).

Columns (``closed_loop.py``'s): ``closed`` = one evaluation called from Python
(``ContactLoop.evaluate``), ``in run`` = the wall time of a whole ``simulate`` run
divided by its evaluations (what a run costs per evaluation), ``RTF`` = simulated time /
wall time of that run.

Usage::

    .venv/bin/python benchmarks/closed_loop_pairs.py --base 22f1fde --out benchmarks/results
"""

from __future__ import annotations

import argparse
import csv
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from benchmarks._machine import commit, run_line  # noqa: E402

COLUMNS = (("t_closed_s", "closed [us]", 1e6), ("t_closed_run_s", "in run [us]", 1e6),
           ("t_open_s", "open [us]", 1e6), ("rtf", "RTF", 1.0))


def _options(tree: Path) -> list[str]:
    """The options that keep ``tree``'s ``closed_loop.py`` to its weld table (older ones
    have no feasibility rows to turn off)."""
    helps = subprocess.run([sys.executable, "benchmarks/closed_loop.py", "--help"], cwd=tree,
                           capture_output=True, text=True, check=True,
                           env=dict(os.environ, PYTHONPATH=str(tree)))
    return ["--feasibility="] if "--feasibility" in helps.stdout else []


def _measure(tree: Path, extra: list[str], out: Path, quick: bool = False) -> list[dict]:
    """``closed_loop.py`` of ``tree`` (weld table and ``two_ur5_box`` only) into ``out``."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    args = ["--quick"] if quick else ["--no-cold", "--scenarios", "two_ur5_box"]
    subprocess.run([sys.executable, "benchmarks/closed_loop.py", *args, *extra, "--out",
                    str(out)], cwd=tree, check=True, capture_output=True, env=env)
    with open(out / "closed_loop.csv", newline="") as f:
        return [r for r in csv.DictReader(f) if r["case"].startswith("weld")]


def report(base: str, rounds: int, sides: dict[str, list[list[dict]]], command: str) -> str:
    """The Markdown report: per arm count, each side's medians and this / base."""
    lines = ["# Closed-loop table against an earlier commit (issue 24)", "",
             f"Command: `{command}`  ", f"Run: {run_line()}  ",
             f"Base: {base}; this: {commit()}; {rounds} rounds of (base, this, this, base), "
             "each a fresh process.", "",
             "Medians over the processes of each side; ratio = this / base (below 1: faster).",
             "", "| n | " + " | ".join(f"{h} base | {h} this | ratio" for _, h, _ in COLUMNS)
             + " |", "|---|" + "---|---|---|" * len(COLUMNS)]
    for i, row in enumerate(sides["base"][0]):
        cells = [row["n_arms"]]
        for key, _, scale in COLUMNS:
            b = statistics.median(float(run[i][key]) for run in sides["base"]) * scale
            t = statistics.median(float(run[i][key]) for run in sides["this"]) * scale
            cells += [f"{b:.1f}" if scale > 1 else f"{b:.2f}",
                      f"{t:.1f}" if scale > 1 else f"{t:.2f}", f"{t / b:.2f}"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--base", required=True, help="the commit to compare with")
    p.add_argument("--rounds", type=int, default=1, help="rounds of (base, this, this, base)")
    p.add_argument("--out", type=Path, default=None, help="folder of closed_loop_pairs.md")
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        tree = work / "base"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree),
                        args.base], check=True, capture_output=True)
        try:
            trees = {"base": tree, "this": ROOT}
            extra = {name: _options(where) for name, where in trees.items()}
            for name, where in trees.items():  # fill each tree's cache
                _measure(where, extra[name], work / f"warm-{name}", quick=True)
            sides: dict[str, list[list[dict]]] = {"base": [], "this": []}
            for r in range(args.rounds):
                for i, name in enumerate(("base", "this", "this", "base")):
                    sides[name].append(_measure(trees[name], extra[name],
                                                work / f"{r}-{i}-{name}"))
                    print(f"round {r + 1}, {name}: done", flush=True)
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)],
                           capture_output=True)
    text = report(args.base, args.rounds,
                  sides, "benchmarks/closed_loop_pairs.py " + " ".join(argv or sys.argv[1:]))
    print(text)
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "closed_loop_pairs.md").write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
