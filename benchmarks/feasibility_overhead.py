"""What the feasibility checks at every recorded sample add to a run (issue 23: at most 20 %).

For each scenario (default: the demo), interleaved rounds of: ``simulate_built`` alone (no
checks); the run's ``feasibility_report`` on the same result, limits and collisions, made
after the run (its ``CollisionScene`` built once beforehand as the runner builds it before
simulating); ``simulate_built`` as ``multiarm-pin run`` calls it, with the collision scan as
a monitor that checks each stretch while the run runs (on a worker thread beside the
compiled loop), then its report reusing that scan: its extra time over the bare run is what
the target is judged on; and the same with the monitors of ``limits: {torque, velocity,
position, collision: stop}``. The medians of the per-round ratios, so that the machine's
load changes hit the parts of a round alike. Also the scene's construction (once per run),
the real-time factor of the run with its checks (simulated time / its median wall time;
target: at least 10), and the checks' extra CPU time (of all threads, over the bare run's):
what they cost where no core is free, whatever the machine's load; and the CPU time of the
collision scan itself in that run (``RunScan.extend`` on the worker thread and
``RunScan.result`` after the run, each timed with its own thread's clock) over the bare
run's CPU time: the least load-sensitive figure. Prints a Markdown table;
the target columns say met / NOT met. The checks beside the simulation need a free core: on
a machine whose cores are all busy they cost what the checks after the run cost, or more.

    .venv/bin/python benchmarks/feasibility_overhead.py [--scenarios two_ur5_box ... | --all]
        [--repeat 7] [--duration S]
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

from multiarm_pin.app.run_feasibility import run_monitors
from multiarm_pin.app.runner import scenario_controller, simulate_built
from multiarm_pin.app.scenario import build_scenario, load_scenario
from multiarm_pin.data import data_path
from multiarm_pin.exceptions import RunStoppedError
from multiarm_pin.feasibility import CollisionScene, feasibility_report
from multiarm_pin.feasibility.scan import RunScan
from multiarm_pin.sim.simulation import partial_result

TARGET = 0.20
"""Largest accepted (feasibility check time) / (simulation time)."""

RTF_TARGET = 10.0
"""Smallest accepted simulated time / wall time of a run with its checks."""


def measure(name: str, repeat: int, duration: float | None = None) -> dict:
    """Median times [s] and per-round ratios of one scenario's checks (module docstring).

    Returns:
        ``scenario``, ``samples``, ``simulate``, ``check``, ``ratio`` (check / simulate),
        ``monitored`` (the run with every ``stop`` monitor, and its report),
        ``monitored_ratio`` (its extra time / simulate), ``scene`` (the scene's
        construction) and ``rtf`` (simulated time / the run with its checks).
    """
    import dataclasses

    from multiarm_pin.app.scenario.specs import LimitsSpec

    sc = load_scenario(data_path("scenarios", f"{name}.yaml"))
    built = build_scenario(sc, load_visuals=False)
    sim = built.scenario.simulation
    T = sim.duration if duration is None else min(duration, sim.duration)
    t0 = time.perf_counter()
    scene = CollisionScene(built.system, built.initial_state, built.scenario.ground) \
        if built.system.n_arms else None
    scene_s = time.perf_counter() - t0
    stops = dataclasses.replace(built, scenario=dataclasses.replace(
        built.scenario, limits=LimitsSpec("stop", "stop", "stop", "stop")))
    simulate_built(built, scenario_controller(built), T, sim.dt, sim.solver)  # kernels loaded
    sims, checks, runs, monitored, cpu_sims, cpu_runs = [], [], [], [], [], []

    def watched_run(spec):
        monitors = run_monitors(spec, scene)
        try:
            watched = simulate_built(built, scenario_controller(built), T, sim.dt, sim.solver,
                                     monitors=monitors)
        except RunStoppedError as exc:  # a stop policy ended it (as `run` does: the report
            watched = partial_result(exc)  # of the samples up to the violation)
        scans = [m.scan for m in monitors if getattr(m, "scan", None) is not None]
        feasibility_report(built.system, watched, ground=built.scenario.ground, scene=scene,
                           scan=scans[0] if scans else None)  # the monitor's scan reused

    scan_cpu = [0.0]  # thread CPU seconds of the scan's calls (worker thread and after)

    def timed(method):
        def wrapper(*args, **kwargs):
            c = time.thread_time()
            try:
                return method(*args, **kwargs)
            finally:
                scan_cpu[0] += time.thread_time() - c
        return wrapper

    scan_runs = []
    for _ in range(repeat):
        controller = scenario_controller(built)
        c0, t0 = time.process_time(), time.perf_counter()
        result = simulate_built(built, controller, T, sim.dt, sim.solver)
        c1, t1 = time.process_time(), time.perf_counter()
        feasibility_report(built.system, result, ground=built.scenario.ground, scene=scene)
        c2, t2 = time.process_time(), time.perf_counter()
        scan_cpu[0] = 0.0
        extend, result_of = RunScan.extend, RunScan.result
        RunScan.extend, RunScan.result = timed(extend), timed(result_of)
        try:
            watched_run(built)  # what `multiarm-pin run` does: the scan beside the simulation
        finally:
            RunScan.extend, RunScan.result = extend, result_of
        c3, t3 = time.process_time(), time.perf_counter()
        scan_runs.append(scan_cpu[0])
        cpu_sims.append(c1 - c0)
        cpu_runs.append(c3 - c2)
        watched_run(stops)
        t4 = time.perf_counter()
        sims.append(t1 - t0)
        checks.append(t2 - t1)
        runs.append(t3 - t2)
        monitored.append(t4 - t3)
    sims, checks = np.array(sims), np.array(checks)
    runs, monitored = np.array(runs), np.array(monitored)
    return {"scenario": name, "samples": len(result.t), "simulate": float(np.median(sims)),
            "check": float(np.median(checks)), "ratio": float(np.median(checks / sims)),
            "run": float(np.median(runs)), "run_ratio": float(np.median(runs / sims - 1.0)),
            "monitored": float(np.median(monitored)),
            "monitored_ratio": float(np.median(monitored / sims - 1.0)), "scene": scene_s,
            "rtf": float(result.t[-1] / np.median(runs)),
            "run_cpu_ratio": float(np.median(np.array(cpu_runs) / np.array(cpu_sims) - 1.0)),
            "scan_cpu": float(np.median(scan_runs)),
            "scan_cpu_ratio": float(np.median(np.array(scan_runs) / np.array(cpu_sims))),
            "simulate_cpu": float(np.median(cpu_sims))}


def table(rows: list[dict]) -> list[str]:
    """The Markdown table of :func:`measure`'s rows (the target is judged on the run's)."""
    out = ["| scenario | samples | simulate [s] | checks after [s] | checks / simulate | "
           "run with its checks [s] | its extra time | target 20 % | its extra CPU | "
           "scan thread CPU [s] | scan CPU / bare run CPU | every stop + report [s] | "
           "its extra time | scene [s] | RTF with its checks | target 10x |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        verdict = "met" if r["run_ratio"] <= TARGET else "NOT met"
        out.append(f"| {r['scenario']} | {r['samples']} | {r['simulate']:.3f} | "
                   f"{r['check']:.3f} | {100 * r['ratio']:.0f} % | {r['run']:.3f} | "
                   f"{100 * r['run_ratio']:+.0f} % | {verdict} | "
                   f"{100 * r['run_cpu_ratio']:+.0f} % | "
                   f"{r['scan_cpu']:.4f} | {100 * r['scan_cpu_ratio']:.0f} % | "
                   f"{r['monitored']:.3f} | {100 * r['monitored_ratio']:+.0f} % | "
                   f"{r['scene']:.3f} | {r['rtf']:.1f} | "
                   f"{'met' if r['rtf'] >= RTF_TARGET else 'NOT met'} |")
    return out


def main(argv=None) -> int:
    """Run the benchmark and print its table."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenarios", nargs="+", default=["two_ur5_box"])
    p.add_argument("--all", action="store_true", help="every shipped scenario")
    p.add_argument("--repeat", type=int, default=7)
    p.add_argument("--duration", type=float, default=None,
                   help="cap on each scenario's simulated time [s]")
    args = p.parse_args(argv)
    print(f"machine: {platform.processor() or platform.machine()}, python "
          f"{platform.python_version()}, load average {os.getloadavg()[0]:.2f}")
    names = (sorted(p.stem for p in data_path("scenarios").glob("*.yaml")) if args.all
             else args.scenarios)
    rows = [measure(name, args.repeat, args.duration) for name in names]
    print("\n".join(table(rows)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
