"""The loop's tuples held once for many calls from Python: :func:`hold`.

numba unboxes every array of a tuple argument at each call from Python (a MemInfo made and
released per array): for the loop's four tuples (about 80 arrays) a few microseconds a call,
which a run pays once per stretch of samples but a caller of one evaluation at a time
(:meth:`~multiarm_pin.sim.contact_loop.ContactLoop.evaluate`) pays at every call.
:func:`hold` puts the tuples into one numba structure (a ``StructRef``, reference-counted,
holding references to the arrays) once; a kernel that takes it unboxes one pointer and reads
its fields ``sy``, ``ctl``, ``wk``, ``out``. The arrays stay the same objects: what the caller
writes into them between calls, the kernel reads.

Without the JIT (``NUMBA_DISABLE_JIT``) :func:`hold` returns a :class:`HeldTuples` named tuple
with the same fields.
"""

from __future__ import annotations

from typing import NamedTuple

from numba import types
from numba.experimental import structref

from multiarm_pin._compiled.jit import jit_disabled, kernel


class HeldTuples(NamedTuple):
    """The loop's tuples by name (what :func:`hold` gives without the JIT)."""

    sy: tuple
    ctl: tuple
    wk: tuple
    out: tuple


@structref.register
class HeldType(types.StructRef):
    """The numba type of a :class:`Held`: its fields' types, never literal."""

    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(t)) for name, t in fields)


class Held(structref.StructRefProxy):
    """The loop's tuples in one numba structure (made by :func:`hold`)."""


structref.define_proxy(Held, HeldType, list(HeldTuples._fields))


@kernel
def _make(sy, ctl, wk, out):  # pragma: no cover - compiled
    return Held(sy, ctl, wk, out)


def hold(sy: tuple, ctl: tuple, wk: tuple, out: tuple) -> Held | HeldTuples:
    """The tuples ``sy``, ``ctl``, ``wk``, ``out`` held as one argument (see the module)."""
    if jit_disabled():
        return HeldTuples(sy, ctl, wk, out)
    return _make(sy, ctl, wk, out)


__all__ = ["Held", "HeldTuples", "HeldType", "hold"]
