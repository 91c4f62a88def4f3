#!/usr/bin/env python
"""Benchmark: a shipped scenario on the compiled contact loop against the Python stepper.

For each scenario: one warm-up run of each path (kernels compiled or loaded from the cache),
then ``--pairs`` interleaved pairs (compiled, reference) in this process; each run's wall
time, CPU time and real-time factor (simulated time over wall time), and whether the two
paths agree: the same events (kinds, contacts, times to within a step), the object's final
pose and the largest differences of the joint and object trajectories and the contact
forces. The reference path is the Python stepper with the controller's numpy reference
(``controller.compiled = False``: no kernel serves it, as a run with no kernel).

``--cold`` also measures the first run in a fresh process with an empty numba cache
(``NUMBA_CACHE_DIR`` a new folder): its CPU time, which is
nearly all compilation; and, for a ``phased_pd`` scenario, in another such process, the CPU
time of the first call of ``_compiled.phased.phased_torques`` once the evaluation kernels
are compiled (the kernel with those of its callees not compiled yet:
``planned_torques``, ``desired_acceleration``, the NNLS).

The report (``scenario_speed.md`` in ``--out``) gives the command, date, commit, machine and
load averages (a shared machine: wall times include others' work; ratios within one run).

Usage::

    .venv/bin/python benchmarks/scenario_speed.py --scenarios tilt_pick --pairs 2 --cold
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from benchmarks._machine import run_line  # noqa: E402

KERNEL = """
import time
from pathlib import Path
from multiarm_pin.app.runner import scenario_controller
from multiarm_pin.app.scenario import build_scenario, load_scenario
built = build_scenario(load_scenario(Path({path!r})), load_visuals=False)
s, x = built.system, built.initial_state
ctrl = scenario_controller(built)
ev = s.blocks(x)  # the evaluation kernels, compiled first
ctrl.prepare(x, ev)
c0 = time.process_time()
assert ctrl.compiled_torques(0.0, x, ev) is not None
print(time.process_time() - c0)
"""

COLD = """
import time, resource
from pathlib import Path
t0 = time.perf_counter()
from multiarm_pin.app.runner import scenario_controller, simulate_built
from multiarm_pin.app.scenario import build_scenario, load_scenario
built = build_scenario(load_scenario(Path({path!r})), load_visuals=False)
sim = built.scenario.simulation
res = simulate_built(built, scenario_controller(built), sim.duration, sim.dt, sim.solver)
print(time.perf_counter() - t0, resource.getrusage(resource.RUSAGE_SELF).ru_utime)
"""


def _run(built, compiled: bool):
    from multiarm_pin.app.runner import scenario_controller, simulate_built

    sim = built.scenario.simulation
    ctrl = scenario_controller(built)
    if not compiled and ctrl is not None:
        ctrl.compiled = False
    c0, t0 = time.process_time(), time.perf_counter()
    res = simulate_built(built, ctrl, sim.duration, sim.dt, sim.solver)
    return res, time.perf_counter() - t0, time.process_time() - c0


def _agreement(a, b, dt: float) -> str:
    ea = [(e.kind, e.label, e.t) for e in a.events]
    eb = [(e.kind, e.label, e.t) for e in b.events]
    same = [x[:2] for x in ea] == [x[:2] for x in eb]
    dt_max = max((abs(x[2] - y[2]) for x, y in zip(ea, eb, strict=False)), default=0.0)
    diffs = {name: float(np.abs(getattr(a, name) - getattr(b, name)).max())
             for name in ("q", "object_position", "object_quaternion", "mu")}
    return (f"{len(ea)} / {len(eb)} events, same kinds and contacts: {same}, times within "
            f"{dt_max:.2g} s ({dt_max / dt:.2g} steps); max |Δq| {diffs['q']:.2g} rad, "
            f"|Δp_o| {diffs['object_position']:.2g} m, |Δquat| "
            f"{diffs['object_quaternion']:.2g}, |Δμ| {diffs['mu']:.2g} N")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenarios", default="tilt_pick")
    p.add_argument("--pairs", type=int, default=2)
    p.add_argument("--cold", action="store_true")
    p.add_argument("--out", default="benchmarks/results")
    args = p.parse_args(argv)
    from multiarm_pin.app.scenario import build_scenario, load_scenario

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    lines = ["# Shipped scenarios: compiled contact loop against the Python stepper", "",
             f"Command: `python benchmarks/scenario_speed.py {' '.join(argv or sys.argv[1:])}`;"
             f" {run_line()}; load average at the start "
             f"{os.getloadavg()[0]:.1f} (a shared machine: wall times include others' work).",
             "", "| scenario | path | run | wall [s] | CPU [s] | real-time factor | load |",
             "|---|---|---|---|---|---|---|"]
    notes = []
    for name in args.scenarios.split(","):
        path = ROOT / "scenarios" / f"{name}.yaml"
        built = build_scenario(load_scenario(path), load_visuals=False)
        sim = built.scenario.simulation
        if args.cold:
            with tempfile.TemporaryDirectory() as cache:
                env = dict(os.environ, NUMBA_CACHE_DIR=cache, PYTHONPATH=str(ROOT))
                r = subprocess.run([sys.executable, "-c", COLD.format(path=str(path))],
                                   capture_output=True, text=True, env=env, cwd=str(ROOT))
                wall, cpu = (float(v) for v in r.stdout.split()[-2:])
                lines.append(f"| {name} | compiled, empty numba cache (first run) | 1 | "
                             f"{wall:.1f} | {cpu:.1f} | {sim.duration / wall:.2f} | "
                             f"{os.getloadavg()[0]:.1f} |")
            if built.scenario.controller and built.scenario.controller.type == "phased_pd":
                with tempfile.TemporaryDirectory() as cache:
                    env = dict(os.environ, NUMBA_CACHE_DIR=cache, PYTHONPATH=str(ROOT))
                    r = subprocess.run([sys.executable, "-c", KERNEL.format(path=str(path))],
                                       capture_output=True, text=True, env=env, cwd=str(ROOT))
                    notes.append(f"- {name}: first call of `phased_torques` with an empty "
                                 f"cache (its compile): {float(r.stdout.split()[-1]):.1f} "
                                 "CPU s.")
        runs = {}
        for path_name in ("compiled", "reference"):  # warm-up
            runs[path_name] = _run(built, path_name == "compiled")
        for k in range(args.pairs):
            for path_name in ("compiled", "reference"):
                res, wall, cpu = _run(built, path_name == "compiled")
                runs[path_name] = (res, wall, cpu)
                lines.append(f"| {name} | {path_name} | {k + 1} | {wall:.2f} | {cpu:.2f} | "
                             f"{sim.duration / wall:.1f} | {os.getloadavg()[0]:.1f} |")
                print(lines[-1], flush=True)
        a, b = runs["compiled"][0], runs["reference"][0]
        notes.append(f"- {name} ({sim.duration:g} s simulated, dt {sim.dt:g} s): "
                     f"{_agreement(a, b, sim.dt)}. Warnings of the compiled run: "
                     f"{a.warnings}; of the reference: {b.warnings}.")
    lines += ["", "Notes (compile of the new kernel; agreement of the last pair):", "", *notes, "",
              f"CPU time of this process's children (cold runs): "
              f"{resource.getrusage(resource.RUSAGE_CHILDREN).ru_utime:.1f} s."]
    tmp = out / "scenario_speed.md.tmp"
    tmp.write_text("\n".join(lines) + "\n", encoding="utf-8")
    tmp.replace(out / "scenario_speed.md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
