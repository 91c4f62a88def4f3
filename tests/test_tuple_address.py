"""Tuples passed by their address (``_compiled.tuple_address``): same values, one argument."""

from __future__ import annotations

import sys

import numba
import numpy as np
import pytest
from numba.core import config

from multiarm_pin._compiled.function_pointers import compile_of
from multiarm_pin._compiled.jit import kernel
from multiarm_pin._compiled.tuple_address import TupleAddress, address, tuple_at

needs_jit = pytest.mark.skipif(config.DISABLE_JIT, reason="addresses need the JIT")


@kernel
def _reads(t):  # pragma: no cover - compiled
    a, b, c = tuple_at(t)
    return a[0] + 10.0 * b[1, 0] + 100.0 * t[2][1] + 1000.0 * t[-1][0] + c.shape[0]


@kernel
def _writes(t, value):  # pragma: no cover - compiled
    t[1][0, 1] = value
    return _reads(t)


@kernel
def _by_address(t, value):  # pragma: no cover - compiled
    total = 0.0
    at = address(t)
    for _ in range(3):
        total += _writes(at, value)
    return total, _reads(address(at))  # an address of an address: itself


@kernel
def _by_value(t, value):  # pragma: no cover - compiled
    total = 0.0
    for _ in range(3):
        total += _writes(t, value)
    return total, _reads(t)


def _example():
    return (np.array([1.0, 2.0]), np.array([[3.0, 4.0], [5.0, 6.0]]), np.array([7.0, 8.0, 9.0]))


def test_an_address_reads_and_writes_what_the_tuple_holds():
    """Indexing (a constant, the last by -1), unpacking and writing through an address give
    what the tuple itself gives (and, without the JIT, both are the tuple)."""
    by_address, by_value = _example(), _example()
    assert _by_address(by_address, 0.5) == _by_value(by_value, 0.5)
    assert _by_value(_example(), 0.5)[1] == 1.0 + 50.0 + 800.0 + 7000.0 + 3
    for a, b in zip(by_address, by_value, strict=True):
        np.testing.assert_array_equal(a, b)
    assert by_address[1][0, 1] == 0.5


@needs_jit
def test_an_address_leaves_the_arrays_counts_as_they_were():
    """A kernel with reference counting that loads arrays through an address counts each
    once more and releases it: the arrays' Python reference counts are unchanged after many
    calls (one count too many would keep them alive, one too few would free them)."""
    t = _example()
    before = [sys.getrefcount(a) for a in t]
    for _ in range(50):
        _by_address(t, 1.0)
    assert [sys.getrefcount(a) for a in t] == before


def _parameters(job) -> int:
    """Parameters of the LLVM function of ``job``'s first-class function (its C wrapper's).

    Compiled here without numba's disk cache: code loaded from the cache has no LLVM to
    inspect (numba returns an empty text), as on any second run of the suite in one checkout.
    """
    made = numba.cfunc(job.result(*job.types), cache=False, error_model="numpy",
                       _nrt=job.kernel.targetoptions.get("_nrt", True))(job.kernel.py_func)
    ir = made.inspect_llvm()
    name = job.kernel.py_func.__name__
    line = next(ln for ln in ir.splitlines() if ln.startswith("define") and name in ln
                and "cfunc." in ln)
    return line.count(",") + 1


@needs_jit
def test_a_tuple_by_its_address_is_one_argument():
    """The structural point of an address: a tuple of three arrays is passed as one pointer,
    where by value each array is its fields (seven or more each)."""
    t = _example()
    by_value = compile_of(_reads, (t,), numba.types.float64)
    by_address = compile_of(_reads, (TupleAddress(numba.typeof(t)),), numba.types.float64)
    assert _parameters(by_address) == 1
    assert _parameters(by_value) >= 3 * 7
