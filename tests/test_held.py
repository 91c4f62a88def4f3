"""The loop's tuples held for many calls (``_compiled.held``): the same arrays, owned."""

from __future__ import annotations

import gc
import sys

import numpy as np
import pytest
from numba.core import config

from multiarm_pin._compiled.held import HeldTuples, HeldType, hold
from multiarm_pin._compiled.jit import kernel
from multiarm_pin._compiled.tuple_address import address, tuple_at

needs_jit = pytest.mark.skipif(config.DISABLE_JIT, reason="a StructRef needs the JIT")


@kernel
def _read_and_write(held, value):  # pragma: no cover - compiled
    sy = address(held.sy)
    a, b = tuple_at(sy)
    held.out[0][1] = value  # into the caller's array
    return a[0] + 10.0 * b[1, 0] + 100.0 * held.ctl[0][0] + 1000.0 * held.wk[0].shape[0]


def _tuples():
    return ((np.array([1.0, 2.0]), np.array([[3.0, 4.0], [5.0, 6.0]])), (np.array([7.0]),),
            (np.zeros(3),), (np.zeros(2),))


def test_a_kernel_reads_and_writes_the_arrays_the_tuples_hold():
    """Fields by name, through an address too; writes on either side are seen by the other
    (the same arrays, not copies); without the JIT a named tuple of the same fields."""
    sy, ctl, wk, out = _tuples()
    held = hold(sy, ctl, wk, out)
    assert _read_and_write(held, 0.5) == 1.0 + 50.0 + 700.0 + 3000.0
    assert out[0][1] == 0.5
    sy[1][1, 0] = 6.0  # written by the caller after hold: the kernel reads it
    assert _read_and_write(held, 0.25) == 1.0 + 60.0 + 700.0 + 3000.0
    assert out[0][1] == 0.25
    if config.DISABLE_JIT:
        assert held == HeldTuples(sy, ctl, wk, out)


@needs_jit
def test_the_structure_owns_a_reference_to_each_array_until_it_goes():
    """A held array outlives its other references (counted once more while held, released
    with the structure); the structure's numba type is the tuples' types, never literal."""
    sy, ctl, wk, out = _tuples()
    first = sy[0]
    before = sys.getrefcount(first)
    held = hold(sy, ctl, wk, out)
    after = sys.getrefcount(first)  # (not inside the assert: pytest's rewrite holds one more)
    assert after == before + 1
    del first
    assert isinstance(held._numba_type_, HeldType)
    expected = _read_and_write(held, 1.0)
    del sy, ctl, wk, out
    gc.collect()
    np.testing.assert_array_equal(_read_and_write(held, 1.0), expected)
    a = np.array([1.0, 2.0])
    before = sys.getrefcount(a)
    held = hold((a, np.zeros((2, 2))), (np.zeros(1),), (np.zeros(1),), (np.zeros(2),))
    del held
    gc.collect()
    after = sys.getrefcount(a)
    assert after == before
