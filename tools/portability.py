"""Run the round-off-sensitive tests under other CPUs' arithmetic, on this one machine.

CI may run on an Intel or an AMD machine, with any OpenBLAS kernel, and rounding differs
between them: numba's code generation (``NUMBA_CPU_NAME``: which vector instructions LLVM
may use, hence the order of a sum's terms), OpenBLAS's kernel (``OPENBLAS_CORETYPE``) and
numpy's SIMD paths (``NPY_DISABLE_CPU_FEATURES``). A test whose verdict rests on round-off
passes on one and fails on another. This script runs the grasp, solver, unilateral and
contact-event tests once per :data:`TARGETS` entry that this machine can execute, each in a
fresh process with its own empty numba cache folder, and reports each run's BLAS kernel as
OpenBLAS itself names it (``threadpoolctl``), so that a coretype the library ignored is seen.

Usage: ``python tools/portability.py [--list] [--only NAME ...] [pytest args or test paths]``
(``make portability``). Exit 0 when every run passed, 1 otherwise, 2 when no target can run.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

TESTS = (
    "tests/grasp",
    "tests/dynamics",
    "tests/test_contact_events.py",
    "tests/test_contact_loop.py",
    "tests/test_contact_loop_kernel.py",
    "tests/test_unilateral_scenarios.py",
    "tests/test_controllers_unilateral.py",
    "tests/test_object_pd_touching.py",
)
"""The tests run under each target: grasp analysis, solvers, unilateral contacts, events."""

NO_AVX512 = "X86_V4 AVX512_ICL AVX512_SPR"
"""numpy's dispatch targets with AVX-512 (numpy 2.x names; an unknown name is ignored)."""


@dataclass(frozen=True)
class Target:
    """One machine's arithmetic: numba's CPU, OpenBLAS's kernel, numpy's SIMD paths.

    ``needs`` are the ``/proc/cpuinfo`` flags this machine must have to execute the code.
    """

    name: str
    description: str
    env: dict[str, str]
    needs: tuple[str, ...] = field(default=())


TARGETS = (
    Target("generic", "x86-64 baseline: numba generic, OpenBLAS Prescott, numpy without AVX2",
           {"NUMBA_CPU_NAME": "generic", "OPENBLAS_CORETYPE": "Prescott",
            "NPY_DISABLE_CPU_FEATURES": "X86_V3 " + NO_AVX512}),
    Target("avx2", "an AVX2 machine (Haswell, Zen 1-3): numba haswell, OpenBLAS Haswell, "
           "numpy without AVX-512",
           {"NUMBA_CPU_NAME": "haswell", "NUMBA_CPU_FEATURES": "", "OPENBLAS_CORETYPE": "Haswell",
            "NPY_DISABLE_CPU_FEATURES": NO_AVX512},
           ("avx2", "fma", "bmi2")),
    Target("avx512", "an AVX-512 Intel machine: numba skylake-avx512, OpenBLAS SkylakeX",
           {"NUMBA_CPU_NAME": "skylake-avx512", "NUMBA_CPU_FEATURES": "",
            "OPENBLAS_CORETYPE": "SkylakeX"},
           ("avx2", "fma", "avx512f", "avx512bw", "avx512dq", "avx512vl", "avx512cd")),
    Target("zen", "an AMD Zen 2 machine: numba znver2, OpenBLAS Zen, numpy without AVX-512",
           {"NUMBA_CPU_NAME": "znver2", "NUMBA_CPU_FEATURES": "", "OPENBLAS_CORETYPE": "Zen",
            "NPY_DISABLE_CPU_FEATURES": NO_AVX512},
           ("avx2", "fma", "bmi2", "sse4a", "clzero")),
)
"""The targets, each run only where this machine has the flags it needs."""

PROBE = ("from threadpoolctl import threadpool_info; import numpy, scipy.linalg; "
         "print(sorted({i.get('architecture') or '?' for i in threadpool_info() "
         "if i['internal_api'] == 'openblas'}))")


def cpu_flags() -> set[str]:
    """The CPU flags of this machine (``/proc/cpuinfo``); empty where it cannot be read."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return set()
    m = re.search(r"^flags\s*:(.*)$", text, re.M)
    return set(m.group(1).split()) if m else set()


def environment(target: Target, cache: str) -> dict[str, str]:
    """The process environment of one run: this one's, with the target's and a fresh cache."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("NUMBA_CPU_NAME", "NUMBA_CPU_FEATURES", "OPENBLAS_CORETYPE",
                        "NPY_DISABLE_CPU_FEATURES", "NUMBA_DISABLE_JIT")}
    env.update(target.env)
    env.update(NUMBA_CACHE_DIR=cache, PYTHONDONTWRITEBYTECODE="1")
    return env


def summary_line(output: str) -> str:
    """The closing line of pytest (``N passed, M failed in T s``), or the last line printed."""
    lines = [ln.strip("= ") for ln in output.splitlines() if ln.strip()]
    for ln in reversed(lines):
        if re.search(r"\d+ (passed|failed|error)", ln):
            return ln
    return lines[-1] if lines else "(no output)"


def main(argv: list[str] | None = None) -> int:
    """Run the tests under every executable target; print a table; exit 1 on any failure."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--list", action="store_true", help="list the targets and exit")
    p.add_argument("--only", nargs="+", metavar="NAME", help="run only these targets")
    p.add_argument("pytest_args", nargs="*", help=f"tests or pytest options (default: {TESTS})")
    args = p.parse_args(argv)
    flags = cpu_flags()
    chosen = [t for t in TARGETS if not args.only or t.name in args.only]
    runnable = [t for t in chosen if all(f in flags for f in t.needs)]
    for t in chosen:
        mark = "run " if t in runnable else "skip"
        missing = [f for f in t.needs if f not in flags]
        print(f"{mark} {t.name:8s} {t.description}"
              + (f" (this CPU lacks {', '.join(missing)})" if missing else ""))
    if args.list:
        return 0
    if not runnable:
        print("portability: no target can run on this machine", file=sys.stderr)
        return 2
    tests = args.pytest_args or list(TESTS)
    rows, failed = [], False
    for t in runnable:
        with tempfile.TemporaryDirectory(prefix=f"numba-cache-{t.name}-") as cache:
            env = environment(t, cache)
            blas = subprocess.run([sys.executable, "-c", PROBE], env=env, cwd=ROOT,
                                  capture_output=True, text=True).stdout.strip()
            print(f"\n== {t.name}: {' '.join(f'{k}={v!r}' for k, v in t.env.items())}; "
                  f"OpenBLAS kernel {blas}", flush=True)
            t0 = time.monotonic()
            run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                                  *tests], env=env, cwd=ROOT, capture_output=True, text=True)
            elapsed = time.monotonic() - t0
        ok = run.returncode == 0
        failed |= not ok
        out = run.stdout + run.stderr
        if not ok:
            print("\n".join(ln for ln in out.splitlines()
                            if ln.startswith(("FAILED", "ERROR")) or "Error" in ln[:40]))
        rows.append((t.name, blas, summary_line(out), elapsed, ok))
        print(f"{t.name}: {summary_line(out)} ({elapsed:.0f} s)", flush=True)
    print("\n| target | OpenBLAS kernel | pytest | wall [s] |\n|---|---|---|---|")
    for name, blas, line, elapsed, _ in rows:
        print(f"| {name} | {blas} | {line} | {elapsed:.0f} |")
    print("portability: " + ("FAILED" if failed else "all targets passed"))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
