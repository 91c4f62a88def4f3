"""``multiarm-pin precompile``: the closed loop built ahead of time from a run of the demo.

The ahead-of-time build itself (:func:`multiarm_pin._compiled.precompiled.build`) sits in the
compiled layer, which imports nothing above it; the types of a kernel's arguments, which fix
the module's signature, come from a real run. This module builds them: the arguments a short
run of the shipped demo scenario passes to each kernel of
:data:`~multiarm_pin._compiled.precompiled.KERNELS` (:data:`EXAMPLES`; every shipped scenario
passes arguments of the same types: tested), and runs the build (``make precompile``,
``python -m multiarm_pin.app.precompile``).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from multiarm_pin._compiled import precompiled


def run_rk4_arguments() -> tuple:
    """The arguments of ``run_rk4`` in a short run of the shipped demo scenario."""
    from multiarm_pin.app.runner import scenario_controller
    from multiarm_pin.app.scenario import build_scenario, load_scenario
    from multiarm_pin.data import DEMO_SCENARIO, data_path
    from multiarm_pin.sim.compiled_loop import CompiledLoop
    from multiarm_pin.sim.stepper import Stepper

    built = build_scenario(load_scenario(data_path("scenarios", DEMO_SCENARIO)),
                           load_visuals=False)
    sim = built.scenario.simulation
    stepper = Stepper(built.system, scenario_controller(built), sim.solver, sim.baumgarte)
    loop = CompiledLoop.for_run(stepper, "rk4")
    if loop is None or not loop.ready(built.initial_state):
        raise RuntimeError("the demo scenario does not run on the compiled closed loop")
    return loop.example_arguments(built.initial_state)


EXAMPLES: dict[str, Callable[[], tuple]] = {"run_rk4": run_rk4_arguments}
"""Kernel name (:data:`~multiarm_pin._compiled.precompiled.KERNELS`) -> ``() -> arguments``
of a real run (a test checks that every kernel has one)."""


def build(folder: Path | None = None, verbose: bool = False) -> Path:
    """Build every kernel of the module for the arguments of :data:`EXAMPLES`.

    Args:
        folder: where (default :data:`~multiarm_pin._compiled.precompiled.FOLDER`).
        verbose: the AOT compiler's messages.

    Returns:
        The module's path.

    Raises:
        Exception: whatever numba's AOT compiler or the C toolchain raises (e.g. no compiler).
    """
    examples = {name: EXAMPLES[name]() for name in precompiled.KERNELS}
    return precompiled.build(examples, folder, verbose)


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: build the module (``--if-stale``: only when none fits these sources)."""
    import argparse

    parser = argparse.ArgumentParser(description="Compile the simulation loops ahead of time.")
    parser.add_argument("--if-stale", action="store_true",
                        help="do nothing if a module of these sources is built")
    parser.add_argument("--folder", type=Path, default=None,
                        help="where to build (default: the package's _compiled folder)")
    opts = parser.parse_args(argv)
    if opts.if_stale and precompiled.load(opts.folder) is not None:
        print(f"precompiled loops up to date ({precompiled.module_name()})")
        return 0
    t0 = time.perf_counter()
    try:
        path = build(opts.folder)
    except Exception as exc:  # noqa: BLE001 - any build failure: the JIT stays in use
        print(f"precompiled loops not built ({type(exc).__name__}: {exc}); the kernels "
              "will be compiled at first use instead", file=sys.stderr)
        return 1
    print(f"precompiled loops built in {time.perf_counter() - t0:.0f} s: {path.name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())


__all__ = ["EXAMPLES", "build", "main", "run_rk4_arguments"]
