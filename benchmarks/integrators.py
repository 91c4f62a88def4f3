"""Semi-implicit Euler against RK4 on the compiled loop, at the same ``dt`` (issue 24).

For each scenario (default: the demo and the other weld scenarios), interleaved rounds of
``simulate_built`` with the scenario's settings, once with ``integrator: rk4`` and once with
``semi_implicit`` (one evaluation a step instead of four), warm (each scenario run once
with each integrator before the rounds). Reports the medians of the wall times and of the
per-round ratio rk4 / semi_implicit (target: at least 3 on the demo), and for each
integrator the largest constraint violation of the run (``max |φ|`` over the real rows and
the samples [m]: Baumgarte stabilisation bounds it; semi-implicit Euler's first-order
error per step is what it corrects) and the object's largest distance from the RK4 run's
path [m].

    .venv/bin/python benchmarks/integrators.py [--scenarios two_ur5_box ...] [--repeat 7]
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import time

import numpy as np

from multiarm_pin.app.runner import scenario_controller, simulate_built
from multiarm_pin.app.scenario import build_scenario, load_scenario
from multiarm_pin.data import data_path

TARGET = 3.0
"""Smallest accepted wall-time ratio rk4 / semi_implicit on the demo."""

INTEGRATORS = ("rk4", "semi_implicit")


def measure(name: str, repeat: int) -> dict:
    """Median wall times [s], the median ratio, violations [m] and the path difference [m]."""
    sc = load_scenario(data_path("scenarios", f"{name}.yaml"))
    built = {i: build_scenario(dataclasses.replace(sc, simulation=dataclasses.replace(
        sc.simulation, integrator=i)), load_visuals=False) for i in INTEGRATORS}
    sim = sc.simulation

    def run(i):
        b = built[i]
        t0 = time.perf_counter()
        result = simulate_built(b, scenario_controller(b), sim.duration, sim.dt, sim.solver)
        return time.perf_counter() - t0, result

    results = {i: run(i)[1] for i in INTEGRATORS}  # kernels compiled or loaded
    walls: dict[str, list[float]] = {i: [] for i in INTEGRATORS}
    for _ in range(repeat):
        for i in INTEGRATORS:
            walls[i].append(run(i)[0])
    w = {i: np.array(v) for i, v in walls.items()}
    rk4, semi = results["rk4"], results["semi_implicit"]
    return {"scenario": name, "samples": len(rk4.t), "dt": sim.dt,
            "rk4": float(np.median(w["rk4"])), "semi": float(np.median(w["semi_implicit"])),
            "ratio": float(np.median(w["rk4"] / w["semi_implicit"])),
            "violation_rk4": float(np.max(rk4.constraint_violation)),
            "violation_semi": float(np.max(semi.constraint_violation)),
            "path": float(np.max(np.linalg.norm(semi.object_position - rk4.object_position,
                                                axis=1)))}


def table(rows: list[dict]) -> list[str]:
    """The Markdown table of :func:`measure`'s rows."""
    out = ["| scenario | samples | dt [s] | rk4 [s] | semi_implicit [s] | rk4 / semi_implicit | "
           "max violation rk4 [m] | max violation semi_implicit [m] | object path apart [m] |",
           "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['scenario']} | {r['samples']} | {r['dt']:g} | {r['rk4']:.4f} | "
                   f"{r['semi']:.4f} | {r['ratio']:.2f} | {r['violation_rk4']:.2e} | "
                   f"{r['violation_semi']:.2e} | {r['path']:.2e} |")
    return out


def main(argv=None) -> int:
    """Run the benchmark and print its table."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenarios", nargs="+",
                   default=["two_ur5_box", "three_ur5_box", "ur5_panda_box", "mp6_pair_box"])
    p.add_argument("--repeat", type=int, default=7)
    args = p.parse_args(argv)
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
          f"python {platform.python_version()}, load average {os.getloadavg()[0]:.2f}")
    rows = [measure(name, args.repeat) for name in args.scenarios]
    print("\n".join(table(rows)))
    demo = next((r for r in rows if r["scenario"] == "two_ur5_box"), None)
    if demo is not None:
        verdict = "met" if demo["ratio"] >= TARGET else "NOT met"
        print(f"\ndemo rk4 / semi_implicit = {demo['ratio']:.2f} (target >= {TARGET:g}: "
              f"{verdict})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
