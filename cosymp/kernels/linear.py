"""The step of a linear scene as a matrix: z_(k+1) = M z_k, p_t,(k+1) = p_t,k - (z_k.Q z_k / 2 + s).

For a quadratic H = z.S(t).z/2 + s(t) (every scene of the paper) each method's step is linear in
z, its implicit equations are one closed-form linear solve, and (M, Q, s) depends on the step's
time only: it is built once per step from the coefficient rows C[j] (S, dS/dt, s, ds/dt, see
scenes.quadratic) and applied to every member of an ensemble. M is also the exact tangent map.
A Q with no rows asks for M alone: Q (and where it costs a step, s) is then not formed. A fused
run of one member uses M only; formed there for the nearby members of a long run (which use Q),
it cost damped midpoint's one-member run with every figure 48-50 ns a step instead of 41-43
(in-process A/B).
"""
from numba import njit

from .dispatch import INLINE, IR_INLINE, flow, ndof, step
from .families import boris_core, stage_row
from .linalg import solve
from .stack import matrices, stage_matrices, stage_square, stage_unknowns, vectors


@njit(**INLINE)
def js(C, j, n, i, c):
    """(J S_j)[i, c], stored by scenes.quadratic.finish."""
    m = 2 * n
    return C[j, 2 * m * m + 2 + i * m + c]


@njit(**INLINE)
def sdot(C, j, m, i, c):
    """(dS/dt)_j[i, c]."""
    return C[j, m * m + i * m + c]


@njit(**INLINE)
def sdot0(C, j, m):
    """ds/dt at row j."""
    return C[j, 2 * m * m + 1]


@njit(**IR_INLINE)
def identity(A, m):
    for i in range(m):
        for c in range(m):
            A[i, c] = 1.0 if i == c else 0.0


@njit(**IR_INLINE)
def product(A, B, out, m, transpose_a=False, scale=1.0, add=False):
    """out (+)= scale * A B, or scale * A^T B, for m x m matrices."""
    for i in range(m):
        for c in range(m):
            acc = 0.0
            for r in range(m):
                acc += (A[r, i] if transpose_a else A[i, r]) * B[r, c]
            out[i, c] = out[i, c] + scale * acc if add else scale * acc


@njit(**IR_INLINE)
def add_sandwich(Q, G, C, j, m, scale, T):
    """Q += scale * G^T (dS/dt)_j G, with T an m x m scratch."""
    for i in range(m):
        for c in range(m):
            acc = 0.0
            for r in range(m):
                acc += sdot(C, j, m, i, r) * G[r, c]
            T[i, c] = acc
    product(G, T, Q, m, transpose_a=True, scale=scale, add=True)


@njit(**INLINE)
def theta_matrix(P, C, j, h, wq0, wq1, wp0, wp1, M, Q, A, N):
    """(I - h J S W1) M = I + h J S W0, N = W0 + W1 M, Q = h N^T S' N, s = h s' (Q where it has rows)."""
    n = ndof(P)
    m = 2 * n
    for i in range(m):
        for c in range(m):
            a = h * js(C, j, n, i, c)
            d = 1.0 if i == c else 0.0
            A[i, c] = d - a * (wq1 if c < n else wp1)
            M[i, c] = d + a * (wq0 if c < n else wp0)
    solve(A, M, m, m)
    if Q.shape[0] == 0:
        return h * sdot0(C, j, m)
    for i in range(m):
        w0, w1 = (wq0, wq1) if i < n else (wp0, wp1)
        for c in range(m):
            N[i, c] = w1 * M[i, c] + (w0 if i == c else 0.0)
    for i in range(m):
        for c in range(m):
            Q[i, c] = 0.0
    add_sandwich(Q, N, C, j, m, h, A)
    return h * sdot0(C, j, m)


@njit(**IR_INLINE)
def compose(M, Q, s, M1, Q1, s1, m, T):
    """(M, Q, s) <- (M1, Q1, s1) after (M, Q, s) (Q where it has rows)."""
    if Q.shape[0] > 0:
        product(Q1, M, T, m)
        product(M, T, Q, m, transpose_a=True, add=True)
    product(M1, M, T, m)
    for i in range(m):
        for c in range(m):
            M[i, c] = T[i, c]
    return s + s1


@njit(**IR_INLINE)
def theta_lwork(D, P):
    return matrices(P, 2, 0.0)


@njit(**INLINE)
def theta_lmatrix(D, P, C, t, h, M, Q, W):
    return theta_matrix(P, C, 0, h, D.wq0, D.wq1, D.wp0, D.wp1, M, Q, W[0], W[1])


@njit(**IR_INLINE)
def composition_lwork(D, P):
    return matrices(P, 5, 0.0)


@njit(**INLINE)
def composition_lmatrix(D, P, C, t, h, M, Q, W):
    m = 2 * ndof(P)
    identity(M, m)
    for i in range(Q.shape[0]):
        for c in range(m):
            Q[i, c] = 0.0
    Q1 = W[3] if Q.shape[0] > 0 else W[3][:0]
    s = 0.0
    for i in range(len(D.gammas)):
        s1 = theta_matrix(P, C, i, D.gammas[i] * h, 0.5, 0.5, 0.5, 0.5, W[2], Q1, W[0], W[1])
        s = compose(M, Q, s, W[2], W[3], s1, m, W[4])
    return s


@njit(**IR_INLINE)
def gauss_lwork(D, P):
    return matrices(P, 1, 0.0), stage_square(D, P, 0.0), stage_matrices(D, P, 0.0)


@njit(**INLINE)
def gauss_lmatrix(D, P, C, t, h, M, Q, W):
    """Stage maps G_i = I + h sum_j a_ij J S_j G_j (one solve), M = I + h sum_j b_j J S_j G_j."""
    V, Big, G = W
    n = ndof(P)
    m = 2 * n
    s = len(D.b)
    for i in range(s):
        for j in range(s):
            for r in range(m):
                for c in range(m):
                    Big[i * m + r, j * m + c] = (1.0 if i == j and r == c else 0.0) \
                        - h * D.A[i * s + j] * js(C, j, n, r, c)
    Gs = G[:s].reshape((s * m, m))
    for r in range(s * m):
        for c in range(m):
            Gs[r, c] = 1.0 if r % m == c else 0.0
    solve(Big, Gs, stage_unknowns(D, P), m)
    identity(M, m)
    for i in range(Q.shape[0]):
        for c in range(m):
            Q[i, c] = 0.0
    total = 0.0
    for j in range(s):
        hb = h * D.b[j]
        for i in range(m):
            for c in range(m):
                acc = 0.0
                for r in range(m):
                    acc += js(C, j, n, i, r) * G[j, r, c]
                M[i, c] += hb * acc
        if Q.shape[0] > 0:
            add_sandwich(Q, G[j], C, j, m, hb, V[0])
        total += hb * sdot0(C, j, m)
    return total


@njit(**IR_INLINE)
def explicit_lwork(D, P):
    return matrices(P, 2, 0.0), stage_matrices(D, P, 0.0)


@njit(**INLINE)
def explicit_lmatrix(D, P, C, t, h, M, Q, W):
    """Stage maps G_i = I + h sum_(j<i) a_ij K_j with K_j = J S_j G_j; M = I + h sum b_i K_i."""
    V, K = W
    n = ndof(P)
    m = 2 * n
    s = len(D.b)
    G = V[0]
    identity(M, m)
    for i in range(Q.shape[0]):
        for c in range(m):
            Q[i, c] = 0.0
    total = 0.0
    for i in range(s):
        row = stage_row(D, i)
        identity(G, m)
        for j in range(i):
            a = h * D.A[i * s + j]
            if a != 0.0:
                for r in range(m):
                    for c in range(m):
                        G[r, c] += a * K[j, r, c]
        for r in range(m):
            for c in range(m):
                acc = 0.0
                for x in range(m):
                    acc += js(C, row, n, r, x) * G[x, c]
                K[i, r, c] = acc
        hb = h * D.b[i]
        for r in range(m):
            for c in range(m):
                M[r, c] += hb * K[i, r, c]
        if Q.shape[0] > 0:
            add_sandwich(Q, G, C, row, m, hb, V[1])
        total += hb * sdot0(C, row, m)
    return total


@njit(**IR_INLINE)
def exact_lwork(D, P):
    return matrices(P, 1, 0.0), vectors(P, 1, 0.0)


@njit(**INLINE)
def exact_lmatrix(D, P, C, t, h, M, Q, W):
    """Columns of M from the flow; p_t from H + p_t conserved: Q = M^T S(t+h) M - S(t)."""
    S1M = W[0][0]
    v = W[1][0]
    m = 2 * ndof(P)
    for c in range(m):
        for r in range(m):
            v[r] = 1.0 if r == c else 0.0
        flow(P, t, t + h, v)
        for r in range(m):
            M[r, c] = v[r]
    if Q.shape[0] == 0:
        return C[1, 2 * m * m] - C[0, 2 * m * m]
    for i in range(m):
        for c in range(m):
            acc = 0.0
            for r in range(m):
                acc += C[1, i * m + r] * M[r, c]
            S1M[i, c] = acc
    product(M, S1M, Q, m, transpose_a=True)
    for i in range(m):
        for c in range(m):
            Q[i, c] -= C[0, i * m + c]
    return C[1, 2 * m * m] - C[0, 2 * m * m]


@njit(**IR_INLINE)
def boris_lwork(D, P):
    return matrices(P, 2, 0.0), vectors(P, 6, 0.0)


@njit(**INLINE)
def boris_lmatrix(D, P, C, t, h, M, Q, W):
    """Columns of M and of the half-step map N (z_half = N z) from the push of unit vectors;
    Q = h N^T S'(t + h/2) N."""
    MM, V = W
    N = MM[0]
    m = 2 * ndof(P)
    v = V[5]
    for c in range(m):
        for r in range(m):
            v[r] = 1.0 if r == c else 0.0
        boris_core(P, C, h, v, 0.0, V)
        for r in range(m):
            M[r, c] = v[r]
            N[r, c] = V[4][r]
    if Q.shape[0] == 0:
        return h * sdot0(C, 1, m)
    for i in range(m):
        for c in range(m):
            Q[i, c] = 0.0
    add_sandwich(Q, N, C, 1, m, h, MM[1])
    return h * sdot0(C, 1, m)


@njit(**IR_INLINE)
def splitting_lwork(D, P):
    return vectors(P, 1, 0.0)


@njit(**INLINE)
def splitting_lmatrix(D, P, C, t, h, M, Q, W):
    """Any splitting family's step (Splitting, Perturbed) as a matrix: M's columns are the steps of
    the unit vectors; the p_t increment -(z.Q z/2 + s), a quadratic form plus a constant, is read
    off at 0, at each e_c and at each e_c + e_r. Where Q has no rows, M alone: s is returned as 0
    without the step at 0 that reads it off (taken, it cost leapfrog's one-member fused run on
    damped 35-40 ns of its 112 a step)."""
    v = W[0]
    m = 2 * ndof(P)
    quad = Q.shape[0] > 0
    d0 = 0.0
    if quad:
        for r in range(m):
            v[r] = 0.0
        d0 = step(D, P, C, t, h, v, 0.0, W)[1]
    for c in range(m):
        for r in range(m):
            v[r] = 1.0 if r == c else 0.0
        d = step(D, P, C, t, h, v, 0.0, W)[1]
        for r in range(m):
            M[r, c] = v[r]
        if quad:
            Q[c, c] = -2.0 * (d - d0)
    if not quad:
        return 0.0
    for c in range(m):
        for r in range(c + 1, m):
            for i in range(m):
                v[i] = 1.0 if i == c or i == r else 0.0
            d = step(D, P, C, t, h, v, 0.0, W)[1]
            Q[c, r] = Q[r, c] = -(d - d0) - 0.5 * (Q[c, c] + Q[r, r])
    return -d0
