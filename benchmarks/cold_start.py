#!/usr/bin/env python
"""Benchmark: the cold start, what a new user waits for before a first result (issue 24).

Two parts, written to ``--out`` as ``cold_start.md`` (commit, date, command, machine) and
``cold_start.json``:

- **Per shipped scenario** (``multiarm_pin/data/scenarios/*.yaml``): in a fresh process with
  its own empty ``NUMBA_CACHE_DIR``, the
  wall and CPU times of the scenario's first ``simulate`` (compilation included) and of a
  second one in the same process (warm); their difference is the compile time. Each runs
  with the monitors ``multiarm-pin run`` gives it (the collision scan, on a worker thread,
  and the scenario's ``stop`` policies), so the scan's kernels are compiled too. The kernels
  compile in this process and in child processes at once
  (``function_pointers.compile_all``, one process per core unless
  ``MULTIARM_PIN_COMPILE_PROCESSES`` says otherwise): the wall time is what a user waits;
  the CPU time counts every process (``time.process_time`` and the children's ``os.times``)
  and is the steadier figure on a shared machine. The warm run's real-time factor is by CPU
  time (one run: a rough figure; the speed benchmark is ``closed_loop.py``). Then, in a new
  process on the cache the first made, one ``simulate`` (``loaded``): the speed a user sees
  from ``multiarm-pin run`` once the kernels are compiled, loading them from the disk cache
  included; its real-time factor is by wall time.
- **Fresh clone** (``--fresh-clone``): ``git clone`` of this checkout's HEAD into a temporary
  folder, then the phases of ``make demo`` timed one by one: the venv and ``pip install``
  (the Makefile's install stamp), then ``multiarm-pin demo`` twice with an empty numba
  cache: the first (compile and run) minus the second (run) is the compilation. Needs
  ``python3.11`` (``--python``) and the package index.

Usage::

    .venv/bin/python benchmarks/cold_start.py --out benchmarks/results
    .venv/bin/python benchmarks/cold_start.py --scenarios two_ur5_box pick_from_table
    .venv/bin/python benchmarks/cold_start.py --fresh-clone --python python3.11
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
SCENARIOS = ROOT / "multiarm_pin" / "data" / "scenarios"

CHILD = """
import json, os, sys, time
from multiarm_pin._compiled.function_pointers import processes
from multiarm_pin.app.run_feasibility import check_initial_state, run_monitors
from multiarm_pin.app.runner import scenario_controller, simulate_built
from multiarm_pin.app.scenario import build_scenario, load_scenario

def cpu():
    t = os.times()
    return time.process_time() + t.children_user + t.children_system

built = build_scenario(load_scenario(sys.argv[1]), load_visuals=False)
sim = built.scenario.simulation
scene = check_initial_state(built)  # as `multiarm-pin run`: its collision scan runs beside
out = {"processes": processes()}
for key in sys.argv[2].split(","):
    c0, w0 = cpu(), time.perf_counter()
    result = simulate_built(built, scenario_controller(built), sim.duration, sim.dt, sim.solver,
                            monitors=run_monitors(built, scene))
    out[key + "_cpu"] = cpu() - c0
    out[key + "_wall"] = time.perf_counter() - w0
out["duration"] = sim.duration
out["events"] = len(result.events)
out["notes"] = list(getattr(result, "warnings", []) or [])[:3]
print(json.dumps(out))
"""


SHELL_ONLY = ("PYTHONPATH", "VIRTUAL_ENV", "PYTHONDONTWRITEBYTECODE")
"""Variables of the caller's shell the measured processes do not get: a user's do not have
them (with ``PYTHONDONTWRITEBYTECODE`` and a venv installed without bytecode, as pip's
``--no-compile`` leaves it, every process compiles its dependencies' Python sources again)."""


def _user_env() -> dict:
    return {k: v for k, v in os.environ.items() if k not in SHELL_ONLY}


def scenario_cold(path: Path) -> dict:
    """Compile and warm times of one scenario in a fresh process with an empty cache."""
    env = dict(_user_env(), PYTHONPATH=str(ROOT))
    with tempfile.TemporaryDirectory(prefix="numba-cold-") as cache:
        env["NUMBA_CACHE_DIR"] = cache
        procs = [subprocess.run([sys.executable, "-c", CHILD, str(path), keys], env=env,
                                capture_output=True, text=True, check=False)
                 for keys in ("first,warm", "loaded")]
    failed = [p for p in procs if p.returncode]
    if failed:
        return {"scenario": path.stem, "error": failed[0].stderr.strip().splitlines()[-1:]}
    row = json.loads(procs[0].stdout.strip().splitlines()[-1])
    loaded = json.loads(procs[1].stdout.strip().splitlines()[-1])
    row.update(loaded_cpu=loaded["loaded_cpu"], loaded_wall=loaded["loaded_wall"])
    row["scenario"] = path.stem
    row["compile_cpu"] = row["first_cpu"] - row["warm_cpu"]
    row["compile_wall"] = row["first_wall"] - row["warm_wall"]
    return row


def _timed(cmd: list[str], cwd: Path, env: dict) -> float:
    t0 = time.perf_counter()
    subprocess.run(cmd, cwd=cwd, env=env, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t0


def fresh_clone(python: str) -> dict:
    """Phases of ``make demo`` on a fresh clone of HEAD: install, compile, run [s, wall]."""
    tmp = Path(tempfile.mkdtemp(prefix="cold-clone-"))
    try:
        repo = tmp / "repo"
        subprocess.run(["git", "clone", "-q", str(ROOT), str(repo)], check=True)
        env = _user_env()
        env["NUMBA_CACHE_DIR"] = str(tmp / "numba-cache")
        out = {"install": _timed(["make", f"PYTHON={python}", "venv"], repo, env)}
        demo = [str(repo / ".venv" / "bin" / "multiarm-pin"), "demo"]
        first = _timed(demo + ["--out", str(tmp / "demo1")], repo, env)
        second = _timed(demo + ["--out", str(tmp / "demo2")], repo, env)
        out.update(compile=first - second, run=second, total=out["install"] + first)
        return out
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _git(*args: str) -> str:
    return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True,
                          check=False).stdout.strip()


def report(rows: list[dict], clone: dict | None, command: str) -> str:
    """The markdown report."""
    lines = ["# Cold start (issue 24)", "",
             f"Command: `{command}`  ",
             f"Commit: {_git('rev-parse', '--short', 'HEAD')} "
             f"({'dirty' if _git('status', '--porcelain', '--untracked-files=no') else 'clean'}); "
             f"date {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}  ",
             f"Machine: {platform.node()}, {platform.processor() or platform.machine()}, "
             f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} at the end; "
             f"Python {platform.python_version()}", ""]
    if clone is not None:
        lines += ["## Fresh clone, `make demo` [s, wall]", "",
                  "| venv and pip | compilation | demo run | total |", "|---|---|---|---|",
                  f"| {clone['install']:.0f} | {clone['compile']:.1f} | {clone['run']:.1f} | "
                  f"{clone['total']:.0f} |", ""]
    lines += ["## First run of each shipped scenario, empty numba cache", "",
              "Each in its own process and `NUMBA_CACHE_DIR`. compile = first run - warm run "
              "(same process). Compile processes (this one and its children): "
              f"{rows[0].get('processes', 1) if rows else 1}; compile CPU counts them all.", "",
              "| scenario | compile wall [s] | compile CPU [s] | warm run CPU [s] "
              "| warm run wall [s] | real time / warm CPU | new process, cached: wall [s] "
              "| real time / that wall | events |",
              "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['scenario']} | error: {r['error']} | | | | | | | |")
            continue
        lines.append(f"| {r['scenario']} | {r['compile_wall']:.1f} | {r['compile_cpu']:.1f} | "
                     f"{r['warm_cpu']:.3f} | {r['warm_wall']:.3f} | "
                     f"{r['duration'] / r['warm_cpu']:.1f}x | {r['loaded_wall']:.3f} | "
                     f"{r['duration'] / r['loaded_wall']:.1f}x | {r['events']} |")
    ok = [r for r in rows if "error" not in r]
    if ok:
        lines += ["", f"Largest compile: {max(r['compile_wall'] for r in ok):.1f} s wall, "
                  f"{max(r['compile_cpu'] for r in ok):.1f} s CPU (target: at most 20 s)."]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    """Command line (see the module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", nargs="*", default=None,
                        help="scenario names (default: every shipped one)")
    parser.add_argument("--fresh-clone", action="store_true", help="also time make demo")
    parser.add_argument("--python", default="python3.11", help="python for the fresh venv")
    parser.add_argument("--out", type=Path, default=None, help="folder for the report")
    args = parser.parse_args(argv)
    names = args.scenarios or sorted(p.stem for p in SCENARIOS.glob("*.yaml"))
    rows = []
    for name in names:
        row = scenario_cold(SCENARIOS / f"{name}.yaml")
        rows.append(row)
        print(json.dumps(row), flush=True)
    clone = fresh_clone(args.python) if args.fresh_clone else None
    text = report(rows, clone, "benchmarks/cold_start.py " + " ".join(argv or sys.argv[1:]))
    print(text)
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "cold_start.md").write_text(text, encoding="utf-8")
        (args.out / "cold_start.json").write_text(
            json.dumps({"scenarios": rows, "fresh_clone": clone}, indent=1), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
