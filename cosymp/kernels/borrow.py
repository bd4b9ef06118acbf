"""Borrowed arrays: the same data and shape, without a reference to its owner.

Numba reference-counts every array it binds, and it cannot prune those atomic counts inside a
loop whose body has branches and early exits (our Newton iterations): measured, they cost more
than the step itself. A compiled loop therefore borrows its arrays once at entry, while the
caller keeps the owners alive for the whole call; every view taken from a borrowed array is
borrowed too, so no count is touched per step.
"""
from numba.core import cgutils, types
from numba.extending import intrinsic


def _strip(context, builder, ty, val):
    if isinstance(ty, types.Array):
        ary = context.make_array(ty)(context, builder, value=val)
        ary.meminfo = cgutils.get_null_value(ary.meminfo.type)
        ary.parent = cgutils.get_null_value(ary.parent.type)
        return ary._getvalue()
    if isinstance(ty, types.BaseTuple):
        for i, t in enumerate(ty):
            val = builder.insert_value(val, _strip(context, builder, t, builder.extract_value(val, i)), i)
    return val


@intrinsic
def borrow(typingctx, x):
    """x with every array in it (also inside tuples and named tuples) borrowed, not owned."""
    def codegen(context, builder, sig, args):
        return _strip(context, builder, sig.args[0], args[0])

    return x(x), codegen
