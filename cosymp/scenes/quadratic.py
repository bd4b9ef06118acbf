"""Scenes whose H is quadratic in z = (q, p): H = z.S(t).z / 2 + s(t).

Such a scene only writes its coefficient function, filling row r of C with S (row-major, 2n x 2n),
dS/dt, s and ds/dt and ending with `finish`, which appends J S (the matrix of the linear vector
field, read by the step builders); energy, gradient, Hessian and dH/dt below serve them all.
"""
from numba import njit

from ..kernels.dispatch import INLINE, ndof


@njit(**INLINE)
def grad(P, C, r, z, g):
    m = 2 * ndof(P)
    for i in range(m):
        acc = C[r, i * m] * z[0]
        for j in range(1, m):
            acc += C[r, i * m + j] * z[j]
        g[i] = acc


@njit(**INLINE)
def _form(C, r, off, z, m):
    acc = 0.0 * z[0]
    for i in range(m):
        row = C[r, off + i * m] * z[0]
        for j in range(1, m):
            row += C[r, off + i * m + j] * z[j]
        acc += z[i] * row
    return 0.5 * acc


@njit(**INLINE)
def energy(P, C, r, z):
    m = 2 * ndof(P)
    return _form(C, r, 0, z, m) + C[r, 2 * m * m]


@njit(**INLINE)
def dhdt(P, C, r, z):
    m = 2 * ndof(P)
    return _form(C, r, m * m, z, m) + C[r, 2 * m * m + 1]


@njit(**INLINE)
def hess(P, C, r, z, Hm):
    m = 2 * ndof(P)
    for i in range(m):
        for j in range(m):
            Hm[i, j] = C[r, i * m + j]


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


def ncoef(ndof):
    """Length of a quadratic scene's coefficient vector: S, dS/dt, s, ds/dt, J S."""
    return 3 * (2 * ndof) ** 2 + 2
