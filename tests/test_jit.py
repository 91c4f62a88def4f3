"""The kernels' decorator: one specialisation per argument types, never per literal value."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import numba
import numpy as np
import pytest
from numba import njit, types
from numba.core import config

from multiarm_pin._compiled import jit

PACKAGE = Path(jit.__file__).resolve().parent

needs_jit = pytest.mark.skipif(config.DISABLE_JIT, reason="specialisations need the JIT")


@needs_jit
def test_a_callee_is_compiled_once_for_literal_and_variable_arguments():
    callee = jit._typed_by_types(njit(lambda a, n, flag: a + n if flag else a))

    @njit
    def caller(a):
        n = 0
        s = callee(a, n, True)  # n is Literal[int](0) in the first pass of type inference
        for _ in range(3):
            n += 1
        return s + callee(a, 0, False) + callee(a, n, np.True_)

    assert caller(1.0) == 1.0 + 1.0 + 4.0
    assert len(callee.signatures) == 1
    assert not any(isinstance(t, types.Literal) for t in callee.signatures[0])


@needs_jit
def test_without_the_hook_numba_compiles_a_literal_specialisation():
    """The case the hook exists for (if numba stops doing this, the hook can go)."""
    callee = njit(lambda a, n: a + n)

    @njit
    def caller(a):
        return callee(a, 0) + callee(a, np.int64(0))

    caller(1.0)
    assert len(callee.signatures) == 2


@needs_jit
def test_a_kernel_called_from_a_kernel_is_its_twin_without_python_wrappers(monkeypatch):
    monkeypatch.setattr(jit, "OPTIONS", {"error_model": "numpy"})  # no disk cache here

    def add(a, n):
        return a + n

    callee = jit.kernel(add)
    caller = jit.kernel(lambda a: callee(a, 2.0) * 3.0)
    assert caller(1.0) == 9.0
    twin = callee.get_overload.__self__.callee  # the dispatcher compiled callers call
    assert twin is not callee and callee.signatures == []
    assert len(twin.signatures) == 1
    assert twin.py_func.__qualname__ == add.__qualname__ + jit.CALLEE_SUFFIX
    assert twin.targetoptions["no_cpython_wrapper"] and twin.targetoptions["no_cfunc_wrapper"]
    # from Python, the same types: compiled again with its wrappers (the twin's entry point
    # has none, and calling it from Python would crash)
    assert callee(1.0, 2.0) == 3.0
    assert len(callee.signatures) == 1
    assert not callee.targetoptions.get("no_cpython_wrapper", False)


def test_every_kernel_is_compiled_by_the_one_decorator():
    """No ``numba.njit`` outside :mod:`multiarm_pin._compiled.jit`: one set of options."""
    bare = []
    for path in sorted(PACKAGE.glob("*.py")):
        if path.name == "jit.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Name) and node.id == "njit":
                bare.append(f"{path.name}:{node.lineno}")
            if isinstance(node, ast.Attribute) and node.attr == "njit":
                bare.append(f"{path.name}:{node.lineno}")
    assert bare == []


def test_the_decorator_keeps_numbas_options():
    assert jit.OPTIONS == {"cache": True, "error_model": "numpy"}
    if not config.DISABLE_JIT:
        k = jit.kernel(inline="always")(lambda a: a)
        assert k.targetoptions["inline"] == "always"
        assert k.targetoptions["error_model"] == "numpy"


@needs_jit
def test_a_kernel_without_refcounts_calls_its_callees_own_twin(monkeypatch):
    """Callers compiled without reference counting are served by a second twin, never the first.

    A callee compiled without counting that returned an array would give a counting caller a
    reference it does not own: unless the callee is marked ``refcounts=False`` (it then
    returns no array), the two kinds of callers never share a compiled callee.
    """
    monkeypatch.setattr(jit, "OPTIONS", {"error_model": "numpy"})  # no disk cache here

    def scale(a, s):
        for j in range(a.shape[0]):
            a[j] *= s

    callee = jit.kernel(scale)

    def twice(a):
        callee(a, 2.0)
        callee(a, 2.0)

    counted = jit.kernel(twice)
    borrowed = jit.kernel(refcounts=False)(twice)
    router = callee.get_overload.__self__
    a = np.ones(3)
    borrowed(a)
    twin, twin_borrowed = router.callee, router._borrowed()
    assert twin.signatures == [] and len(twin_borrowed.signatures) == 1
    assert twin_borrowed.targetoptions["_nrt"] is False
    assert twin_borrowed.py_func.__qualname__ == (scale.__qualname__ + jit.CALLEE_SUFFIX
                                                  + jit.BORROWED_SUFFIX)
    counted(a)
    assert len(twin.signatures) == 1 and twin.targetoptions["_nrt"] is True
    np.testing.assert_array_equal(a, np.full(3, 16.0))
    assert borrowed.targetoptions["_nrt"] is False and "_nrt" not in counted.targetoptions


@needs_jit
def test_a_kernel_without_refcounts_is_one_twin_for_every_caller(monkeypatch):
    """A callee marked ``refcounts=False`` is compiled once, for counting callers and others."""
    monkeypatch.setattr(jit, "OPTIONS", {"error_model": "numpy"})  # no disk cache here

    def scale(a, s):
        for j in range(a.shape[0]):
            a[j] *= s

    callee = jit.kernel(refcounts=False)(scale)

    def twice(a):
        callee(a, 2.0)
        callee(a, 2.0)

    counted = jit.kernel(twice)
    borrowed = jit.kernel(refcounts=False)(twice)
    a = np.ones(3)
    counted(a)
    borrowed(a)
    router = callee.get_overload.__self__
    assert router._borrowed is None  # no second twin
    assert len(router.callee.signatures) == 1 and router.callee.targetoptions["_nrt"] is False
    assert router.callee.py_func.__qualname__ == (scale.__qualname__ + jit.CALLEE_SUFFIX
                                                  + jit.BORROWED_SUFFIX)
    np.testing.assert_array_equal(a, np.full(3, 16.0))


@needs_jit
def test_a_kernel_without_refcounts_may_not_return_an_array(monkeypatch):
    """Its caller would release a reference it was never given: the compile is refused."""
    monkeypatch.setattr(jit, "OPTIONS", {"error_model": "numpy"})

    def same(a):
        return a  # numba compiles this without counting (the argument itself, no new array)

    callee = jit.kernel(refcounts=False)(same)
    with pytest.raises(TypeError) as refused:
        jit.kernel(lambda a: callee(a).sum())(np.ones(3))
    assert "which holds an array: its callers would release" in str(refused.value)
    counted = jit.kernel(same)  # the default: a counting twin, which may return it
    assert jit.kernel(lambda a: counted(a).sum())(np.ones(3)) == 3.0


@needs_jit
def test_numba_refuses_an_allocation_without_refcounts(monkeypatch):
    """What makes ``refcounts=False`` safe to declare: an allocation does not compile."""
    monkeypatch.setattr(jit, "OPTIONS", {"error_model": "numpy"})

    def first_of_zeros(n):
        z = np.zeros(n)
        return z[0]

    callee = jit.kernel(first_of_zeros)
    with pytest.raises(numba.TypingError, match="Only accept returning of array"):
        jit.kernel(refcounts=False)(lambda n: callee(n))(3)  # np.zeros's own, without counting
    assert jit.kernel(lambda n: callee(n))(3) == 0.0


@needs_jit
def test_a_twins_module_is_left_for_its_callers_to_optimise(monkeypatch):
    """A twin's own module is optimised function by function only; its callers' as a whole.

    The middle kernel's twin still calls the inner one (no whole-module pass inlined it);
    the entry point, compiled from Python with numba's own pipeline, has both inlined.
    """
    monkeypatch.setattr(jit, "OPTIONS", {"error_model": "numpy"})  # no disk cache here

    def add_one(a):
        return a + 1.0

    inner = jit.kernel(add_one)
    middle = jit.kernel(lambda a: inner(a) * 2.0)
    outer = jit.kernel(lambda a: middle(a) - 3.0)
    assert outer(1.0) == 1.0

    def calls(library, name):
        return [line for line in library.get_llvm_str().splitlines()
                if " call " in line and name in line]

    twin = middle.get_overload.__self__.callee
    twin_library = next(iter(twin.overloads.values())).library
    assert isinstance(twin_library, jit._LinkedLibrary)
    assert calls(twin_library, add_one.__name__ + jit.CALLEE_SUFFIX)
    entry_library = next(iter(outer.overloads.values())).library
    assert not isinstance(entry_library, jit._LinkedLibrary)
    assert calls(entry_library, jit.CALLEE_SUFFIX) == []


@needs_jit
def test_a_loops_python_wrapper_is_not_optimised(monkeypatch):
    """``loop=True``: the wrapper for calls from Python is ``optnone``, the kernel is not.

    Read from the modules' text: the attributes of the wrapper's definition hold
    ``optnone`` and ``noinline``, those of the kernel's do not (LLVM's passes gave it
    theirs, ``nounwind`` among them); without ``loop`` neither is ``optnone``.
    """
    monkeypatch.setattr(jit, "OPTIONS", {"error_model": "numpy"})  # no disk cache here

    def total(t):
        return t[0][0] + t[1][1]

    def attributes(entry):
        """(the wrapper's, the kernel's) attribute names, from the module's text."""
        assert entry((np.ones(2), np.arange(3.0))) == 2.0
        text = next(iter(entry.overloads.values())).library.get_llvm_str()
        groups = dict(re.findall(r"^attributes (#\d+) = \{([^}]*)\}", text, re.M))
        defined = {name: set(" ".join(groups[g] for g in refs.split()).split())
                   for name, refs in re.findall(
                       r"^define [^@]*@(\S+?)\(.*\)[^#]*((?:#\d+ ?)+)", text, re.M)}
        wrapper = [a for name, a in defined.items() if name.startswith(jit.WRAPPER_PREFIX)]
        own = [a for name, a in defined.items()
               if total.__name__ in name and not name.startswith(jit.WRAPPER_PREFIX)]
        assert len(wrapper) == 1 and len(own) == 1
        return wrapper[0], own[0]

    wrapper, own = attributes(jit.kernel(total, loop=True))
    assert {"optnone", "noinline"} <= wrapper
    assert "optnone" not in own and "nounwind" in own
    wrapper, own = attributes(jit.kernel(total))
    assert "optnone" not in wrapper and "optnone" not in own


@needs_jit
@pytest.mark.skipif(not config.LOOP_VECTORIZE, reason="numba's loop vectoriser is off here")
def test_kernels_are_optimised_without_the_loop_vectoriser(monkeypatch):
    """A kernel's loops stay scalar (``LLVM_PASSES``); numba's own ``njit`` still vectorises.

    The same loop compiled both ways: numba's default pipeline makes vector instructions
    of it, the kernel's none; both give the same sums.
    """
    monkeypatch.setattr(jit, "OPTIONS", {"error_model": "numpy"})  # no disk cache here

    def add(a, b, out):
        for i in range(out.shape[0]):
            out[i] = a[i] + b[i]

    a, b = np.arange(64.0), np.ones(64)
    outs = [np.zeros(64), np.zeros(64)]
    ours, numbas = jit.kernel(add), numba.njit(add)
    ours(a, b, outs[0])
    numbas(a, b, outs[1])
    assert np.array_equal(outs[0], a + b) and np.array_equal(outs[1], a + b)

    def vector_lines(dispatcher):
        library = next(iter(dispatcher.overloads.values())).library
        return [line for line in library.get_llvm_str().splitlines() if " x double>" in line]

    assert isinstance(next(iter(ours.overloads.values())).library, jit._KernelLibrary)
    assert vector_lines(numbas)
    assert vector_lines(ours) == []
