"""Small dense linear algebra for implicit steps (real or complex, any size)."""
import numpy as np
from numba import njit, types
from numba.extending import overload

from .dispatch import _IR_INLINE, IR_INLINE

TINY = float(np.finfo(float).tiny)  # the smallest normal double: 1 / det is finite above it
SINGULAR_2X2 = 4.0 * float(np.finfo(float).eps)  # det within this of |a d| + |b c| is round-off of 0


@njit(**IR_INLINE)
def _pivot(A, c, n):
    """The row, from c on, of column c's largest entry (the first of equals); -1 if all are zero."""
    p = c
    big = abs(A[c, c])
    for i in range(c + 1, n):
        v = abs(A[i, c])
        if v > big:
            big = v
            p = i
    return p if big != 0.0 else -1


@njit(**IR_INLINE)
def solve(A, B, n, k):
    """Overwrite the leading n x k block of B with A^-1 B; A is destroyed (as scratch).

    B is 2-D (k right-hand sides) or 1-D (k = 1). By elimination with partial pivoting; returns False
    if a pivot is exactly zero.

    A 2 x 2 system (the Newton steps and step matrices of the theta family and of midpoint
    compositions on a one-degree-of-freedom scene; Gauss's stage systems are larger) is solved by
    Cramer's rule, which is forward stable for n = 2 (Higham, Accuracy and Stability of Numerical
    Algorithms, 2nd ed., section 1.10.1) and takes no pivot's comparison (damped midpoint's step
    21.5 -> 20 ns). Elimination takes it where det is not a normal number clear of its own round-off
    (SINGULAR_2X2): an exactly singular A, whose det an FMA can leave at 1e-17 instead of 0, a det
    that overflows, or one whose reciprocal would. See _cramer.
    """
    if n == 2:
        ad, bc = A[0, 0] * A[1, 1], A[0, 1] * A[1, 0]
        det = ad - bc
        size = _size(det)
        if size >= TINY and size > SINGULAR_2X2 * (_size(ad) + _size(bc)):  # False for inf or NaN too
            _cramer(A, B, det, k)
            return True
    for c in range(n):
        p = _pivot(A, c, n)
        if p < 0:
            return False
        if p != c:
            for j in range(c, n):
                A[c, j], A[p, j] = A[p, j], A[c, j]
            _swap_rows(B, c, p, k)
        inv = 1.0 / A[c, c]
        for i in range(c + 1, n):
            f = A[i, c] * inv
            if f != 0.0:
                for j in range(c + 1, n):
                    A[i, j] -= f * A[c, j]
                _axpy_rows(B, i, c, -f, k)
    for c in range(n - 1, -1, -1):
        for j in range(c + 1, n):
            _axpy_rows(B, c, j, -A[c, j], k)
        _scale_row(B, c, 1.0 / A[c, c], k)
    return True


@njit(**IR_INLINE)
def factor(A, piv, n):
    """LU factors of A's leading n x n block in place, as `solve` eliminates (partial pivoting: at
    column c, row c was swapped with row piv[c]; the multipliers below the diagonal, the pivots'
    reciprocals on it), for solves against right-hand sides known one after another
    (`substitute`). Returns False if a pivot is exactly zero."""
    for c in range(n):
        p = _pivot(A, c, n)
        if p < 0:
            return False
        piv[c] = p
        if p != c:
            for j in range(n):
                A[c, j], A[p, j] = A[p, j], A[c, j]
        inv = 1.0 / A[c, c]
        for i in range(c + 1, n):
            f = A[i, c] * inv
            A[i, c] = f
            if f != 0.0:
                for j in range(c + 1, n):
                    A[i, j] -= f * A[c, j]
        A[c, c] = inv
    return True


@njit(**IR_INLINE)
def substitute(A, piv, B, n, k):
    """Overwrite the leading n x k block of B with A^-1 B, A and piv from `factor`: every row swap
    first (the multipliers moved with their rows), then the same operations on each row of B as
    `solve`'s elimination, so the same result."""
    for c in range(n):
        if piv[c] != c:
            _swap_rows(B, c, piv[c], k)
    for c in range(n):
        for i in range(c + 1, n):
            f = A[i, c]
            if f != 0.0:
                _axpy_rows(B, i, c, -f, k)
    for c in range(n - 1, -1, -1):
        for j in range(c + 1, n):
            _axpy_rows(B, c, j, -A[c, j], k)
        _scale_row(B, c, A[c, c], k)


def _size(x):
    """|x| of a real x; |Re x| + |Im x| of a complex one (no square root)."""


def _cramer(A, B, det, k):
    """B <- A^-1 B for a 2 x 2 A of determinant det. A vector (a state's update) is divided by det:
    the same matrix step after step, a reciprocal's rounding is the same scale error every step
    (the rotations of tests/test_hard_cases.py drifted from |z| by up to 1.3e-12 in 1000 steps
    multiplied by 1 / det, 6.5e-13 by elimination, 5.0e-13 divided). Columns (a step or tangent
    map) are multiplied by 1 / det, one division for all (a rotation's ensembles 6.2e-13, 3.6e-13
    by elimination): a division there cost the fused run of damped midpoint 3 ns a step."""


def _swap_rows(B, a, b, k):
    """Swap rows a and b of B (a vector, or k columns)."""


def _axpy_rows(B, i, c, f, k):
    """Row i of B += f * row c."""


def _scale_row(B, c, f, k):
    """Row c of B *= f."""


@overload(_size, jit_options=_IR_INLINE, inline="always")
def _size_impl(x):
    if isinstance(x, types.Complex):
        return lambda x: abs(x.real) + abs(x.imag)
    return lambda x: abs(x)


@overload(_cramer, jit_options=_IR_INLINE, inline="always")
def _cramer_impl(A, B, det, k):
    if B.ndim == 1:
        def cramer(A, B, det, k):
            b0, b1 = B[0], B[1]
            B[0] = (A[1, 1] * b0 - A[0, 1] * b1) / det
            B[1] = (A[0, 0] * b1 - A[1, 0] * b0) / det
    else:
        def cramer(A, B, det, k):
            inv = 1.0 / det
            for j in range(k):
                b0, b1 = B[0, j], B[1, j]
                B[0, j] = (A[1, 1] * b0 - A[0, 1] * b1) * inv
                B[1, j] = (A[0, 0] * b1 - A[1, 0] * b0) * inv
    return cramer


@overload(_swap_rows, jit_options=_IR_INLINE, inline="always")
def _swap_rows_impl(B, a, b, k):
    if B.ndim == 1:
        def swap(B, a, b, k):
            B[a], B[b] = B[b], B[a]
    else:
        def swap(B, a, b, k):
            for j in range(k):
                B[a, j], B[b, j] = B[b, j], B[a, j]
    return swap


@overload(_axpy_rows, jit_options=_IR_INLINE, inline="always")
def _axpy_rows_impl(B, i, c, f, k):
    if B.ndim == 1:
        def axpy(B, i, c, f, k):
            B[i] += f * B[c]
    else:
        def axpy(B, i, c, f, k):
            for j in range(k):
                B[i, j] += f * B[c, j]
    return axpy


@overload(_scale_row, jit_options=_IR_INLINE, inline="always")
def _scale_row_impl(B, c, f, k):
    if B.ndim == 1:
        def scale(B, c, f, k):
            B[c] *= f
    else:
        def scale(B, c, f, k):
            for j in range(k):
                B[c, j] *= f
    return scale
