"""``multiarm-pin precompile``: the kernels of the shipped scenarios compiled into numba's cache.

numba compiles a kernel at its first call and caches it on disk (``cache=True``, each entry
stamped with a digest of all kernel sources: :mod:`multiarm_pin._compiled.cache`), so the
first run of a scenario waits once for the compilation of the loops and stages it uses.
This command (``make precompile``; optional, never part of ``make demo``, ``make test`` or
``pip install``) runs shipped scenarios once each, exactly as ``multiarm-pin run`` does (the
whole duration, without plots or replay page, into a temporary folder removed afterwards), so
that what they use is compiled and cached for this machine. Later runs of them, and of any
scenario that takes the same loops (the cache is keyed by argument types, not sizes), then
load the kernels instead.

Nothing is built outside numba's own cache, and no C compiler is needed. With
``NUMBA_DISABLE_JIT`` set there is nothing to compile and it says so.
"""

from __future__ import annotations

import contextlib
import io
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from multiarm_pin.data import shipped_files
from multiarm_pin.exceptions import InputError, MultiArmError


@dataclass(frozen=True)
class Compiled:
    """One scenario's pass of :func:`precompile`.

    Attributes:
        name: the scenario's file name without ``.yaml``.
        seconds: wall time of its run, compilation included [s].
        outcome: ``"complete"``, or how the run ended (a run that fails, e.g. the grasp
            failure the scenario shows, still compiles what it used).
    """

    name: str
    seconds: float
    outcome: str


def shipped_scenarios() -> dict[str, Path]:
    """The shipped scenario files by name (file name without ``.yaml``)."""
    return {p.stem: p for p in shipped_files("scenarios")}


def precompile(names: Sequence[str] | None = None,
               report: Callable[[Compiled], None] | None = None) -> list[Compiled]:
    """Run shipped scenarios once each, so that numba compiles and caches their kernels.

    Args:
        names: scenario names (:func:`shipped_scenarios`); default all.
        report: called after each scenario (e.g. to print progress).

    Returns:
        One :class:`Compiled` per scenario, in order.

    Raises:
        InputError: a name that is not a shipped scenario (before anything runs).
    """
    from multiarm_pin.app.runner import run_scenario

    shipped = shipped_scenarios()
    chosen = list(shipped) if names is None else list(names)
    unknown = [n for n in chosen if n not in shipped]
    if unknown:
        raise InputError(f"not shipped scenarios: {', '.join(map(repr, unknown))}; expected "
                         f"names among {', '.join(shipped)}")
    done = []
    with tempfile.TemporaryDirectory(prefix="multiarm-pin-precompile-") as tmp:
        for name in chosen:
            t0 = time.perf_counter()
            quiet = io.StringIO()  # the scenarios' own warnings are not this command's
            try:
                with contextlib.redirect_stderr(quiet):
                    run_scenario(shipped[name], out=Path(tmp) / name, quiet=True, html=False,
                                 plots=False)
                outcome = "complete"
            except MultiArmError as exc:
                outcome = f"ended early ({type(exc).__name__})"
            item = Compiled(name, time.perf_counter() - t0, outcome)
            done.append(item)
            if report is not None:
                report(item)
    return done


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: compile the kernels of the shipped scenarios (``--scenarios`` some)."""
    import argparse

    from multiarm_pin._compiled.jit import jit_disabled

    parser = argparse.ArgumentParser(
        prog="multiarm-pin precompile",
        description="Compile the kernels of the shipped scenarios into numba's cache.")
    parser.add_argument("--scenarios", nargs="+", default=None, metavar="NAME",
                        help="only these shipped scenarios (default: all)")
    opts = parser.parse_args(argv)
    if jit_disabled():
        print("NUMBA_DISABLE_JIT is set: the kernels run as Python, nothing to compile")
        return 0
    t0 = time.perf_counter()
    try:
        done = precompile(opts.scenarios, report=lambda c: print(
            f"  {c.name}: {c.seconds:.0f} s, {c.outcome}", flush=True))
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"the kernels of {len(done)} scenarios are compiled and cached "
          f"({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())


__all__ = ["Compiled", "main", "precompile", "shipped_scenarios"]
