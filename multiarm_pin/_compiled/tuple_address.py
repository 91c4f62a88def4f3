"""A tuple passed to a kernel by its address: :func:`address` and :func:`tuple_at`.

numba passes a tuple argument by value, each array in it as its fields (data pointer,
shape, strides, ...), one argument each: a call that passes the contact loop's tuples (about a
hundred arrays) has about a thousand arguments, which the caller takes apart and the callee
puts back together, at every call site. That code grows with the product of the arrays and the
call sites, and it is compiled (lowered, optimised, made into machine code) at every level of
the call tree. ``address(t)`` stores the tuple ``t`` once in its caller's frame and gives a
:class:`TupleAddress`: one pointer, whatever the tuple holds. Indexing it with a constant
(``t[3]``) loads that element; :func:`tuple_at` loads the whole tuple (to unpack it).

An address is valid while the function that made it runs: pass it down the call tree, never
return or keep it. The tuple's arrays are not counted again (numba's reference counts): they
stay the caller's. Without the JIT (``NUMBA_DISABLE_JIT``) both functions return their
argument: the kernels then index and unpack the tuple itself.
"""

from __future__ import annotations

from numba.core import cgutils, types
from numba.core.imputils import impl_ret_borrowed, lower_builtin
from numba.core.typing.templates import AbstractTemplate, infer, signature
from numba.extending import intrinsic, models, register_model

from multiarm_pin._compiled.jit import jit_disabled


class TupleAddress(types.Type):
    """The numba type of the address of a tuple of numba type ``tuple_type``.

    What :func:`address` makes, and what a signature gives such an argument.
    """

    def __init__(self, tuple_type: types.BaseTuple):
        self.tuple_type = tuple_type
        super().__init__(name=f"TupleAddress({tuple_type})")


@register_model(TupleAddress)
class _AddressModel(models.PrimitiveModel):
    """A pointer to the tuple's value (its LLVM struct)."""

    def __init__(self, dmm, fe_type):
        pointee = dmm.lookup(fe_type.tuple_type).get_value_type()
        super().__init__(dmm, fe_type, pointee.as_pointer())


def _identity(t):
    return t


@intrinsic
def _address(typingctx, t):
    """In a kernel: the :class:`TupleAddress` of the tuple ``t`` (an address: itself)."""
    if isinstance(t, TupleAddress):
        return t(t), lambda context, builder, sig, args: args[0]
    if not isinstance(t, types.BaseTuple):
        return None

    def codegen(context, builder, sig, args):
        return cgutils.alloca_once_value(builder, args[0])  # in the caller's frame

    return TupleAddress(t)(t), codegen


@intrinsic
def _tuple_at(typingctx, t):
    """In a kernel: the tuple at the address ``t`` (a tuple: itself)."""
    if isinstance(t, types.BaseTuple):
        return t(t), lambda context, builder, sig, args: impl_ret_borrowed(
            context, builder, sig.return_type, args[0])
    if not isinstance(t, TupleAddress):
        return None

    def codegen(context, builder, sig, args):
        return impl_ret_borrowed(context, builder, sig.return_type, builder.load(args[0]))

    return t.tuple_type(t), codegen


address = _identity if jit_disabled() else _address
"""``address(t)``: the :class:`TupleAddress` of the tuple ``t`` in a kernel (an address:
itself); ``t`` without the JIT."""

tuple_at = _identity if jit_disabled() else _tuple_at
"""``tuple_at(t)``: the tuple at the address ``t`` in a kernel (a tuple: itself); ``t``
without the JIT."""


@infer
class _StaticGetItem(AbstractTemplate):
    """``t[i]`` for a constant ``i``: the type of the tuple's element ``i``."""

    key = "static_getitem"

    def generic(self, args, kws):
        at, index = args
        if isinstance(at, TupleAddress) and isinstance(index, int):
            return signature(at.tuple_type.types[index], *args)
        return None


@lower_builtin("static_getitem", TupleAddress, types.IntegerLiteral)
@lower_builtin("static_getitem", TupleAddress, types.Integer)
def _static_getitem(context, builder, sig, args):
    at, index = args
    index %= len(sig.args[0].tuple_type.types)  # t[-1]: the last
    element = builder.load(cgutils.gep_inbounds(builder, at, 0, index))
    return impl_ret_borrowed(context, builder, sig.return_type, element)


__all__ = ["TupleAddress", "address", "tuple_at"]
