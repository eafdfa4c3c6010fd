"""A row's pairs in lanes: scratch blocks on the stack of a compiled pair loop.

A pair loop sums each particle's row term by term in row order, which keeps the sums the
same on any rank count. The work that forms a pair's term needs no order. So a row's pairs
are gathered, up to LANES at a time, into a block with a column per pair (a lane) and a row
per quantity; the arithmetic then runs down the lanes, where the compiler uses SIMD
instructions (square roots and divisions too), and the sums follow, lane by lane in row
order. Every term is the same operation on the same values as in a plain pair loop, so the
results are the same bits.

The gathering stays scalar: a SIMD gather costs more than the loads it replaces. Lanes past
a row's pairs are computed too (they hold a former row's values) and never summed.
"""

from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic
from numba.np.arrayobj import make_array, populate_array

LANES = 32  # pairs per block; a multiple of the widest SIMD register's doubles (8)


@intrinsic
def lane_block(typingctx, rows):
    """A (rows, LANES) float64 array on the calling function's stack frame, zeroed; `rows`
    a compile-time constant. Its memory is the function's own, so the compiler knows that
    no other array overlaps it."""
    if not isinstance(rows, types.IntegerLiteral):
        return None
    count = rows.literal_value
    block = types.Array(types.float64, 2, "C")

    def codegen(context, builder, signature, args):
        intp = context.get_value_type(types.intp)
        data = cgutils.alloca_once(builder, context.get_value_type(types.float64), size=count * LANES)
        cgutils.memset(builder, data, intp(8 * count * LANES), 0)
        array = make_array(block)(context, builder)
        populate_array(array, data=data, shape=[intp(count), intp(LANES)], strides=[intp(8 * LANES), intp(8)],
                       itemsize=intp(8), meminfo=None)
        return array._getvalue()

    return block(rows), codegen


@intrinsic
def quotient(typingctx, a, b):
    """a / b as IEEE division: no test for a zero b, whose exception would keep the loop
    from SIMD instructions. For divisors known to be non-zero, or lanes not summed."""
    if not (isinstance(a, types.Float) and isinstance(b, types.Float)):
        return None

    def codegen(context, builder, signature, args):
        return builder.fdiv(args[0], args[1])

    return types.float64(types.float64, types.float64), codegen


@njit(cache=True, inline="always")
def lanes_used(pairs):
    """The lanes a pass over `pairs` gathered pairs runs on: rounded up to a multiple of 8,
    so that the SIMD loop covers them without a scalar remainder."""
    return min((pairs + 7) // 8 * 8, LANES)
