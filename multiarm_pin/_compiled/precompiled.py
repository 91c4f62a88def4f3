"""The closed loop built ahead of time (optional): a first run compiles nothing.

numba compiles a kernel at its first call and caches it on disk. ``make precompile`` (or
``multiarm-pin precompile``, :mod:`multiarm_pin.app.precompile`, which gives :func:`build` the
example arguments of a short run of the demo scenario; not part of the install, and never
needed) compiles the closed loop (:func:`multiarm_pin._compiled.closed_loop.run_rk4`,
:data:`KERNELS`) once with numba's ahead-of-time compiler (``numba.pycc``) into one extension
module next to this file, for this machine's CPU;
:class:`~multiarm_pin.sim.compiled_loop.CompiledLoop` calls it when it is there and fits the
call (:func:`kernel_for`), and numba's JIT (cached on disk) otherwise.
Same code, same results (tested: equal to the JIT kernel's to the bit). The contact loop is
not in the module: the JIT compiles it, its stages once each
(:mod:`~multiarm_pin._compiled.function_pointers`).

Safety, since ``numba.pycc``'s entry points trust their arguments:

- the module's name carries the digest of all kernel sources
  (:func:`~multiarm_pin._compiled.cache.kernel_sources_digest`): a module built from other
  sources is never loaded;
- its sidecar file records the numba version and the CPU it was built for (triple, name,
  features: numba's own cache key) and the exact argument types, with their dispatch
  fingerprints; on another CPU or numba it is not loaded, and a call whose arguments do not
  have exactly those fingerprints (dtype, number of dimensions, layout, writability: what
  numba's own dispatcher compares) goes to the JIT kernel;
- it is not used when ``NUMBA_DISABLE_JIT`` is set (the kernels then run as Python,
  bounds-checked, in ``make test``) or when ``MULTIARM_PIN_AOT=0``.

A build writes both files atomically (a half-built module is never seen) and removes modules
of older sources. Without a C compiler the build fails with a message and the JIT is used;
the same if numba drops ``numba.pycc`` (pending deprecation since numba 0.57, with no
successor yet).
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import json
import os
import tempfile
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numba
from numba._dispatcher import compute_fingerprint as _fingerprint
from numba.core import config
from numba.core.errors import NumbaPendingDeprecationWarning

from multiarm_pin._compiled import closed_loop as kernels
from multiarm_pin._compiled.cache import kernel_sources_digest

FOLDER = Path(__file__).resolve().parent
"""Where the module and its sidecar are built: the ``_compiled`` package folder."""

PREFIX = "_closed_loop_aot_"
"""Module name prefix; the name is this plus the first 16 hex digits of the source digest."""

ENV_SWITCH = "MULTIARM_PIN_AOT"
"""Environment variable: ``0`` turns the precompiled module off (the JIT kernel is used)."""

RETURN_TYPE = numba.types.UniTuple(numba.types.int64, 2)
"""The loops' return type, ``(status, sample)``."""


@dataclass(frozen=True)
class Kernel:
    """One kernel of the module.

    Attributes:
        name: its name (the module's function, :data:`KERNELS`' key).
        dispatcher: the JIT kernel (the same code, compiled at first use).
        bound: its last parameters that are kernels (the stages the JIT path passes as
            function pointers), by name: the module calls these kernels directly and does not
            take them.
    """

    name: str
    dispatcher: Callable
    bound: dict = field(default_factory=dict)


KERNELS: dict[str, Kernel] = {k.name: k for k in (
    Kernel("run_rk4", kernels.run_rk4, {"evaluate": kernels.closed_loop_stage}),
)}
"""The kernels the module holds, by name."""

_loaded: dict[Path, dict | None] = {}  # folder -> {name: (function, fingerprints)} or None


def module_name() -> str:
    """The module's name for the current kernel sources."""
    return PREFIX + kernel_sources_digest()[:16]


def machine() -> list[str]:
    """The key of this machine's code in numba's cache: ``[triple, CPU name, CPU features]``."""
    from numba.core.registry import cpu_target

    return [str(x) for x in cpu_target.target_context.codegen().magic_tuple()]


def fingerprints(args: Sequence) -> list[bytes]:
    """Numba's dispatch fingerprints of ``args`` (dtype, dimensions, layout, writability).

    What numba's own dispatcher compares to pick a compiled kernel, computed in C (where
    ``numba.typeof`` of each argument would run Python for each).
    """
    return [_fingerprint(a) for a in args]


def _sidecar(folder: Path) -> Path:
    return folder / f"{module_name()}.json"


def load(folder: Path | None = None) -> dict | None:
    """``{name: (function, argument fingerprints)}`` of the module built in ``folder``, or None.

    None when it is off (:data:`ENV_SWITCH`, ``NUMBA_DISABLE_JIT``), not built for these
    sources, or built for another CPU or numba. Looked up once per process and folder
    (default :data:`FOLDER`).
    """
    if os.environ.get(ENV_SWITCH, "1") == "0" or config.DISABLE_JIT:
        return None
    folder = FOLDER if folder is None else Path(folder)
    if folder in _loaded:
        return _loaded[folder]
    found = None
    try:
        meta = json.loads(_sidecar(folder).read_text(encoding="utf-8"))
        paths = [folder / (module_name() + s) for s in importlib.machinery.EXTENSION_SUFFIXES]
        path = next((p for p in paths if p.exists()), None)
        if (path is not None and meta.get("digest") == kernel_sources_digest()
                and meta.get("numba") == numba.__version__ and meta.get("machine") == machine()):
            spec = importlib.util.spec_from_file_location(module_name(), path)
            module = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(module)
            found = {name: (getattr(module, name), [bytes.fromhex(f) for f in entry])
                     for name, entry in meta["fingerprints"].items()}
    except (OSError, ValueError, KeyError, ImportError, AttributeError):
        found = None
    _loaded[folder] = found
    return found


def kernel_for(name: str, args: Sequence, folder: Path | None = None):
    """The kernel ``name`` (:data:`KERNELS`) to call with ``args``.

    The precompiled one if it is there and ``args`` are exactly of its types, else the JIT
    kernel.
    """
    kernel = KERNELS[name]
    free = len(args) - len(kernel.bound)
    found = load(folder)
    if found is not None and name in found:
        fn, prints = found[name]
        try:
            if fingerprints(args[:free]) == prints:
                return fn if free == len(args) else (lambda *a: fn(*a[:free]))
        except (TypeError, ValueError):  # an argument numba cannot fingerprint
            pass
    return kernel.dispatcher


def run_rk4_for(args: Sequence, folder: Path | None = None):
    """The ``run_rk4`` to call with ``args`` (:func:`kernel_for`)."""
    return kernel_for("run_rk4", args, folder)


def _entry(kernel: Kernel):
    """A plain function calling the kernel with its own parameters.

    The AOT compiler compiles the function it exports with its default flags; exporting this
    call keeps the kernel compiled exactly as the JIT compiles it (``error_model="numpy"``).
    Its :attr:`Kernel.bound` parameters are not the entry's: the kernels they name are passed
    (and compiled in) here.
    """
    code = kernel.dispatcher.py_func.__code__
    names = list(code.co_varnames[:code.co_argcount])
    free = names[:len(names) - len(kernel.bound)]
    assert names[len(free):] == list(kernel.bound), "bound parameters come last, in order"
    src = f"def entry({', '.join(free)}):\n    return kernel({', '.join(names)})\n"
    scope = {"kernel": kernel.dispatcher, **kernel.bound}
    exec(compile(src, "<precompiled entry>", "exec"), scope)  # noqa: S102 - our own names
    return scope["entry"]


def build(examples: Mapping[str, Sequence], folder: Path | None = None,
          verbose: bool = False) -> Path:
    """Compile the kernels ahead of time into ``folder``; returns the module's path.

    Writes the module and its sidecar atomically and removes modules of other sources (the
    same compile the first runs would otherwise do).

    Args:
        examples: kernel name (:data:`KERNELS`) -> its arguments in a real run (with or
            without its :attr:`Kernel.bound` stages), whose types fix the module's signature;
            the kernels named are built.
        folder: where (default :data:`FOLDER`).
        verbose: the AOT compiler's messages.

    Raises:
        Exception: whatever numba's AOT compiler or the C toolchain raises (e.g. no compiler).
    """
    with warnings.catch_warnings():  # pending deprecation since numba 0.57, no successor yet:
        warnings.simplefilter("ignore", NumbaPendingDeprecationWarning)  # when it goes, the
        from numba.pycc import CC  # ImportError is a failed build, and the JIT is used

    chosen = [(KERNELS[n], tuple(args)) for n, args in examples.items()]
    folder = FOLDER if folder is None else Path(folder)
    name = module_name()
    with tempfile.TemporaryDirectory(dir=folder, prefix=".aot-") as tmp:
        cc = CC(name, __name__)
        cc.output_dir = tmp
        cc.target_cpu = "host"
        cc.verbose = verbose
        arguments, prints = {}, {}
        for kernel, args in chosen:
            free = kernel.dispatcher.py_func.__code__.co_argcount - len(kernel.bound)
            args = args[:free]
            types = [numba.typeof(a) for a in args]
            cc.export(kernel.name, RETURN_TYPE(*types))(_entry(kernel))
            arguments[kernel.name] = [str(t) for t in types]
            prints[kernel.name] = [f.hex() for f in fingerprints(args)]
        cc.compile()
        built = Path(tmp) / cc.output_file
        meta = {"digest": kernel_sources_digest(), "numba": numba.__version__,
                "machine": machine(), "arguments": arguments, "fingerprints": prints,
                "built": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
        side = Path(tmp) / "meta.json"
        side.write_text(json.dumps(meta, indent=1), encoding="utf-8")
        target = folder / cc.output_file
        os.replace(side, _sidecar(folder))
        os.replace(built, target)  # last: the module is seen only with its sidecar
    for old in folder.glob(PREFIX + "*"):
        if not old.name.startswith(name):
            old.unlink(missing_ok=True)
    _loaded.pop(folder, None)
    return target


__all__ = ["ENV_SWITCH", "KERNELS", "Kernel", "build", "fingerprints", "kernel_for", "load",
           "machine", "module_name", "run_rk4_for"]
