"""Stages of the loops called through function pointers: each compiled once.

numba compiles a kernel's callees into the kernel's own LLVM module: the code of every callee
is linked into the module of each caller and optimised and compiled to machine code again
there, once per level of the call tree above it. For the large stages of the loops (one
evaluation of the system: arm terms, blocks, controller, contact solve) that repeated work is
most of a first run's compile. A stage handed to a loop as a first-class function (numba's
``cfunc``: a C-callable function of one fixed signature) is compiled once, on its own, and
the loop calls it through its address: the loop's module holds the loop's own code only.
The code is the same; only where it is compiled changes.
"""

from __future__ import annotations

from collections.abc import Sequence

import numba
from numba._dispatcher import compute_fingerprint
from numba.core import config

_made: dict = {}  # (py_func, type_key of the arguments) -> cfunc


def type_key(args: Sequence) -> tuple:
    """A key of the numba types of ``args``, cheap to compute (numba's dispatch fingerprints).

    The fingerprint of each argument (dtype, dimensions, layout, writability; tuples element
    by element), computed in C, as numba's dispatcher does before it falls back to the much
    slower ``numba.typeof``. An argument numba cannot fingerprint (a function pointer) is
    keyed by its identity.
    """
    key = []
    for a in args:
        try:
            key.append(compute_fingerprint(a))
        except (TypeError, ValueError, NotImplementedError):
            key.append(("id", id(a)))
    return tuple(key)


def pointer(kernel, args: Sequence, result_type):
    """``kernel`` as a first-class function for the types of ``args`` (made once per process).

    Args:
        kernel: a kernel (``multiarm_pin._compiled.jit.kernel``).
        args: example arguments: their numba types are the signature.
        result_type: the numba type it returns.

    Returns:
        The compiled function (cached on disk as the kernels are), or ``kernel`` itself when
        the JIT is off (``NUMBA_DISABLE_JIT``: the loops then run as Python).
    """
    if config.DISABLE_JIT or not hasattr(kernel, "py_func"):
        return kernel
    key = (kernel.py_func, type_key(args))
    made = _made.get(key)
    if made is None:
        types = tuple(numba.typeof(a) for a in args)
        made = numba.cfunc(result_type(*types), cache=True, error_model="numpy")(kernel.py_func)
        _made[key] = made
    return made


def entry_point(kernel, args: Sequence):
    """The compiled specialisation of ``kernel`` for exactly the types of ``args``.

    Called without numba's dispatch, which types every argument again at every call (the
    function pointers through ``numba.typeof``); ``kernel`` itself when it is not compiled
    (``NUMBA_DISABLE_JIT``).
    Compiled or loaded from the cache here, not run. Only for arguments whose types are
    fixed by construction (the loop's own arrays): the entry point does not check them.
    """
    if not hasattr(kernel, "overloads"):
        return kernel
    key = (kernel, type_key(args))  # numba.typeof of every argument: once per types
    found = _entries.get(key)
    if found is None:
        found = _entries[key] = kernel.compile(tuple(numba.typeof(a) for a in args))
    return found


_entries: dict = {}  # (kernel, type_key of the arguments) -> entry point


__all__ = ["entry_point", "pointer", "type_key"]
