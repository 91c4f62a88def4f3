"""The one decorator of every compiled kernel: :func:`kernel`.

``@kernel`` is ``numba.njit(cache=True, error_model="numpy")`` (cached on disk, numpy's
floating-point semantics: a division by zero gives inf or NaN, never an exception), with one
difference in how a kernel called from another kernel is specialised: by the types of its
arguments, never by their literal values.

numba types a constant argument (``f(x, 0)``, ``f(x, True)``) and, during type inference, a
variable not yet unified with its later values (``n = 0`` before ``n += 1`` in a loop) as a
*literal* type (``Literal[int](0)``), and compiles the callee once for that literal and again
for ``int64``. Each such specialisation is a full compile of the callee and of everything it
calls. The kernels never branch on an argument's literal value, so here a call's argument
types are made non-literal before the callee is looked up: one specialisation per
argument types.
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
        Its numba dispatcher (``OPTIONS`` and ``options``), specialised by argument types only
        when called from another kernel (see the module).
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
    callee = njit(**OPTIONS, **options, no_cpython_wrapper=True, no_cfunc_wrapper=True)(twin)
    return _typed_by_types(dispatcher, callee)


def jit_disabled() -> bool:
    """True when numba's JIT is off (``NUMBA_DISABLE_JIT``): the kernels then run as Python."""
    return bool(config.DISABLE_JIT)


__all__ = ["CALLEE_SUFFIX", "OPTIONS", "jit_disabled", "kernel"]
