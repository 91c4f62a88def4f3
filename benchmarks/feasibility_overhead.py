"""What the feasibility checks at every recorded sample add to a run (issue 23: at most 20 %).

For each scenario (default: the demo), interleaved pairs of (``simulate_built``, the run's
``feasibility_report`` on the same result, limits and collisions, its ``CollisionScene``
built once beforehand as the runner builds it before simulating): the median of the
per-pair ratios, so that the machine's load changes hit both halves of a pair alike. Prints
a Markdown table; the target column says met / NOT met.

    .venv/bin/python benchmarks/feasibility_overhead.py [--scenarios two_ur5_box ...]
        [--repeat 7]
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np

from multiarm_pin.app.runner import make_controller, simulate_built
from multiarm_pin.app.scenario import build_scenario, load_scenario
from multiarm_pin.data import data_path
from multiarm_pin.feasibility import CollisionScene, feasibility_report

TARGET = 0.20
"""Largest accepted (feasibility check time) / (simulation time)."""


def measure(name: str, repeat: int) -> dict:
    """Median simulate and check times [s] and their median per-pair ratio for one scenario."""
    built = build_scenario(load_scenario(data_path("scenarios", f"{name}.yaml")),
                           load_visuals=False)
    sim = built.scenario.simulation
    scene = CollisionScene(built.system, built.initial_state, built.scenario.ground) \
        if built.system.n_arms else None
    sims, checks = [], []
    for _ in range(repeat):
        controller = make_controller(built)
        t0 = time.perf_counter()
        result = simulate_built(built, controller, sim.duration, sim.dt, sim.solver)
        t1 = time.perf_counter()
        feasibility_report(built.system, result, ground=built.scenario.ground, scene=scene)
        t2 = time.perf_counter()
        sims.append(t1 - t0)
        checks.append(t2 - t1)
    ratio = float(np.median(np.array(checks) / np.array(sims)))
    return {"scenario": name, "samples": len(result.t), "simulate": float(np.median(sims)),
            "check": float(np.median(checks)), "ratio": ratio}


def main(argv=None) -> int:
    """Run the benchmark and print its table."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenarios", nargs="+", default=["two_ur5_box"])
    p.add_argument("--repeat", type=int, default=7)
    args = p.parse_args(argv)
    print(f"machine: {platform.processor() or platform.machine()}, python "
          f"{platform.python_version()}")
    print("| scenario | samples | simulate [s] | checks [s] | checks / simulate | target 20 % |")
    print("|---|---|---|---|---|---|")
    for name in args.scenarios:
        r = measure(name, args.repeat)
        verdict = "met" if r["ratio"] <= TARGET else "NOT met"
        print(f"| {name} | {r['samples']} | {r['simulate']:.3f} | {r['check']:.3f} | "
              f"{100 * r['ratio']:.0f} % | {verdict} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
