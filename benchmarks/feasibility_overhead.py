"""What the feasibility checks at every recorded sample add to a run (issue 23: at most 20 %).

For each scenario (default: the demo), interleaved rounds of (``simulate_built``, the run's
``feasibility_report`` on the same result, limits and collisions, its ``CollisionScene``
built once beforehand as the runner builds it before simulating; then ``simulate_built``
with the monitors of ``limits: {torque, velocity, position, collision: stop}``, which check
each stretch while the run runs, and its report, which reuses the collision monitor's scan):
the medians of the per-round ratios, so that the machine's
load changes hit the parts of a round alike. Also the scene's construction (once per run).
Prints a Markdown table; the target column says met / NOT met.

    .venv/bin/python benchmarks/feasibility_overhead.py [--scenarios two_ur5_box ...]
        [--repeat 7] [--duration S]
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

from multiarm_pin.app.run_feasibility import run_monitors
from multiarm_pin.app.runner import make_controller, simulate_built
from multiarm_pin.app.scenario import build_scenario, load_scenario
from multiarm_pin.data import data_path
from multiarm_pin.feasibility import CollisionScene, feasibility_report

TARGET = 0.20
"""Largest accepted (feasibility check time) / (simulation time)."""


def measure(name: str, repeat: int, duration: float | None = None) -> dict:
    """Median times [s] and per-round ratios of one scenario's checks (module docstring).

    Returns:
        ``scenario``, ``samples``, ``simulate``, ``check``, ``ratio`` (check / simulate),
        ``monitored`` (the run with every ``stop`` monitor, and its report),
        ``monitored_ratio`` (its extra time / simulate) and ``scene`` (the scene's
        construction).
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
    simulate_built(built, make_controller(built), T, sim.dt, sim.solver)  # kernels loaded
    sims, checks, monitored = [], [], []
    for _ in range(repeat):
        controller = make_controller(built)
        t0 = time.perf_counter()
        result = simulate_built(built, controller, T, sim.dt, sim.solver)
        t1 = time.perf_counter()
        feasibility_report(built.system, result, ground=built.scenario.ground, scene=scene)
        t2 = time.perf_counter()
        monitors = run_monitors(stops, scene)
        watched = simulate_built(built, make_controller(built), T, sim.dt, sim.solver,
                                 monitors=monitors)
        scans = [m.scan for m in monitors if getattr(m, "scan", None) is not None]
        feasibility_report(built.system, watched, ground=built.scenario.ground, scene=scene,
                           scan=scans[0] if scans else None)  # the monitor's scan reused
        t3 = time.perf_counter()
        sims.append(t1 - t0)
        checks.append(t2 - t1)
        monitored.append(t3 - t2)
    sims, checks, monitored = np.array(sims), np.array(checks), np.array(monitored)
    return {"scenario": name, "samples": len(result.t), "simulate": float(np.median(sims)),
            "check": float(np.median(checks)), "ratio": float(np.median(checks / sims)),
            "monitored": float(np.median(monitored)),
            "monitored_ratio": float(np.median(monitored / sims - 1.0)), "scene": scene_s}


def table(rows: list[dict]) -> list[str]:
    """The Markdown table of :func:`measure`'s rows."""
    out = ["| scenario | samples | simulate [s] | checks after [s] | checks / simulate | "
           "target 20 % | stop monitors + report [s] | its extra time | scene [s] |",
           "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        verdict = "met" if r["ratio"] <= TARGET else "NOT met"
        out.append(f"| {r['scenario']} | {r['samples']} | {r['simulate']:.3f} | "
                   f"{r['check']:.3f} | {100 * r['ratio']:.0f} % | {verdict} | "
                   f"{r['monitored']:.3f} | {100 * r['monitored_ratio']:+.0f} % | "
                   f"{r['scene']:.3f} |")
    return out


def main(argv=None) -> int:
    """Run the benchmark and print its table."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenarios", nargs="+", default=["two_ur5_box"])
    p.add_argument("--repeat", type=int, default=7)
    p.add_argument("--duration", type=float, default=None,
                   help="cap on each scenario's simulated time [s]")
    args = p.parse_args(argv)
    print(f"machine: {platform.processor() or platform.machine()}, python "
          f"{platform.python_version()}, load average {os.getloadavg()[0]:.2f}")
    rows = [measure(name, args.repeat, args.duration) for name in args.scenarios]
    print("\n".join(table(rows)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
