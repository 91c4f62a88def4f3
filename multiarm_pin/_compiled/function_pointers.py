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
from numba.core import config

_made: dict = {}  # (py_func, argument types) -> cfunc


def pointer(kernel, args: Sequence, result_type):
    """``kernel`` as a first-class function for the types of ``args`` (made once per process).

    Args:
        kernel: a ``@njit`` kernel (``error_model="numpy"``).
        args: example arguments: their numba types are the signature.
        result_type: the numba type it returns.

    Returns:
        The compiled function (cached on disk as the kernels are), or ``kernel`` itself when
        the JIT is off (``NUMBA_DISABLE_JIT``: the loops then run as Python).
    """
    if config.DISABLE_JIT or not hasattr(kernel, "py_func"):
        return kernel
    types = tuple(numba.typeof(a) for a in args)
    key = (kernel.py_func, types)
    made = _made.get(key)
    if made is None:
        made = numba.cfunc(result_type(*types), cache=True, error_model="numpy")(kernel.py_func)
        _made[key] = made
    return made


__all__ = ["pointer"]
