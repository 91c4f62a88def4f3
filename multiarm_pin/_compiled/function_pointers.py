"""Stages of the loops called through function pointers: each compiled once.

numba compiles a kernel's callees into the kernel's own LLVM module: the code of every callee
is linked into the module of each caller and optimised and compiled to machine code again
there, once per level of the call tree above it. For the large stages of the loops (one
evaluation of the system: arm terms, blocks, controller, contact solve) that repeated work is
most of a first run's compile. A stage handed to a loop as a first-class function (numba's
``cfunc``: a C-callable function of one fixed signature) is compiled once, on its own, and
the loop calls it through its address: the loop's module holds the loop's own code only.
The code is the same; only where it is compiled changes.

A caller's module needs only the *type* of a first-class function it calls
(:attr:`Compile.function_type`), not its code: the stages of a loop and the loop itself are
independent compiles. :func:`compile_all` runs them in this process and in child processes
at once, which share numba's disk cache (:mod:`~multiarm_pin._compiled.cache`): a first run
compiles on every core the machine gives it.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
import warnings
import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numba
from numba._dispatcher import compute_fingerprint
from numba.core import cgutils
from numba.core import types as nb_types
from numba.core.caching import FunctionCache
from numba.extending import intrinsic, overload

from multiarm_pin._compiled.cache import compile_lock, index_key
from multiarm_pin._compiled.jit import KernelCompiler, jit_disabled

PROCESSES_VARIABLE = "MULTIARM_PIN_COMPILE_PROCESSES"
"""Environment variable: how many processes :func:`compile_all` may use (``1``: this one
only). Unset: one per core this process may run on, at most :data:`DEFAULT_MOST_PROCESSES`."""

CHILD_TIMEOUT = 600.0
"""How long [s] :func:`compile_all` waits for its children once it has taken its last group.
A child still compiling then is stopped (``SIGKILL``), and its groups are compiled here."""

DEFAULT_MOST_PROCESSES = 4
"""Most processes :func:`compile_all` uses unless told otherwise: a loop has about ten groups,
one of them much larger than the others, which bounds the wall time beyond a few processes
(each of which compiles the shared small callees of its groups again)."""

_by_signature: dict = {}  # (py_func, signature) -> cfunc


@dataclass(frozen=True)
class Compile:
    """One compile of a kernel for fixed argument types.

    Attributes:
        kernel: a kernel (``multiarm_pin._compiled.jit.kernel``).
        types: the numba types of its arguments.
        result: the numba type it returns as a first-class function (a ``cfunc``), or
            ``None`` for the kernel's own entry point (an overload of its dispatcher).
    """

    kernel: Any
    types: tuple
    result: Any = None

    @property
    def function_type(self) -> nb_types.FunctionType:
        """The numba type of the first-class function: what a caller's signature holds."""
        return nb_types.FunctionType(self.result(*self.types))

    @property
    def pointer_type(self) -> nb_types.Tuple:
        """The numba type of :func:`pointer`'s ``(address, function type)``."""
        return nb_types.Tuple((nb_types.int64, nb_types.TypeRef(self.function_type)))


@dataclass(frozen=True)
class WarmUp:
    """Kernels compiled by calling them: ``run()`` calls them on a small example.

    For kernels whose argument types are simplest to get by running the code that calls
    them (the collision scan's, on two samples of a run's own state). A group of
    :func:`compile_all` may hold one. It runs only when :func:`compile_all` forks: in the
    process that takes its group (a child compiles into numba's disk cache, from which this
    process loads the kernels at their first call). Best effort: an error in ``run`` is
    dropped (the kernels are then compiled at their first call, as without it).
    """

    run: Callable[[], object]


_this_thread = threading.local()  # .riders: groups that ride along with its next compile_all


def _riders() -> list:
    if not hasattr(_this_thread, "riders"):
        _this_thread.riders = []
    return _this_thread.riders


def compile_with_next(group: Sequence) -> None:
    """Add ``group`` (:class:`Compile` or :class:`WarmUp` jobs) to the next compile_all here.

    To this thread's next :func:`compile_all`, taken after the first group of each process
    (:func:`_queue_order`): the compiles of a run's monitors fill the processes beside the
    loop's. Dropped if no call comes (:func:`forget`). Per thread: a run in another
    thread neither takes nor drops it.
    """
    _riders().append(tuple(group))


def forget(group: Sequence) -> None:
    """Drop ``group`` from the next :func:`compile_all`'s, if it is still waiting there."""
    key = tuple(group)
    _riders()[:] = [g for g in _riders() if g != key]


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


def _holds_type(a) -> bool:
    return isinstance(a, nb_types.Type) or (
        isinstance(a, tuple) and any(_holds_type(e) for e in a))


def numba_type(a):
    """The numba type of the argument ``a``; a numba type stands for an argument of that type.

    A tuple that holds numba types (the function types of stages not compiled yet) is typed
    element by element, as ``numba.typeof`` types a tuple.
    """
    if isinstance(a, nb_types.Type):
        return a
    if isinstance(a, tuple) and _holds_type(a):
        return nb_types.BaseTuple.from_types([numba_type(e) for e in a])
    return numba.typeof(a)


def compile_of(kernel, args: Sequence, result=None) -> Compile:
    """The :class:`Compile` of ``kernel`` for the types of the example arguments ``args``.

    Args:
        kernel: a kernel.
        args: example arguments, or their numba types (:func:`numba_type`).
        result: the return type of the first-class function, or ``None`` for the kernel's
            entry point.
    """
    return Compile(kernel, tuple(numba_type(a) for a in args), result)


def compiled(job: Compile):
    """The compiled function of ``job``: made, loaded from numba's disk cache, or compiled.

    A compile holds :func:`~multiarm_pin._compiled.cache.compile_lock`: a process that needs
    the same compile as another at once waits for it and loads its work from the cache.

    A first-class function is made once per process. A kernel's entry point is called
    without numba's dispatch, which types every argument again at every call (the function
    pointers through ``numba.typeof``): only for arguments whose types are fixed by
    construction (the loop's own arrays), as the entry point does not check them.

    Returns:
        The ``cfunc`` (``job.result`` given) or the entry point of the kernel's overload;
        ``job.kernel`` itself when the JIT is off (``NUMBA_DISABLE_JIT``: the loops then run
        as Python).
    """
    kernel = job.kernel
    if jit_disabled() or not hasattr(kernel, "py_func"):
        return kernel
    if job.result is None:
        if job.types in kernel.overloads:
            return kernel.compile(job.types)  # the overload made: returned as it is
        with compile_lock(kernel._cache, job.types):  # another process may be compiling it
            return kernel.compile(job.types)
    key = (kernel.py_func, job.result(*job.types))
    made = _by_signature.get(key)
    if made is None:
        with compile_lock(FunctionCache(kernel.py_func), key[1]):
            made = _by_signature[key] = numba.cfunc(  # without refcounts as the kernel says
                key[1], cache=True, error_model="numpy", pipeline_class=KernelCompiler,
                _nrt=kernel.targetoptions.get("_nrt", True))(kernel.py_func)
    return made


# ------------------------------------------------------------------ pointers from Python
def pointer(job: Compile):
    """``job``'s first-class function as an argument from Python: ``(address, function type)``.

    numba unboxes a first-class function passed from Python by calling back into Python for
    its addresses, at every call (microseconds each). A pointer is an integer, the address of
    the ``cfunc`` (kept alive in this module), and the function's numba type as a type
    reference, which holds no data: unboxing them costs next to nothing. A kernel makes the
    function from it by :func:`bind`. Without the JIT, the Python function itself.
    """
    function = compiled(job)
    if function is job.kernel:  # no JIT: the kernel is its Python function
        return function
    return (function.address, job.function_type)


def bind(pointers):
    """In a kernel: the functions of ``pointers`` (:func:`pointer`), in a tuple nested as given.

    Each pointer becomes its first-class function; anything else (a function already bound)
    stays as it is. Called from Python (no JIT), where pointers are the functions: returns
    ``pointers``.
    """
    return pointers


def _is_pointer(ty) -> bool:
    return (isinstance(ty, nb_types.BaseTuple) and len(ty) == 2
            and isinstance(ty[0], nb_types.Integer) and isinstance(ty[1], nb_types.TypeRef)
            and isinstance(ty[1].instance_type, nb_types.FunctionType))


def _bound_type(ty):
    if _is_pointer(ty):
        return ty[1].instance_type
    if isinstance(ty, nb_types.BaseTuple):
        return nb_types.BaseTuple.from_types([_bound_type(e) for e in ty])
    return ty


def _bound_value(context, builder, ty, value):
    """The LLVM value of ``_bound_type(ty)`` for ``value`` of type ``ty``."""
    if _is_pointer(ty):
        void_p = context.get_value_type(nb_types.voidptr)
        function = cgutils.create_struct_proxy(ty[1].instance_type)(context, builder)
        function.c_addr = builder.inttoptr(builder.extract_value(value, 0), void_p)
        function.py_addr = cgutils.get_null_value(void_p)  # no Python object behind it
        function.jit_addr = cgutils.get_null_value(void_p)  # called through c_addr
        return function._getvalue()
    if isinstance(ty, nb_types.BaseTuple):
        return context.make_tuple(builder, _bound_type(ty), [
            _bound_value(context, builder, e, builder.extract_value(value, i))
            for i, e in enumerate(ty)])
    return value


@intrinsic
def _bind(typingctx, pointers):
    def codegen(context, builder, signature, args):
        return _bound_value(context, builder, pointers, args[0])
    return _bound_type(pointers)(pointers), codegen


@overload(bind)
def _bind_overload(pointers):
    return lambda pointers: _bind(pointers)


# ------------------------------------------------------------------ compiling on every core
def _ready(job: Compile) -> bool:
    """True if ``job`` is compiled in this process or in numba's disk cache."""
    if isinstance(job, WarmUp):
        return False  # not known: it runs when a child takes it
    kernel = job.kernel
    if job.result is None:
        if job.types in kernel.overloads:
            return True
        cache = getattr(kernel, "_cache", None)
        signature = job.types
    else:
        signature = job.result(*job.types)
        if (kernel.py_func, signature) in _by_signature:
            return True
        cache = None
    try:
        if cache is None:
            cache = FunctionCache(kernel.py_func)
        return index_key(cache, signature) in cache._cache_file._load_index()
    except Exception:  # noqa: BLE001 - numba's cache internals: then it is not known ready
        return False


_thread_owners: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # -> thread id


def register_thread_owner(owner) -> None:
    """Let :func:`compile_all`, called from this thread, end ``owner``'s worker thread first.

    A child process is forked to compile only while this process runs no other Python
    thread (:func:`processes`). A worker thread that checks a run's samples beside its loop
    (the simulation's monitors) would otherwise keep every compile after its start (the
    loop's, at the run's first stretch) to one process.
    ``owner.end_worker()`` must end its one worker thread before it returns, its work under
    way done and its results kept; the owner starts a new thread when it next needs one. Only
    a :func:`compile_all` of the thread that registered the owner (the run's own) ends it:
    never a run in another thread, while the owner's thread may be using it. Held weakly: an
    owner that is gone is forgotten.
    """
    _thread_owners[owner] = threading.get_ident()


def processes() -> int:
    """How many processes :func:`compile_all` uses (:data:`PROCESSES_VARIABLE`, or the cores).

    One, this process, where a child cannot be forked safely: without ``os.fork`` (not
    Linux), or with other Python threads running (a Dask worker, a server), whose locks a
    forked child would inherit held.
    """
    if not sys.platform.startswith("linux") or threading.active_count() > 1:
        return 1
    value = os.environ.get(PROCESSES_VARIABLE, "").strip()
    if value:
        try:
            return max(1, int(value))
        except ValueError:
            return 1
    return max(1, min(DEFAULT_MOST_PROCESSES, len(os.sched_getaffinity(0))))


def _work(queue: int, groups: Sequence[Sequence[Compile]]) -> None:
    """Compile the groups whose numbers this process reads from the pipe ``queue``.

    One byte a read: a pipe hands each byte to one reader only.
    """
    while True:
        b = os.read(queue, 1)
        if not b:
            return
        for job in groups[b[0]]:
            if isinstance(job, WarmUp):
                try:
                    job.run()
                except Exception:  # noqa: BLE001 - best effort (WarmUp): compiled at first call
                    pass
            else:
                compiled(job)


def _reap(pids: Sequence[int], timeout: float) -> int:
    """Wait for the child processes ``pids``; stop those still running after ``timeout`` [s].

    Returns:
        How many were stopped (``SIGKILL``). What a stopped child had not saved is compiled
        again: numba writes each cache file whole (by a rename), and loading an entry whose
        index was written but whose data was not compiles it.
    """
    deadline = time.monotonic() + timeout
    left = list(pids)
    delay = 0.001
    while left:
        left = [pid for pid in left if os.waitpid(pid, os.WNOHANG)[0] == 0]
        if left and time.monotonic() >= deadline:
            for pid in left:
                try:
                    os.kill(pid, signal.SIGKILL)
                except OSError:
                    pass
                os.waitpid(pid, 0)
            return len(left)
        if left:
            time.sleep(delay)
            delay = min(2.0 * delay, 0.05)
    return 0


def _left(groups: Sequence[Sequence[Compile]]) -> list:
    """The groups with a compile not yet done, here or on disk."""
    return [g for g in groups if not all(_ready(j) for j in g)]


def _queue_order(own: list, riders: list, many: int) -> list:
    """The groups in the order the processes take them: ``riders`` after ``many`` of ``own``.

    The callers list their groups largest first, and a rider (the monitors' warm-up: a few
    seconds) is about as large as the middle ones: taken after the first group of each of the
    ``many`` processes, it goes ahead of the small groups that end the compile, where a rider
    taken last keeps the other processes waiting for it.
    """
    return [*own[:many], *riders, *own[many:]]


def compile_all(groups: Sequence[Sequence[Compile]]) -> None:
    """Compile ``groups`` of :class:`Compile` here and in child processes, at once.

    A group is compiled in order, in one process (kernels that share a large callee belong
    in one group: each process compiles the callees of its own groups); the processes take
    the next group from one queue, so list the larger ones first. The children compile into
    numba's disk cache and exit; this process then loads their work from it (a compile a
    child did not finish is done here). Groups already compiled, here or on disk, are not
    given to a child; with one group left, more than 256, or one process
    (:func:`processes`), all is done here. A child still compiling :data:`CHILD_TIMEOUT`
    seconds after this process took its last group is stopped, with a ``RuntimeWarning``,
    and what it had not saved is compiled here.

    The groups added by :func:`compile_with_next` are taken after the first group of each
    process (:func:`_queue_order`; a :class:`WarmUp` among them runs only when children are
    forked). With two groups or more left, the worker threads of the owners this thread
    registered (:func:`register_thread_owner`) are ended first, so that a child may be
    forked.

    Nothing is returned: :func:`compiled` then gives each compiled function without
    compiling.
    """
    riders = list(_riders())
    _riders().clear()
    if jit_disabled():
        return
    left = None  # (own groups, riders) not compiled yet, here or on disk
    here = threading.get_ident()
    mine = [owner for owner, thread in list(_thread_owners.items()) if thread == here]
    if mine and threading.active_count() > 1:
        left = _left(groups), _left(riders)
        if len(left[0]) + len(left[1]) > 1:  # worth a child: end the workers forbidding it
            for owner in mine:
                owner.end_worker()
    many = processes()
    # what is left to compile decides whether to fork: with one process, all is done here
    if left is None:
        left = (_left(groups), _left(riders)) if many > 1 else (list(groups), riders)
    todo = _queue_order(*left, many)
    # the queue holds a group's number in one byte: more groups are all done here
    children = min(many, len(todo)) - 1 if len(todo) <= 256 else 0
    if children > 0:
        read, write = os.pipe()
        os.write(write, bytes(range(len(todo))))
        os.close(write)
        pids = []
        try:
            for _ in range(children):
                with warnings.catch_warnings():
                    # Python 3.12+ warns at a fork beside any OS thread: no other Python
                    # thread runs (processes()), and OpenBLAS's pool handles fork itself
                    warnings.simplefilter("ignore", DeprecationWarning)
                    pid = os.fork()
                if pid == 0:  # the child: compile into the disk cache, then leave at once
                    status = 1
                    try:
                        # an interrupt ends the child at once (not the caller's handlers, which
                        # may hold signals while the run writes its results)
                        for s in (signal.SIGINT, signal.SIGTERM):
                            signal.signal(s, signal.SIG_DFL)
                        _work(read, todo)
                        status = 0
                    finally:
                        os._exit(status)
                pids.append(pid)
            _work(read, todo)
        except BaseException:
            for pid in pids:
                try:
                    os.kill(pid, signal.SIGTERM)
                except OSError:
                    pass
            raise
        finally:
            os.close(read)
            if _reap(pids, CHILD_TIMEOUT):
                warnings.warn(f"a compile process took more than {CHILD_TIMEOUT:g} s after the "
                              "last group was taken and was stopped; its kernels are compiled "
                              "in this process", RuntimeWarning, stacklevel=2)
    for group in todo:
        for job in group:
            if not isinstance(job, WarmUp):  # run by a child, or compiled at first call
                compiled(job)


__all__ = ["CHILD_TIMEOUT", "DEFAULT_MOST_PROCESSES", "PROCESSES_VARIABLE", "Compile", "WarmUp",
           "bind", "compile_all", "compile_of", "compile_with_next", "compiled", "forget",
           "numba_type", "pointer", "processes", "register_thread_owner", "type_key"]
