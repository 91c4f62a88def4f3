"""Cold-compile time of the compiled kernels on the demo path, per compiled function (issue 14).

Run with an empty numba cache, e.g.::

    NUMBA_CACHE_DIR=$(mktemp -d) .venv/bin/python benchmarks/compile_times.py

It simulates 0.01 s of ``scenarios/two_ur5_box.yaml`` under its controller while numba's event
recorder listens to ``numba:compile`` events, then prints the wall and CPU time of that run
(mostly compilation when the cache is empty; on a shared machine the CPU time is the steadier
figure), the per-function table of exclusive compile seconds
(own compile, nested compiles of callees excluded), their sum, the number of compiled
specialisations (each is a full compile), and how much of the compile held numba's LLVM lock
(LLVM passes, linking and code generation; the rest is numba's typing and lowering). With a
warm cache the table is (nearly) empty. The loops' stages, compiled as ``cfunc`` function
pointers, are not dispatcher compiles: their own time is in the total only.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from numba.core import event

from multiarm_pin.app.runner import scenario_controller, simulate_built
from multiarm_pin.app.scenario import build_scenario, load_scenario

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    """Run the demo briefly under the compile-event recorder and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default=str(ROOT / "scenarios" / "two_ur5_box.yaml"))
    parser.add_argument("--duration", type=float, default=0.01, help="simulated time [s]")
    args = parser.parse_args()
    built = build_scenario(load_scenario(args.scenario))
    sim = built.scenario.simulation
    controller = scenario_controller(built)
    t0, c0 = time.perf_counter(), time.process_time()
    with event.install_recorder("numba:compile") as rec, \
            event.install_recorder("numba:llvm_lock") as llvm:
        simulate_built(built, controller, args.duration, sim.dt, sim.solver)
    total, cpu = time.perf_counter() - t0, time.process_time() - c0
    stack, excl, count = [], {}, {}
    for ts, ev in rec.buffer:
        f = ev.data["dispatcher"].py_func
        name = f.__module__.split(".")[-1] + "." + f.__name__
        if ev.is_start:
            stack.append([name, ts, 0.0])
        else:
            n, t1, child = stack.pop()
            excl[n] = excl.get(n, 0.0) + (ts - t1) - child
            count[n] = count.get(n, 0) + 1
            if stack:
                stack[-1][2] += ts - t1
    print(f"total {total:.2f} s wall, {cpu:.2f} s CPU (run of {args.duration} s simulated, "
          "compile included)")
    for n, e in sorted(excl.items(), key=lambda x: -x[1]):
        print(f"{e:7.2f} {n}" + (f"  ({count[n]} specialisations)" if count[n] > 1 else ""))
    print(f"{sum(excl.values()):7.2f} sum of compiles, {sum(count.values())} specialisations")
    print(f"{_outermost(llvm.buffer):7.2f} of it holding numba's LLVM lock (LLVM passes, linking, "
          "code generation); the rest is numba's typing and lowering")


def _outermost(buffer) -> float:
    """Seconds covered by the outermost start/end pairs of a recorder's events."""
    depth, total, start = 0, 0.0, 0.0
    for ts, ev in buffer:
        if ev.is_start:
            if depth == 0:
                start = ts
            depth += 1
        else:
            depth -= 1
            if depth == 0:
                total += ts - start
    return total


if __name__ == "__main__":
    main()
