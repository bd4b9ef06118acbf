"""Scenes whose H is quadratic in z = (q, p): H = z.S(t).z / 2 + s(t).

Such a scene only writes its coefficient function: `clear` row r of C, set S(t), dS/dt, s(t) and
ds/dt with `put_S`, `put_dS`, `put_s`, `put_ds` (z = (q, p), so S[i, j] with i, j < n couples q_i
and q_j, S[n + i, n + j] p_i and p_j), and end with `finish`, which appends J S (the matrix of the
linear vector field, read by the step builders). Energy, gradient, Hessian and dH/dt below serve
them all, and `kick` the splitting methods of a separable one (S_qp = 0). A row holds, in order:
S (row-major, 2n x 2n), dS/dt, s, ds/dt and J S (`ncoef`).
"""
import numpy as np
from numba import njit

from ..kernels.dispatch import INLINE, IR_INLINE, diagonal, ndof


@njit(**INLINE)
def put_S(P, C, r, i, j, value):
    """S[i, j] = value in row r (set S[j, i] too: S is symmetric)."""
    C[r, i * 2 * ndof(P) + j] = value


@njit(**INLINE)
def get_S(P, C, r, i, j):
    """S[i, j] of row r."""
    return C[r, i * 2 * ndof(P) + j]


@njit(**INLINE)
def get_dS(P, C, r, i, j):
    """dS/dt[i, j] of row r."""
    m = 2 * ndof(P)
    return C[r, m * m + i * m + j]


@njit(**INLINE)
def put_dS(P, C, r, i, j, value):
    """dS/dt[i, j] = value in row r."""
    m = 2 * ndof(P)
    C[r, m * m + i * m + j] = value


@njit(**INLINE)
def put_s(P, C, r, value):
    """The z-independent part s(t) of H in row r."""
    m = 2 * ndof(P)
    C[r, 2 * m * m] = value


@njit(**INLINE)
def put_ds(P, C, r, value):
    """ds/dt in row r."""
    m = 2 * ndof(P)
    C[r, 2 * m * m + 1] = value


@njit(**INLINE)
def grad(P, C, r, z, g):
    m = 2 * ndof(P)
    if diagonal(P):
        for i in range(m):
            g[i] = C[r, i * m + i] * z[i]
        return
    for i in range(m):
        acc = C[r, i * m] * z[0]
        for j in range(1, m):
            acc += C[r, i * m + j] * z[j]
        g[i] = acc


@njit(**IR_INLINE)
def _form(C, r, off, z, m, diag):
    """z.A z / 2 for the m x m matrix A at column off of row r (diag: A is diagonal). Where the
    scene's S and dS/dt are diagonal, skipping their zeros took 3-5 ns a step off modulated rk4
    with H + p_t (the zeros were multiplied: 0 x is not 0 where x is not finite)."""
    acc = -0.0
    if diag:
        for i in range(m):
            acc += C[r, off + i * m + i] * z[i] * z[i]
        return 0.5 * acc
    for i in range(m):
        row = C[r, off + i * m] * z[0]
        for j in range(1, m):
            row += C[r, off + i * m + j] * z[j]
        acc += z[i] * row
    return 0.5 * acc


@njit(**INLINE)
def energy(P, C, r, z):
    m = 2 * ndof(P)
    return _form(C, r, 0, z, m, diagonal(P)) + C[r, 2 * m * m]


@njit(**INLINE)
def dhdt(P, C, r, z):
    m = 2 * ndof(P)
    return _form(C, r, m * m, z, m, diagonal(P)) + C[r, 2 * m * m + 1]


@njit(**INLINE)
def hess(P, C, r, z, Hm):
    m = 2 * ndof(P)
    for i in range(m):
        for j in range(m):
            Hm[i, j] = C[r, i * m + j]


@njit(**INLINE)
def clear(P, C, r):
    """Zero row r's S, dS/dt, s and ds/dt (a loop of known length: `C[r, :] = 0.0` runs over the
    row's length at run time, see kernels.dispatch.IR_INLINE); `finish` writes all of J S."""
    m = 2 * ndof(P)
    for c in range(2 * m * m + 2):
        C[r, c] = 0.0


@njit(**INLINE)
def finish(P, C, r):
    """Append J S to row r: (J S)[i] = S[n + i], (J S)[n + i] = -S[i], J = [[0, I], [-I, 0]]."""
    n = ndof(P)
    m = 2 * n
    off = 2 * m * m + 2
    for i in range(n):
        for c in range(m):
            C[r, off + i * m + c] = C[r, (n + i) * m + c]
            C[r, off + (n + i) * m + c] = -C[r, i * m + c]


@njit(**INLINE)
def kick(P, C, r, tau, z):
    """The exact flow of V(q, t) = q.S_qq q/2 + s for a time tau at the time of row r, for a
    separable H (S_qp = 0; q and t stay): p -= tau S_qq q. Returns the p_t increment -tau dV/dt."""
    n = ndof(P)
    m = 2 * n
    dv = -0.0
    for i in range(n):
        force = C[r, i * m] * z[0]
        rate = C[r, m * m + i * m] * z[0]
        for c in range(1, n):
            force += C[r, i * m + c] * z[c]
            rate += C[r, m * m + i * m + c] * z[c]
        z[n + i] -= tau * force
        dv += z[i] * rate
    return -tau * (0.5 * dv + C[r, 2 * m * m + 1])


@njit(**INLINE)
def exprel(x):
    """(e^x - 1) / x, 1 at x = 0: the integral of e^(x s) over s in [0, 1]."""
    return 1.0 if x == 0.0 else np.expm1(x) / x


def ncoef(ndof):
    """Length of a quadratic scene's coefficient vector: S, dS/dt, s, ds/dt, J S."""
    return 3 * (2 * ndof) ** 2 + 2
