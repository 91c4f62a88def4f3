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
dispatcher :func:`kernel` returns, which compiles its own overloads with the first wrapper only
(a first-class function of a kernel is a ``cfunc`` of its own:
:mod:`~multiarm_pin._compiled.function_pointers`): a twin's overload has no entry point for
Python. A loop's entry point (``@kernel(loop=True)``) is called from Python once per run,
or per stretch of samples: its wrapper is left unoptimised (:class:`_LoopLibrary`).

numba counts the references to every array a function holds: an array argument is counted as
the function starts and released on every path out of it, each array of a tuple argument
too. The loops' kernels take tuples of about a hundred arrays and have many paths out: that
code grows with the product of the two. A kernel whose call tree allocates no array needs
none of it: every array it holds is its caller's, alive for the whole call.
``@kernel(refcounts=False)`` compiles such a kernel without reference counting (numba's
``_nrt=False``), and its callees likewise: calls from a caller compiled so are served by a
second twin compiled without it (its cache files named with :data:`BORROWED_SUFFIX`), never
by the twin that serves other callers (a callee compiled without counting that returned an
array would give its caller a reference it does not own). numba refuses to compile an
allocation without reference counting, so a kernel that allocates cannot be marked so by
mistake. A kernel marked so returns no array (a caller's compile is refused otherwise,
with a ``TypeError``), and its twin without counting serves every caller: a callee
that neither allocates nor returns an array takes and gives no reference, so a caller
that counts its own may call it. Such a callee is then compiled once, not once for the
callers that count and again for those that do not.

numba compiles a callee into its own module, optimises that module, and links a copy of it
into the module of every caller, which it optimises again as a whole (the callee's code is
inlined there and optimised with its caller's). A twin's own module is made for that linking
and for the disk cache: a caller loaded from the cache carries its own optimised copy of its
callees. So the twins are compiled by :class:`LinkedCompiler`, which skips the whole-module
optimisation of a twin's module: its functions are still optimised one by one, and every
caller's module is optimised as before, callees included. Nor is a twin's own module made
machine code: no caller calls it (each calls its own copy), so only its callers' code is.

LLVM optimises every kernel's code without its loop vectoriser (:data:`LLVM_PASSES`), which
numba runs by default: the kernels work on small arrays (6-vectors, a few joints, a few
contact rows), whose loops the vectoriser multiplies into vector, remainder and checking
copies that such trip counts seldom run. Only the kernels' passes are changed
(``NUMBA_LOOP_VECTORIZE`` still governs every other function of the process; ``NUMBA_OPT``
sets the level of all): the results are the same bits, the code is smaller and compiles
faster.
"""

from __future__ import annotations

import types as py_types
from contextlib import contextmanager

from numba import njit, types
from numba.core import codegen, config
from numba.core.compiler import Compiler
from numba.core.compiler_lock import global_compiler_lock
from numba.core.datamodel import default_manager
from numba.core.targetconfig import ConfigStack

OPTIONS = {"cache": True, "error_model": "numpy"}
"""The options every kernel is compiled with (:func:`kernel` adds ``inline``, ``nogil``)."""


CALLEE_SUFFIX = "__in_kernels"
"""Added to a kernel's ``__qualname__`` for the dispatcher that compiled callers call (its
disk cache files are named by it)."""

LLVM_PASSES = {"loop_vectorize": False}
"""numba's pass builder's arguments for the kernels' code: LLVM's loop vectoriser off (see
the module)."""

ENV_PREFIX = "_ZN08NumbaEnv"
"""How numba's names of the functions' environment pointers (LLVM globals) begin."""

WRAPPER_PREFIX = "_ZN7cpython"
"""How numba's names of the wrappers for calls from Python (LLVM functions) begin."""

BORROWED_SUFFIX = "__borrowed"
"""Added after :data:`CALLEE_SUFFIX` for the twin that serves callers compiled without reference
counting (its disk cache files are named by it)."""


def _typed_by_types(dispatcher, callee=None, borrowed=None):
    """``dispatcher`` with its calls from compiled code typed by non-literal argument types.

    Args:
        dispatcher: a numba dispatcher.
        callee: the dispatcher that compiles and serves those calls instead (the same Python
            function compiled without the wrappers for calls from Python); ``None``:
            ``dispatcher`` itself.
        borrowed: a function returning the dispatcher that serves the calls from a caller
            compiled without reference counting (the twin compiled without it); ``None``:
            ``callee`` serves them too (with ``callee`` compiled without reference counting,
            ``refcounts=False``, a call whose result would hold an array is refused).

    Without the JIT (``NUMBA_DISABLE_JIT``) ``njit`` returns the Python function: returned as is.
    """
    own = getattr(dispatcher, "get_call_template", None)
    if own is None:
        return dispatcher
    router = _Router(own, callee, borrowed)
    dispatcher.get_call_template = router.get_call_template
    if callee is not None:  # the compiled call's implementation
        dispatcher.get_overload = router.get_overload
    return dispatcher


class _Router:
    """Serves a kernel's calls from compiled code (:func:`_typed_by_types`'s arguments)."""

    def __init__(self, own, callee, borrowed):
        self.own, self.callee, self._borrowed = own, callee, borrowed

    def serving(self):
        """The twin for the caller being compiled (the top of numba's configuration stack)."""
        if self._borrowed is not None and not getattr(ConfigStack.top_or_none(), "nrt", True):
            return self._borrowed()
        return self.callee

    def get_call_template(self, args, kws):
        find = self.own if self.callee is None else self.serving().get_call_template
        found = find(tuple(types.unliteral(a) for a in args),
                     {k: types.unliteral(v) for k, v in kws.items()})
        if self.callee is not None and self.callee.targetoptions.get("_nrt") is False:
            # refcounts=False: its one twin serves every caller, so no array may come back
            result = self.callee.overloads[tuple(found[2])].signature.return_type
            if default_manager.lookup(result).contains_nrt_meminfo():
                name = self.callee.py_func.__qualname__.removesuffix(CALLEE_SUFFIX
                                                                     + BORROWED_SUFFIX)
                raise TypeError(f"kernel {name!r} is compiled without reference counting "
                                f"(refcounts=False) but returns {result}, which holds an "
                                "array: its callers would release a reference not theirs")
        return found

    def get_overload(self, sig):
        return self.serving().get_overload(sig)


@contextmanager
def _kernel_passes(made):
    """The pass managers of numba for the codegen ``made``, built with :data:`LLVM_PASSES`.

    For the optimisation of one library's code, under numba's compiler lock (re-entrant):
    no other thread optimises a function's code with them meanwhile.
    """
    with global_compiler_lock:
        if "_module_pass_manager" in vars(made):  # within another library's optimisation
            yield
            return
        module, function = made._module_pass_manager, made._function_pass_manager

        def with_passes(build):
            return lambda **kwargs: build(**{**LLVM_PASSES, **kwargs})

        made._module_pass_manager = with_passes(module)
        made._function_pass_manager = with_passes(function)
        try:
            yield
        finally:
            del made._module_pass_manager, made._function_pass_manager


class _KernelLibrary(codegen.JITCodeLibrary):
    """A kernel's code library: optimised with :data:`LLVM_PASSES`."""

    def _optimize_functions(self, ll_module):
        """The function passes of numba, with :data:`LLVM_PASSES`."""
        with _kernel_passes(self._codegen):
            super()._optimize_functions(ll_module)

    def _optimize_final_module(self):
        """The module passes of numba, with :data:`LLVM_PASSES` (its first, cheap, pass as is)."""
        with _kernel_passes(self._codegen):
            super()._optimize_final_module()


class _LoopLibrary(_KernelLibrary):
    """A loop's entry point's code library: its Python wrapper not optimised at all.

    The wrapper for calls from Python (:data:`WRAPPER_PREFIX`) unboxes each argument, calls
    the kernel and boxes its result: straight-line code as long as the loop's tuples of
    arrays, run once per call from Python, which for a loop's entry point is once per run
    (or per stretch of samples). It is marked ``optnone`` (with ``noinline``, which
    ``optnone`` requires): LLVM's passes skip it and its machine code is made without
    optimisation. The kernel it calls is optimised as every kernel is. (Unoptimised, the
    wrapper is slower at every call: kernels called from Python at every step keep the
    optimised one.)
    """

    def add_ir_module(self, ir_module):
        """Add ``ir_module`` (numba's ``add_ir_module``), its Python wrapper marked ``optnone``."""
        for function in ir_module.functions:
            if function.name.startswith(WRAPPER_PREFIX) and not function.is_declaration:
                function.attributes.add("noinline")
                function.attributes.add("optnone")
        super().add_ir_module(ir_module)


class _LinkedLibrary(_KernelLibrary):
    """A twin's code library: optimised function by function only, and made no machine code.

    Its module is kept for its callers to link (numba's module for linking, its functions
    ``linkonce_odr``): no caller calls a twin's own machine code, so numba's engine gets a
    module in its place that holds only the function's environment pointer (a global that
    numba sets by name once the function is compiled or loaded). Its object code, for the
    disk cache, is that module's; the cache keeps the module for linking beside it.
    """

    def _optimize_final_module(self):
        """Nothing: every caller optimises this code as part of its own module."""

    def _finalize_final_module(self):
        """The finalisation of numba, of an empty module; the full one kept for linking only."""
        self._finalize_dynamic_globals()  # of the full module (numba's cache checks them)
        self._verify_declare_only_symbols()
        linked = self._final_module
        for function in linked.functions:  # as numba's _get_module_for_linking makes them
            if not function.is_declaration and function.linkage == codegen.ll.Linkage.external:
                function.linkage = "linkonce_odr"
        self._shared_module = linked
        # the engine's module: the environment pointers only, which numba sets by name
        env = "".join(f"{v}\n" for v in linked.global_variables if v.name.startswith(ENV_PREFIX))
        self._final_module = codegen.ll.parse_assembly(  # numba's llvmlite binding
            str(self._codegen._create_empty_module(self.name)) + env)
        super()._finalize_final_module()

    def get_llvm_str(self):
        """The module its callers link, once finalised (the engine's holds no function)."""
        return str(self._final_module if self._shared_module is None else self._shared_module)


class KernelCompiler(Compiler):
    """numba's compiler, its code library a :class:`_KernelLibrary` (a kernel's ``pipeline_class``).

    The library numba makes in its lowering pass (with its function's qualified name and
    object caching on, for the disk cache) is made here instead, of the subclass.
    """

    library_class = _KernelLibrary

    def compile_extra(self, func):
        """Compile ``func`` (numba's ``Compiler.compile_extra``) into a :attr:`library_class`."""
        made = self.state.targetctx.codegen()
        if self.state.library is None and made._library_class is codegen.JITCodeLibrary:
            self.state.library = self.library_class(made, func.__qualname__)
            self.state.library.enable_object_caching()
        return super().compile_extra(func)


class LoopCompiler(KernelCompiler):
    """:class:`KernelCompiler` with a :class:`_LoopLibrary` (a loop's entry point's)."""

    library_class = _LoopLibrary


class LinkedCompiler(KernelCompiler):
    """:class:`KernelCompiler` with a :class:`_LinkedLibrary` (a twin's ``pipeline_class``)."""

    library_class = _LinkedLibrary


def _twin(function, suffix: str, **options):
    """``function`` compiled for calls from kernels only, its cache files named by ``suffix``."""
    twin = py_types.FunctionType(function.__code__, function.__globals__, function.__name__,
                                 function.__defaults__, function.__closure__)
    twin.__qualname__ = function.__qualname__ + suffix
    twin.__module__ = function.__module__
    twin.__doc__ = function.__doc__
    twin.__kwdefaults__ = function.__kwdefaults__
    return njit(**OPTIONS, **options, no_cpython_wrapper=True, no_cfunc_wrapper=True,
                pipeline_class=LinkedCompiler)(twin)


def kernel(function=None, *, refcounts: bool = True, loop: bool = False, **options):
    """Compile ``function`` as a kernel (``@kernel`` or ``@kernel(inline="always")``).

    Args:
        function: the Python function (numba's ``nopython`` subset).
        refcounts: ``False``: compiled without reference counting (numba's ``_nrt=False``),
            and so are its callees; one twin serves every kernel that calls it (see the
            module). For a kernel whose call tree allocates no array and which returns none.
        loop: ``True`` for a loop's entry point, called from Python once per run (or per
            stretch of samples): its Python wrapper is compiled without optimisation
            (:class:`_LoopLibrary`).
        **options: further ``numba.njit`` options (``inline``, ``nogil``).

    Returns:
        Its numba dispatcher (``OPTIONS`` and ``options``) for calls from Python; calls from
        another kernel are served by its twins, specialised by argument types only (see the
        module).
    """
    if function is None:
        return lambda f: kernel(f, refcounts=refcounts, loop=loop, **options)
    dispatcher = njit(**OPTIONS, **options, **({} if refcounts else {"_nrt": False}),
                      no_cfunc_wrapper=True,
                      pipeline_class=LoopCompiler if loop else KernelCompiler)(function)
    if "inline" in options or not hasattr(dispatcher, "get_call_template"):
        return _typed_by_types(dispatcher)  # inlined (or no JIT): no call to serve

    def borrowed_twin():  # the twin compiled without reference counting
        return _twin(function, CALLEE_SUFFIX + BORROWED_SUFFIX, **options, _nrt=False)

    if not refcounts:  # one twin, without counting, serves every caller (see the module)
        return _typed_by_types(dispatcher, borrowed_twin())
    callee = _twin(function, CALLEE_SUFFIX, **options, _nrt=True)
    made = []

    def borrowed():
        if not made:
            made.append(borrowed_twin())
        return made[0]

    return _typed_by_types(dispatcher, callee, borrowed)


def jit_disabled() -> bool:
    """True when numba's JIT is off (``NUMBA_DISABLE_JIT``): the kernels then run as Python."""
    return bool(config.DISABLE_JIT)


__all__ = ["BORROWED_SUFFIX", "CALLEE_SUFFIX", "LLVM_PASSES", "OPTIONS", "KernelCompiler",
           "LinkedCompiler", "LoopCompiler", "jit_disabled", "kernel"]
