"""The one decorator of every compiled kernel: :func:`kernel`.

``@kernel`` is ``numba.njit(cache=True, error_model="numpy")`` (cached on disk, numpy's
floating-point semantics: a division by zero gives inf or NaN, never an exception), with two
differences in how a kernel called from another kernel is compiled: it is specialised by the
types of its arguments, never by their literal values, and it is compiled without numba's
wrappers.

numba types a constant argument (``f(x, 0)``, ``f(x, True)``) and, during type inference, a
variable not yet unified with its later values (``n = 0`` before ``n += 1`` in a loop) as a
*literal* type (``Literal[int](0)``), and compiles the callee once for that literal and again
for ``int64``. Each such specialisation is a full compile of the callee and of everything it
calls. The kernels never branch on an argument's literal value, so here a call's argument
types are made non-literal before the callee is looked up: one specialisation per
argument types.

numba compiles with every function a wrapper for calls from Python (it unboxes each
argument: for the loops' tuples of arrays, code about as large as the kernel's own) and one
for its use as a first-class function. A kernel called from another kernel uses neither: the
calls from compiled code are served by a twin dispatcher of the same Python function compiled
without them (``no_cpython_wrapper``, ``no_cfunc_wrapper``; its disk cache files are named by
its ``__qualname__``, the kernel's and :data:`CALLEE_SUFFIX`). Calls from Python take the
dispatcher :func:`kernel` returns, which compiles its own overloads with both wrappers: a
twin's overload has no entry point for Python.
"""

from __future__ import annotations

import types as py_types

from numba import njit, types
from numba.core import config

OPTIONS = {"cache": True, "error_model": "numpy"}
"""The options every kernel is compiled with (:func:`kernel` adds ``inline``, ``nogil``)."""


CALLEE_SUFFIX = "__in_kernels"
"""Added to a kernel's ``__qualname__`` for the dispatcher that compiled callers call (its
disk cache files are named by it)."""


def _typed_by_types(dispatcher, callee=None):
    """``dispatcher`` with its calls from compiled code typed by non-literal argument types.

    Args:
        dispatcher: a numba dispatcher.
        callee: the dispatcher that compiles and serves those calls instead (the same Python
            function compiled without the wrappers for calls from Python); ``None``:
            ``dispatcher`` itself.

    Without the JIT (``NUMBA_DISABLE_JIT``) ``njit`` returns the Python function: returned as is.
    """
    find = getattr(dispatcher, "get_call_template", None)
    if find is None:
        return dispatcher
    if callee is not None:
        find = callee.get_call_template
        dispatcher.get_overload = callee.get_overload  # the compiled call's implementation

    def get_call_template(args, kws):
        return find(tuple(types.unliteral(a) for a in args),
                    {k: types.unliteral(v) for k, v in kws.items()})

    dispatcher.get_call_template = get_call_template
    return dispatcher


def kernel(function=None, **options):
    """Compile ``function`` as a kernel (``@kernel`` or ``@kernel(inline="always")``).

    Args:
        function: the Python function (numba's ``nopython`` subset).
        **options: further ``numba.njit`` options (``inline``, ``nogil``).

    Returns:
        Its numba dispatcher (``OPTIONS`` and ``options``) for calls from Python; calls from
        another kernel are served by its twin, specialised by argument types only (see the
        module).
    """
    if function is None:
        return lambda f: kernel(f, **options)
    dispatcher = njit(**OPTIONS, **options)(function)
    if "inline" in options or not hasattr(dispatcher, "get_call_template"):
        return _typed_by_types(dispatcher)  # inlined (or no JIT): no call to serve
    twin = py_types.FunctionType(function.__code__, function.__globals__, function.__name__,
                                 function.__defaults__, function.__closure__)
    twin.__qualname__ = function.__qualname__ + CALLEE_SUFFIX
    twin.__module__ = function.__module__
    twin.__doc__ = function.__doc__
    twin.__kwdefaults__ = function.__kwdefaults__
    callee = njit(**OPTIONS, **options, no_cpython_wrapper=True, no_cfunc_wrapper=True)(twin)
    return _typed_by_types(dispatcher, callee)


def jit_disabled() -> bool:
    """True when numba's JIT is off (``NUMBA_DISABLE_JIT``): the kernels then run as Python."""
    return bool(config.DISABLE_JIT)


__all__ = ["CALLEE_SUFFIX", "OPTIONS", "jit_disabled", "kernel"]
