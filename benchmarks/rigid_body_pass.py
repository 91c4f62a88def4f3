#!/usr/bin/env python
"""Benchmark: the compiled rigid-body pass against ``ArmSet.pinocchio_pass`` (issue 14).

For n UR5s (default 2, 8, 64; bases on a circle), per call, interleaved over ``--repeat``
rounds of ``--calls`` calls each (median of the rounds' per-call times):

- ``pinocchio``: :meth:`ArmSet.pinocchio_pass` (Jacobians and their time variation, CRBA,
  nonlinear effects, tool placements; in groups of ``GROUP_SIZE`` arms beyond 16 arms);
- ``compiled_pass``: :meth:`ArmSet.compiled_pass` (the same outputs, Python method);
- ``kernel``: :func:`multiarm_pin._compiled.rigid_body.rigid_body_pass` called directly on
  preallocated arrays (what another kernel pays, plus one dispatch from Python).

Times are the thread's CPU time (``time.thread_time``), robust to other processes' load.

Then the cold compile time of the three kernels of the module (a fresh process with an empty
``NUMBA_CACHE_DIR``: first call minus a warm call, CPU time of the process, after a trivial
kernel has paid numba's one-off start-up). Prints a Markdown table; ``--out FILE`` also
writes it.

Usage::

    .venv/bin/python benchmarks/rigid_body_pass.py
    .venv/bin/python benchmarks/rigid_body_pass.py --arms 2 --repeat 5 --no-cold   # smoke
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pinocchio as pin

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from multiarm_pin._compiled.rigid_body import rigid_body_pass  # noqa: E402
from multiarm_pin.model.arm import load_arm  # noqa: E402
from multiarm_pin.model.arm_set import ArmSet  # noqa: E402

_COLD = """
import time
import numba
import numpy as np
numba.njit(lambda x: x + 1)(1)  # numba's one-off start-up, paid by any first kernel
from multiarm_pin._compiled.rigid_body import difference, integrate, rigid_body_pass
from multiarm_pin.model.arm import load_arm
from multiarm_pin.model.compiled_model import CompiledModel
arm = load_arm("ur5", load_visuals=False)
cm = CompiledModel.build(arm.model, [arm.tool_frame_id])
q, v = np.zeros(cm.nq), np.ones(cm.nv)
out = cm.outputs()
res = []
for f, args in ((rigid_body_pass, (cm.ints, cm.floats, q, v) + out),
                (integrate, (cm.ints, q, v, np.empty(cm.nq))),
                (difference, (cm.ints, q, q, np.empty(cm.nv)))):
    t = time.process_time(); f(*args); first = time.process_time() - t
    t = time.process_time(); f(*args); warm = time.process_time() - t
    res.append(first - warm)
print(" ".join(f"{x:.4f}" for x in res))
"""


def ur5_set(n: int) -> ArmSet:
    """n UR5s on a circle of radius 0.9 m around the origin, facing it."""
    arms = []
    for i in range(n):
        a = 2 * np.pi * i / n
        base = pin.SE3(pin.rpy.rpyToMatrix(0, 0, a + np.pi),
                       np.array([0.9 * np.cos(a), 0.9 * np.sin(a), 0.0]))
        arms.append(load_arm("ur5", name=f"ur5_{i}", base=base, load_visuals=False))
    return ArmSet(arms)


def time_pass(n: int, repeat: int, calls: int, rng) -> dict[str, float]:
    """Median per-call CPU times of this thread [µs] of the three ways, interleaved.

    CPU time of the thread (``time.thread_time``) rather than wall time: the machine is
    shared, and a round during which the process waits for a core would otherwise count.
    """
    arm_set = ur5_set(n)
    cm = arm_set.compiled_model
    q = pin.randomConfiguration(arm_set.model)
    v = rng.normal(size=arm_set.nv)
    out = cm.outputs()
    ways = {
        "pinocchio": lambda: arm_set.pinocchio_pass(q, v),
        "compiled_pass": lambda: arm_set.compiled_pass(q, v),
        "kernel": lambda: rigid_body_pass(cm.ints, cm.floats, q, v, *out),
    }
    for f in ways.values():  # warm up (compiles or loads the kernel)
        f()
    samples = {k: [] for k in ways}
    for _ in range(repeat):
        for k, f in ways.items():
            t = time.thread_time()
            for _ in range(calls):
                f()
            samples[k].append((time.thread_time() - t) / calls * 1e6)
    return {k: statistics.median(s) for k, s in samples.items()}


def cold_compile() -> list[float]:
    """Cold compile times [s] of rigid_body_pass, integrate, difference (empty cache)."""
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        res = subprocess.run([sys.executable, "-c", _COLD], env=env, cwd=ROOT, check=True,
                             capture_output=True, text=True)
    return [float(x) for x in res.stdout.split()]


def main(argv=None) -> None:
    """Run the benchmark and print (and optionally write) the Markdown report."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--arms", default="2,8,64", help="comma-separated numbers of UR5s")
    ap.add_argument("--repeat", type=int, default=30, help="interleaved rounds")
    ap.add_argument("--calls", type=int, default=200, help="calls per round and way")
    ap.add_argument("--no-cold", action="store_true", help="skip the cold-compile run")
    ap.add_argument("--out", type=Path, help="write the Markdown report there too")
    args = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    cpu = platform.processor() or platform.machine()
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, text=True,
                            capture_output=True).stdout.strip() or "unknown"
    lines = [f"# Compiled rigid-body pass vs ArmSet.pinocchio_pass (commit {commit}, {cpu}, "
             f"{os.cpu_count()} cores, pin {pin.__version__}, load {os.getloadavg()[0]:.1f})",
             "",
             "| UR5s | pinocchio_pass [µs] | compiled_pass [µs] | kernel [µs] | "
             "pinocchio / compiled_pass | pinocchio / kernel |", "|---|---|---|---|---|---|"]
    for n in (int(x) for x in args.arms.split(",")):
        t = time_pass(n, args.repeat, max(1, args.calls // max(1, n // 8)), rng)
        lines.append(f"| {n} | {t['pinocchio']:.1f} | {t['compiled_pass']:.1f} | "
                     f"{t['kernel']:.1f} | {t['pinocchio'] / t['compiled_pass']:.2f} | "
                     f"{t['pinocchio'] / t['kernel']:.2f} |")
        print(lines[-1], flush=True)
    if not args.no_cold:
        c = cold_compile()
        lines += ["", f"Cold compile (empty NUMBA_CACHE_DIR, CPU): rigid_body_pass {c[0]:.2f} s, "
                  f"integrate {c[1]:.2f} s, difference {c[2]:.2f} s."]
    report = "\n".join(lines) + "\n"
    print(report)
    if args.out:
        args.out.write_text(report)


if __name__ == "__main__":
    main()
