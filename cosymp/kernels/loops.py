"""The generic compiled loops: every scene and every method family runs through these."""
import numpy as np
from numba import njit

from .borrow import borrow
from .dispatch import (INLINE, JIT, coef, dhdt, energy, grad, is_linear, lmatrix, lwork, ncoef, ndof,
                       step, work)
from .families import OK, OVERFLOW
from .stack import coef_table, matrices, vectors

COMPLEX_STEP = 1e-50


@njit(**INLINE)
def _coefs(P, offsets, tk, tk1, h, C, reuse):
    """Time coefficients at the step's offsets; the end of the last step is the start of this."""
    u = len(offsets)
    for j in range(u):
        if j == 0 and reuse:
            for c in range(ncoef(P)):
                C[0, c] = C[u - 1, c]
        else:
            coef(P, tk1 if offsets[j] == 1.0 else tk + offsets[j] * h, C, j)


@njit(**JIT)
def propagate(D, P, t0, h, Z, PT, nsteps, stride, Trec, Zrec, PTrec, dZrec):
    """Advance the N members of (Z, PT) by nsteps steps of h from t0 together.

    Records every stride-th state (index j is step j*stride, index 0 the start) and, when dZrec
    is non-empty, the increment z_k - z_(k-1) of the last step before each record. Returns
    (status, k): k steps were completed; on failure the step k -> k+1 failed and the records
    hold every recorded state before it. Linear scenes step by one matrix per step, shared by
    all members (kernels.linear); others step each member (kernels.families).
    """
    D, P, Z, PT, Trec, Zrec, PTrec, dZrec = borrow((D, P, Z, PT, Trec, Zrec, PTrec, dZrec))
    C = coef_table(D, P)
    W = work(D, P, 0.0)
    LW = lwork(D, P)
    MQ = matrices(P, 2, 0.0)
    M, Q = MQ[0], MQ[1]
    V = vectors(P, 2, 0.0)
    z, old = V[0], V[1]
    N = Z.shape[0]
    m = 2 * ndof(P)
    offsets = D.offsets
    u = len(offsets)
    can_reuse = u > 1 and offsets[0] == 0.0 and offsets[u - 1] == 1.0
    increments = dZrec.shape[0] > 0
    Trec[0] = t0
    for i in range(N):
        PTrec[0, i] = PT[i]
        for r in range(m):
            Zrec[0, i, r] = Z[i, r]
            if increments:
                dZrec[0, i, r] = np.nan
    rec = 1
    s = 0.0
    for k in range(nsteps):
        tk = t0 + k * h
        tk1 = t0 + (k + 1) * h
        _coefs(P, offsets, tk, tk1, h, C, can_reuse and k > 0)
        recording = (k + 1) % stride == 0
        if is_linear(P):
            s = lmatrix(D, P, C, tk, h, M, Q, LW)
        for i in range(N):
            for r in range(m):
                old[r] = Z[i, r]
            if is_linear(P):
                status = OK
                quad = 0.0
                for r in range(m):
                    acc = 0.0
                    qr = 0.0
                    for c in range(m):
                        acc += M[r, c] * old[c]
                        qr += Q[r, c] * old[c]
                    z[r] = acc
                    quad += old[r] * qr
                pt = PT[i] - (0.5 * quad + s)
            else:
                for r in range(m):
                    z[r] = old[r]
                status, pt = step(D, P, C, tk, h, z, PT[i], W)
            if status == OK and not np.isfinite(pt):
                status = OVERFLOW
            for r in range(m):
                if not np.isfinite(z[r]):
                    status = OVERFLOW
            if status != OK:
                return status, k
            PT[i] = pt
            for r in range(m):
                Z[i, r] = z[r]
            if recording:
                PTrec[rec, i] = pt
                for r in range(m):
                    Zrec[rec, i, r] = z[r]
                    if increments:
                        dZrec[rec, i, r] = z[r] - old[r]
        if recording:
            Trec[rec] = tk1
            rec += 1
    return OK, nsteps


@njit(**JIT)
def tangent(D, P, h, T, Z, PT, M):
    """One-step tangent maps M[k] = d z_(k+1) / d z_k on the time slice t = T[k].

    Linear scenes: the step matrix itself. Otherwise by complex step on the member step: exact
    to round-off (no subtraction).
    """
    D, P, T, Z, PT, M = borrow((D, P, T, Z, PT, M))
    C = coef_table(D, P)
    W = work(D, P, 0j)
    LW = lwork(D, P)
    Q = matrices(P, 1, 0.0)[0]
    zc = vectors(P, 1, 0j)[0]
    m = 2 * ndof(P)
    for k in range(Z.shape[0]):
        _coefs(P, D.offsets, T[k], T[k] + h, h, C, False)
        if is_linear(P):
            lmatrix(D, P, C, T[k], h, M[k], Q, LW)
            continue
        for j in range(m):
            for r in range(m):
                zc[r] = Z[k, r]
            zc[j] += 1j * COMPLEX_STEP
            status, _ = step(D, P, C, T[k], h, zc, PT[k] + 0j, W)
            if status != OK:
                return status, k
            for r in range(m):
                M[k, r, j] = zc[r].imag / COMPLEX_STEP
    return OK, Z.shape[0]


@njit(**JIT)
def energies(P, T, Z, out):
    """H at recorded states: T (K,), Z (K, N, 2n) -> out (K, N)."""
    C = np.empty((1, ncoef(P)))
    for k in range(T.shape[0]):
        coef(P, T[k], C, 0)
        for i in range(Z.shape[1]):
            out[k, i] = energy(P, C, 0, Z[k, i])


@njit(**JIT)
def vector_field(P, t, z, out):
    """The extended vector field (dq/dt, dp/dt, dp_t/dt) at (z, t), for reference solvers."""
    n = ndof(P)
    C = np.empty((1, ncoef(P)))
    coef(P, t, C, 0)
    g = np.empty(2 * n)
    grad(P, C, 0, z, g)
    for i in range(n):
        out[i] = g[n + i]
        out[n + i] = -g[i]
    out[2 * n] = -dhdt(P, C, 0, z)
