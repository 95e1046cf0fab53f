"""Decorators and intrinsics shared by the kernels."""

from __future__ import annotations

from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

# helpers of the per-step loop: inlined into their callers at the numba IR level
inlined = njit(cache=True, inline="always")

# A value that decays toward exactly 0 (a coordinate of nodes learning the plane z = 0, a colour
# channel of 0) shrinks geometrically with every move and ends subnormal (below 2.2e-308),
# where each arithmetic operation on it costs ~100 cycles (48 of 100 nodes on Data2's floor:
# a third of the learning speed). Below this magnitude it is stored as 0: far below float64's
# resolution beside any other coordinate, so no distance, winner or edge changes.
FLUSH_TINY = 1e-200


@inlined
def flush_tiny(value):
    """``value``, or 0.0 when its magnitude is below `FLUSH_TINY` (never subnormal)."""
    return value if abs(value) >= FLUSH_TINY else 0.0


@intrinsic
def prefetch_row(typingctx, array, row):
    """Ask the CPU to bring row ``row`` of a C-contiguous 2-D ``array`` into its caches
    (``llvm.prefetch`` of the row's first and last element; a hint: nothing is read, nothing
    can fault, the results never change). A loop that reads rows in a random order hides the
    memory's latency by naming a row a few iterations before it reads it."""

    def codegen(context, builder, signature, args):
        array_type, row_type = signature.args
        view = context.make_array(array_type)(context, builder, args[0])
        index = context.cast(builder, args[1], row_type, types.intp)
        last = builder.sub(cgutils.unpack_tuple(builder, view.shape, 2)[1],
                           context.get_constant(types.intp, 1))
        byte_pointer = ir.IntType(8).as_pointer()
        i32 = ir.IntType(32)
        hint = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(ir.VoidType(), [byte_pointer, i32, i32, i32]),
            "llvm.prefetch.p0")
        for column in (context.get_constant(types.intp, 0), last):
            pointer = cgutils.get_item_pointer(context, builder, array_type, view,
                                               [index, column])
            # read (0), keep in every cache level (3), data (1)
            builder.call(hint, [builder.bitcast(pointer, byte_pointer), i32(0), i32(3), i32(1)])
        return context.get_dummy_value()

    return types.void(array, row), codegen
