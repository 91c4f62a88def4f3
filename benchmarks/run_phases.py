#!/usr/bin/env python
"""Benchmark: wall time of each phase of ``multiarm-pin run`` on a scenario (issue 14).

Everything around the simulation is the user's wait too: starting the command (imports),
building the scenario, and writing each result file. Each round runs, in fresh processes:

- ``multiarm-pin --help`` and ``python -c 'import multiarm_pin.app.cli'`` (start-up);
- a child process that does what :func:`multiarm_pin.app.runner.run_scenario` does, phase by
  phase, timing each one: importing the runner, loading and building the scenario (meshes
  included), the controller, the simulation, ``trajectory.npz``, the plots (their imports
  included), the replay page (its imports included) and ``summary.json``, each alone;
- a second child that writes all the result files as the runner does after the simulation
  (``all result files (as run)``; ``around simulate (as run)`` adds the import, build and
  controller phases);
- the whole ``multiarm-pin run SCENARIO --out DIR --quiet`` (the figure the user sees).

Times are medians over ``--repeat`` rounds (the numba cache warmed first by one run). To
compare two checkouts, run this program once with each on ``PYTHONPATH`` (``--src DIR``
does it: ``DIR`` holds the ``multiarm_pin`` package to measure).

Usage::

    .venv/bin/python benchmarks/run_phases.py                      # demo, 5 rounds, ~2 min
    .venv/bin/python benchmarks/run_phases.py --repeat 3 --src /tmp/base --out /tmp/before
    .venv/bin/python benchmarks/run_phases.py --compare /tmp/before/run_phases.json \
        /tmp/after/run_phases.json                                 # before / after ratios
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_SCENARIO = ROOT / "scenarios" / "two_ur5_box.yaml"
PHASES = ("import", "build", "controller", "simulate", "trajectory", "plots", "replay",
          "summary")
"""Phases timed inside the child process, in order."""


def child(scenario: str, out: str, duration: float | None, as_run: bool = False) -> dict:
    """Run the phases of ``run_scenario`` in this (fresh) process; wall time [s] of each.

    ``as_run``: after the simulation, time the runner's own writing of every result file
    and their move into place (``runner._write_results``) instead of each file alone.
    """
    times = {}
    t = time.perf_counter()
    import numpy as np

    from multiarm_pin.app import runner
    from multiarm_pin.app.run_results import (
        REPLAY_FPS,
        replay_parts,
        summarize,
        trajectory_arrays,
    )
    from multiarm_pin.app.scenario import build_scenario, load_scenario
    times["import"] = time.perf_counter() - t

    t = time.perf_counter()
    sc = load_scenario(scenario)
    built = build_scenario(sc, load_visuals=True)
    times["build"] = time.perf_counter() - t
    t = time.perf_counter()
    controller = runner.scenario_controller(built)
    times["controller"] = time.perf_counter() - t
    T = duration if duration is not None else sc.simulation.duration
    t = time.perf_counter()
    result = runner.simulate_built(built, controller, T, sc.simulation.dt, sc.simulation.solver)
    times["simulate"] = time.perf_counter() - t
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    if as_run:
        t = time.perf_counter()
        with runner.ResultsWriter(folder, sc.file, overwrite=True) as writer, \
                runner._RunSignals() as signals:
            signals.hold()
            runner._write_results(writer, signals, built, result, sc.simulation.solver,
                                  times["simulate"], T, sc, True, True, "complete", None, [],
                                  True)
        times["all result files (as run)"] = time.perf_counter() - t
        return times
    t = time.perf_counter()
    traj = trajectory_arrays(built, result)
    np.savez(folder / "trajectory.npz", **traj)  # uncompressed, as the runner writes it
    times["trajectory"] = time.perf_counter() - t
    t = time.perf_counter()
    from multiarm_pin.app.plots import write_plots

    write_plots(folder, traj, [a.name for a in built.arms], sc.name,
                [sp.name for sp in built.system.supports.supports])
    times["plots"] = time.perf_counter() - t
    t = time.perf_counter()
    from multiarm_pin.app.replay import write_replay_html

    rarms, robj, rc = replay_parts(built.arms, built.obj, traj)
    write_replay_html(folder / "replay.html", rarms, robj, traj["t"], rc, fps=REPLAY_FPS)
    times["replay"] = time.perf_counter() - t
    t = time.perf_counter()
    summary = summarize(built, result, sc.simulation.solver, times["simulate"])
    (folder / "summary.json").write_text(json.dumps(summary, indent=2), encoding="utf-8")
    times["summary"] = time.perf_counter() - t
    return times


def _wall(cmd: list[str], env: dict) -> float:
    t = time.perf_counter()
    subprocess.run(cmd, check=True, env=env, stdout=subprocess.DEVNULL,
                   cwd=env["RUN_PHASES_CWD"])
    return time.perf_counter() - t


def _child(args, env: dict, out: str, as_run: bool) -> dict:
    cmd = [sys.executable, __file__, "--scenario", args.scenario, "--child", out,
           *([] if args.duration is None else ["--duration", str(args.duration)]),
           *(["--as-run"] if as_run else [])]
    text = subprocess.run(cmd, check=True, env=env, capture_output=True, text=True,
                          cwd=env["RUN_PHASES_CWD"]).stdout
    return json.loads(text.strip().splitlines()[-1])


def compare_table(before: dict, after: dict) -> str:
    """Markdown table of two ``run_phases.json`` medians: before, after, before / after."""
    lines = [f"before: {before['package']}", f"after: {after['package']}", "",
             "| phase | before [s] | after [s] | before / after |", "|---|---|---|---|"]
    for k, a in after["median"].items():
        b = before["median"].get(k)
        if b is None:
            lines.append(f"| {k} | - | {a:.3f} | - |")
        else:
            lines.append(f"| {k} | {b:.3f} | {a:.3f} | {b / a:.2f}x |" if a > 0 else
                         f"| {k} | {b:.3f} | {a:.3f} | - |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    """Measure, print a table and write ``run_phases.json`` / ``.md`` into ``--out``."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scenario", default=str(DEFAULT_SCENARIO))
    p.add_argument("--duration", type=float, default=None, help="override [s]")
    p.add_argument("--repeat", type=int, default=5, help="rounds (medians)")
    p.add_argument("--src", default=None, help="folder holding the multiarm_pin to measure")
    p.add_argument("--out", default=None, help="folder for run_phases.json and .md")
    p.add_argument("--compare", nargs=2, metavar=("BEFORE", "AFTER"), default=None,
                   help="print the table of two run_phases.json files (no measurement)")
    p.add_argument("--child", default=None, help=argparse.SUPPRESS)
    p.add_argument("--as-run", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.compare:
        before, after = (json.loads(Path(f).read_text()) for f in args.compare)
        print(compare_table(before, after), end="")
        return 0
    if args.child is not None:
        print(json.dumps(child(args.scenario, args.child, args.duration, args.as_run)))
        return 0

    env = dict(os.environ)
    py = sys.executable
    args.scenario = str(Path(args.scenario).resolve())
    with tempfile.TemporaryDirectory() as tmp:
        env["RUN_PHASES_CWD"] = tmp  # not the checkout: `python -c` would import from it
        if args.src:  # that package first; an editable install's finder would shadow it
            Path(tmp, "sitecustomize.py").write_text(_SHADOW_EDITABLE)
            env["PYTHONPATH"] = os.pathsep.join(
                [tmp, str(Path(args.src).resolve()), *filter(None, [env.get("PYTHONPATH")])])
        return _measure(args, env, py, tmp)


_SHADOW_EDITABLE = """import sys
sys.meta_path[:] = [f for f in sys.meta_path
                    if not getattr(f, "__module__", "").startswith("__editable__")]
"""


def _measure(args, env: dict, py: str, tmp: str) -> int:
    """Run the rounds in ``tmp``, print and write the table."""
    cli = str(Path(py).parent / "multiarm-pin")
    src = subprocess.run([py, "-c", "import multiarm_pin; print(multiarm_pin.__file__)"],
                         env=env, check=True, capture_output=True, text=True,
                         cwd=tmp).stdout.strip()
    dur = [] if args.duration is None else ["--duration", str(args.duration)]
    rows: dict[str, list[float]] = {}
    run_cmd = [cli, "run", args.scenario, "--quiet", "--overwrite", *dur]
    _wall([*run_cmd, "--out", f"{tmp}/warm"], env)  # fills the numba cache
    for r in range(args.repeat):
        rows.setdefault("cli --help", []).append(_wall([cli, "--help"], env))
        rows.setdefault("import cli", []).append(
            _wall([py, "-c", "import multiarm_pin.app.cli"], env))
        for k, v in _child(args, env, f"{tmp}/child{r}", False).items():
            rows.setdefault(k, []).append(v)
        as_run = _child(args, env, f"{tmp}/as_run{r}", True)
        rows.setdefault("all result files (as run)", []).append(
            as_run["all result files (as run)"])
        rows.setdefault("around simulate (as run)", []).append(
            sum(v for k, v in as_run.items() if k != "simulate"))
        rows.setdefault("run (whole command)", []).append(
            _wall([*run_cmd, "--out", f"{tmp}/run{r}"], env))
    med = {k: statistics.median(v) for k, v in rows.items()}
    lines = [f"# `multiarm-pin run` phases: {Path(args.scenario).name}",
             "",
             f"package {src}; {platform.node()}, {os.cpu_count()} CPUs, "
             f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; median of "
             f"{args.repeat} rounds, warm numba cache",
             "", "| phase | median [s] | min [s] | max [s] |", "|---|---|---|---|"]
    for k, v in rows.items():
        lines.append(f"| {k} | {med[k]:.3f} | {min(v):.3f} | {max(v):.3f} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        o = Path(args.out)
        o.mkdir(parents=True, exist_ok=True)
        (o / "run_phases.json").write_text(json.dumps({"package": src, "rounds": rows,
                                                       "median": med}, indent=2))
        (o / "run_phases.md").write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
