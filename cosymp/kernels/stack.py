"""Scratch arrays on the machine stack, sized at compile time, as a C loop would declare them.

The compiled loops keep their small vectors and matrices here rather than on the heap: the
compiler then sees every element at a constant offset of a private buffer and keeps it in
registers (measured: the theta step's matrices in 6.8 ns instead of 22.8 ns on the heap).
A stack array lives as long as the compiled function that declares it; every function that
declares some is inlined in numba's IR (kernels.dispatch.IR_INLINE), so the declaring function is
always the loop itself (functions that only receive such arrays may be compiled on their own).
"""
import numpy as np
from llvmlite import ir
from numba.core import cgutils, types
from numba.core.errors import TypingError
from numba.extending import intrinsic, overload
from numba.np.arrayobj import make_array, populate_array

from .dispatch import _IR_INLINE, registered


@intrinsic(prefer_literal=True)
def stack_array(typingctx, shape, like):
    """An uninitialised C-contiguous array of the literal `shape`, dtype of `like`."""
    if not isinstance(shape, types.BaseTuple) or not all(
            isinstance(t, types.IntegerLiteral) for t in shape.types):
        raise TypingError("stack_array needs a tuple of literal sizes")
    dims = [t.literal_value for t in shape.types]
    dtype = like.dtype if isinstance(like, types.Array) else like
    aty = types.Array(dtype, len(dims), "C")

    def codegen(context, builder, sig, args):
        item_type = context.get_value_type(dtype)
        buf = cgutils.alloca_once(builder, ir.ArrayType(item_type, max(1, int(np.prod(dims)))))
        intp = context.get_value_type(types.intp)
        item = context.get_abi_sizeof(item_type)
        strides = [item * int(np.prod(dims[i + 1:])) for i in range(len(dims))]
        ary = make_array(aty)(context, builder)
        populate_array(ary, data=builder.bitcast(buf, item_type.as_pointer()),
                       shape=[ir.Constant(intp, d) for d in dims],
                       strides=[ir.Constant(intp, s) for s in strides],
                       itemsize=ir.Constant(intp, item), meminfo=None)
        return ary._getvalue()

    return aty(shape, like), codegen


def _scene(P):
    return registered(P.instance_class)


@intrinsic
def _opaque(typingctx, n):
    """n, which the optimizer cannot see through (an empty inline assembly returns it)."""
    def codegen(context, builder, sig, args):
        return builder.asm(ir.FunctionType(ir.IntType(64), [ir.IntType(64)]), "", "=r,0", [args[0]],
                           side_effect=False)
    return types.int64(types.int64), codegen


MAX_STAGES = 16
MAX_OFFSETS = 16
UNROLLED_MAX = 8  # stage_unknowns


def _count(D, field, bound):
    """The length of D's field where its type fixes it (a tuple), else the bound: array data let
    every tableau of a family share one compiled loop."""
    ty = D.types[D.fields.index(field)]
    return ty.count if isinstance(ty, types.BaseTuple) else bound


def _stages(D):
    """The number of stages of the tableau D, or its bound MAX_STAGES."""
    return _count(D, "b", MAX_STAGES)


def vectors(P, k, like):
    """k stack vectors of the scene's state size 2n."""


def matrices(P, k, like):
    """k stack matrices 2n x 2n."""


def stage_vectors(D, P, like):
    """One stack vector of size 2n per stage of the tableau D."""


def stage_flat(D, P, like):
    """One stack vector of size stages * 2n."""


def stage_matrices(D, P, like):
    """One 2n x 2n stack matrix per stage of the tableau D."""


def stage_square(D, P, like):
    """A stack matrix (stages * 2n) x (stages * 2n)."""


def stage_unknowns(D, P):
    """The unknowns of the Gauss stages' system, stages x 2n: the size its factorization and
    solves loop over. A constant up to UNROLLED_MAX, by which the compiler unrolls those loops;
    beyond it hidden from the optimizer, so that they stay loops. Unrolled, the charged particle's
    gauss6 system (12 x 12) made its step matrix 1.70x its C mirror (1348 against 792 ns a step)
    and its member step 1419 ns; as loops 1.07x and 967 ns. gauss4's 8 x 8 runs faster unrolled
    (its step matrix 303 against 413 ns as loops). D's stages must be a tuple: the bound
    MAX_STAGES of an array tableau would size the system wrong."""


def stage_pivots(D, P):
    """A stack vector of stages * 2n integers: the row swaps of an LU factorization (linalg.factor)."""


def coef_table(D, P):
    """The stack table of time coefficients: one row per time offset of D (at most MAX_OFFSETS),
    and one more column: the row's time while a pending row is still to be computed, NaN once it
    is (kernels.loops._coefs and kernels.families.row)."""


@overload(vectors, jit_options=_IR_INLINE, inline="always", prefer_literal=True)
def _vectors(P, k, like):
    m = 2 * _scene(P).ndof
    kk = k.literal_value
    return lambda P, k, like: stack_array((kk, m), like)


@overload(matrices, jit_options=_IR_INLINE, inline="always", prefer_literal=True)
def _matrices(P, k, like):
    m = 2 * _scene(P).ndof
    kk = k.literal_value
    return lambda P, k, like: stack_array((kk, m, m), like)


@overload(stage_vectors, jit_options=_IR_INLINE, inline="always")
def _stage_vectors(D, P, like):
    m = 2 * _scene(P).ndof
    s = _stages(D)
    return lambda D, P, like: stack_array((s, m), like)


@overload(stage_flat, jit_options=_IR_INLINE, inline="always")
def _stage_flat(D, P, like):
    sm = 2 * _scene(P).ndof * _stages(D)
    return lambda D, P, like: stack_array((sm,), like)


@overload(stage_matrices, jit_options=_IR_INLINE, inline="always")
def _stage_matrices(D, P, like):
    m = 2 * _scene(P).ndof
    s = _stages(D)
    return lambda D, P, like: stack_array((s, m, m), like)


@overload(stage_square, jit_options=_IR_INLINE, inline="always")
def _stage_square(D, P, like):
    sm = 2 * _scene(P).ndof * _stages(D)
    return lambda D, P, like: stack_array((sm, sm), like)


@overload(stage_unknowns, jit_options=_IR_INLINE, inline="always")
def _stage_unknowns(D, P):
    if not isinstance(D.types[D.fields.index("b")], types.BaseTuple):
        raise TypingError("stage_unknowns: the tableau's weights b must be a tuple")
    sm = 2 * _scene(P).ndof * _stages(D)
    if sm > UNROLLED_MAX:
        return lambda D, P: _opaque(np.int64(sm))
    return lambda D, P: sm


@overload(stage_pivots, jit_options=_IR_INLINE, inline="always")
def _stage_pivots(D, P):
    sm = 2 * _scene(P).ndof * _stages(D)
    return lambda D, P: stack_array((sm,), np.int64(0))


@overload(coef_table, jit_options=_IR_INLINE, inline="always")
def _coef_table(D, P):
    cols = _scene(P).ncoef + 1
    rows = _count(D, "offsets", MAX_OFFSETS)
    return lambda D, P: stack_array((rows, cols), 0.0)
